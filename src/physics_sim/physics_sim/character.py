"""One simulated character: its body, its target stream (interpolated between 30 Hz frames), its
virtual-joint state, and its indices into the current MuJoCo model.

A :class:`Character` outlives model rebuilds (characters and objects come and go at run time), so it
keeps no MuJoCo pointers except the index arrays refreshed by :meth:`Character.bind`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict

import mujoco
import numpy as np
from skeleton_core.model import (FOOT_LEFT, FOOT_RIGHT, NUM_JOINTS, SEGMENTS, SEGMENT_CHILDREN,
                                 SEGMENT_CHILD_INDEX, SEGMENT_PARENT_INDEX, Body)

from .posture import ball_qpos, segment_quats_from_positions
from .mjcf_body import AXES, PIN_JOINTS, ROOT_SEGMENT, ElementNames, character_prefix, joint_anchor


MAX_TARGET_SPEED = 10.0  # m/s: bound on the target velocity p'_target of Eq. 1


def _nlerp(q0: np.ndarray, q1: np.ndarray, s: float) -> np.ndarray:
    sign = np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    q = (1.0 - s) * q0 + s * sign * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


@dataclass
class Target:
    """A target posture in the world frame (floor at z = 0): joint positions (20, 3) and segment
    orientations (19, 4, x y z w) with the simulation time it was received and its input stamp."""

    positions: np.ndarray
    seg_quats: np.ndarray
    sim_time: float
    stamp_ns: int = 0


@dataclass
class PinState:
    active: bool = False
    manual: bool = False   # set through Simulation.pin(): not released by the target
    point: np.ndarray = field(default_factory=lambda: np.zeros(3))


class Character:
    """A simulated character following the targets of one user."""

    def __init__(self, user_id: int, body: Body, slot: int, first: Target):
        self.user_id = int(user_id)
        self.prefix = character_prefix(self.user_id)
        self.names = ElementNames(self.prefix)
        self.body = body
        self.slot = slot
        self.prev = first
        self.cur = first
        self.period = 1.0 / 30.0
        self.pins: Dict[int, PinState] = {j: PinState() for j in PIN_JOINTS}
        self.dodge_until = -1.0
        self.spawned = False   # qpos not yet set from the first target
        self.velocity = np.zeros((NUM_JOINTS, 3))  # p'_target (frame differences, smoothed)
        # joint anchors (segment, local point)
        anchors = [joint_anchor(body, j) for j in range(NUM_JOINTS)]
        self.joint_seg = np.array([a[0] for a in anchors])
        self.joint_local = np.array([a[1] for a in anchors])
        # Eq. 3-4 retargeting per joint (skeleton_core.geometry.retarget_by_joint): the length of
        # the segment ending at each joint and the direction a zero-length segment takes
        self.retarget_bone = np.zeros(NUM_JOINTS)
        self.retarget_bone[SEGMENT_CHILD_INDEX] = body.segment_lengths
        self.retarget_dirs = body.rest_offsets / np.maximum(
            np.linalg.norm(body.rest_offsets, axis=1), 1e-12)[:, None]
        # each segment's axis in its body frame (the direction of its child joint)
        ends = body.rest_offsets[SEGMENT_CHILD_INDEX]
        self.segment_axes_local = ends / np.maximum(np.linalg.norm(ends, axis=1), 1e-9)[:, None]
        # twist inertia per segment (capsule axial inertia ~ m r^2 / 2)
        self.axial_inertia = 0.5 * body.segment_masses * body.segment_radii ** 2

    # ------------------------------------------------------------------ model binding
    def bind(self, model: mujoco.MjModel) -> None:
        """Look up this character's ids in a (re)built model."""
        n = self.names
        bid = lambda n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n)  # noqa: E731
        self.seg_body = np.array([bid(n.body(c)) for c in SEGMENT_CHILDREN])
        if np.any(self.seg_body < 0):
            raise RuntimeError(f'character {self.user_id} missing from the model')
        self.joint_body = self.seg_body[self.joint_seg]
        mids = [bid(n.target(j)) for j in range(NUM_JOINTS)]
        self.mocap_ids = (np.array([model.body_mocapid[m] for m in mids]) if min(mids) >= 0
                          else None)
        aid = lambda n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, n)  # noqa: E731
        acts = np.array([[aid(n.pd_actuator(j, a)) for a in AXES]
                         for j in range(NUM_JOINTS)])
        self.actuator_ids = acts if acts.min() >= 0 else None   # (20, 3): actuator_pd only
        tw = np.array([aid(n.twist_actuator(c)) for c in SEGMENT_CHILDREN])
        self.twist_actuator_ids = tw if tw.min() >= 0 else None  # (19,): actuator_pd only
        sid = lambda n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, n)  # noqa: E731
        js = np.array([sid(n.joint_site(j)) for j in range(NUM_JOINTS)])
        self.joint_site_ids = js if js.min() >= 0 else None   # (20,)
        if self.joint_site_ids is not None:   # exactly the anchors (the MJCF has 6 digits)
            model.site_pos[js] = self.joint_local
        ax = np.array([sid(n.axis_site(c)) for c in SEGMENT_CHILDREN])
        self.axis_site_ids = ax if ax.min() >= 0 else None   # (19,): site z = segment axis
        eid = lambda n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, n)  # noqa: E731
        self.pin_eq = {j: eid(n.pin(j)) for j in PIN_JOINTS}
        # MuJoCo derives body2's anchor from the compile-time pose; the tracking connects must
        # pull the joint point onto the mocap body's origin, so set both anchors explicitly.
        self.track_eq = {}
        for j in range(NUM_JOINTS):
            e = eid(n.track(j))
            self.track_eq[j] = e
            if e >= 0:
                model.eq_data[e, 0:3] = self.joint_local[j]
                model.eq_data[e, 3:6] = 0.0
        jid = lambda n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n)  # noqa: E731
        self.root_qadr = model.jnt_qposadr[jid(n.root_joint())]
        self.root_dadr = model.jnt_dofadr[jid(n.root_joint())]
        self.ball_qadr = {}
        for k, c in enumerate(SEGMENT_CHILDREN):
            if k != ROOT_SEGMENT:
                self.ball_qadr[k] = model.jnt_qposadr[jid(n.ball_joint(c))]
        dofs = [self.root_dadr + i for i in range(6)]
        for k, c in enumerate(SEGMENT_CHILDREN):
            if k != ROOT_SEGMENT:
                d0 = model.jnt_dofadr[jid(n.ball_joint(c))]
                dofs += [d0, d0 + 1, d0 + 2]
        self.dofs = np.array(dofs)
        arm = model.dof_armature[self.dofs[6:]].reshape(-1, 3)[:, 0]
        inertia = self.axial_inertia.copy()
        others = [k for k in range(len(SEGMENTS)) if k != ROOT_SEGMENT]
        inertia[others] += arm
        self.twist_inertia = inertia

    def set_pose(self, model, data, positions: np.ndarray, seg_quats: np.ndarray) -> None:
        """Put the character in a posture (root at ``positions[0]``) with zero velocity."""
        qb = ball_qpos(seg_quats)
        data.qpos[self.root_qadr:self.root_qadr + 3] = positions[0]
        data.qpos[self.root_qadr + 3:self.root_qadr + 7] = qb[ROOT_SEGMENT]
        for k, adr in self.ball_qadr.items():
            data.qpos[adr:adr + 4] = qb[k]
        data.qvel[self.dofs] = 0.0

    # ------------------------------------------------------------------ targets
    def push_target(self, target: Target, smoothing: float = 0.0) -> None:
        """A new target frame: interpolate from where the target is now to it over one frame;
        the target velocity (Eq. 1 p'_target) is the frame difference, exponentially smoothed
        with factor ``smoothing`` (0 = raw difference)."""
        now = target.sim_time
        p_now, q_now = self.pose_at(now)
        dt_stamp = (target.stamp_ns - self.cur.stamp_ns) * 1e-9
        if self.cur.stamp_ns and target.stamp_ns and 1.0 / 240 <= dt_stamp <= 0.25:
            self.period = dt_stamp
        else:
            self.period = 1.0 / 30.0
        self.prev = Target(p_now, q_now, now, self.cur.stamp_ns)
        self.cur = target
        raw = (target.positions - p_now) / self.period
        n2 = np.einsum('ij,ij->i', raw, raw)   # a tracking glitch is not a velocity:
        if n2.max() > MAX_TARGET_SPEED ** 2:   # bound |p'_target|
            raw *= np.minimum(1.0, MAX_TARGET_SPEED / np.maximum(np.sqrt(n2), 1e-12))[:, None]
        self.velocity = smoothing * self.velocity + (1.0 - smoothing) * raw

    def pose_at(self, t: float):
        """(positions, seg quats) of the target at sim time ``t``: linear from the previous to the
        newest frame over one frame period, then held."""
        s = (t - self.cur.sim_time) / self.period
        if s >= 1.0 or self.prev is self.cur:
            return self.cur.positions, self.cur.seg_quats
        s = max(s, 0.0)
        return ((1.0 - s) * self.prev.positions + s * self.cur.positions,
                _nlerp(self.prev.seg_quats, self.cur.seg_quats, s))

    # ------------------------------------------------------------------ state
    def joint_points(self, data) -> np.ndarray:
        """World positions (20, 3) of the joint points of the simulated bodies."""
        xm = data.xmat[self.joint_body].reshape(-1, 3, 3)
        return data.xpos[self.joint_body] + (xm @ self.joint_local[:, :, None])[:, :, 0]

    def segment_quats(self, data) -> np.ndarray:
        """World orientations (19, 4) x, y, z, w of the segment bodies (rest-relative)."""
        q = data.xquat[self.seg_body]
        return np.concatenate([q[:, 1:], q[:, :1]], axis=1)

    def segment_axes(self, points: np.ndarray) -> np.ndarray:
        d = points[SEGMENT_CHILD_INDEX] - points[SEGMENT_PARENT_INDEX]
        return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)

    @staticmethod
    def default_seg_quats(positions: np.ndarray, body: Body) -> np.ndarray:
        return segment_quats_from_positions(positions, body.rest_offsets)

    def foot_ids(self):
        return (FOOT_LEFT, FOOT_RIGHT)


__all__ = ['Character', 'Target', 'PinState']
