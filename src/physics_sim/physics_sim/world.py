"""One MuJoCo model and its state: a group of characters that may touch each other (and, while
there are any, the objects), stepped by one controller (:mod:`physics_sim.controllers`).

The :class:`~physics_sim.simulation.Simulation` keeps one world per such group; a world is rebuilt
(recompiled, the state of everything that already existed copied over by name) whenever its
characters or objects change. Everything here works on all of a world's characters at once: the
targets and indices of its characters are stacked (N*20 joint rows, N*19 segment rows).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Dict, List, Optional, Sequence

import mujoco
import numpy as np
from skeleton_core.geometry import quat_rotate
from skeleton_core.model import (ELBOW_LEFT, ELBOW_RIGHT, HAND_LEFT, HAND_RIGHT, HEAD,
                                 JOINT_NAMES, NUM_JOINTS, SEGMENT_CHILDREN, SEGMENT_PARENTS,
                                 SEGMENTS, SHOULDER_LEFT, SHOULDER_RIGHT, WRIST_LEFT, WRIST_RIGHT)

from .character import Character
from .config import CharacterState, SimConfig
from .controller import pd_twist_torque, twist_angle, twist_drive, twist_forms
from .controller import twist_torques as twist_kernel
from .controllers import make_controller
from .feature_holds import grip_changes
from .frames import SensorPose
from .mjcf_body import ROOT_SEGMENT, CharacterParams, joint_anchor
from .mjcf_features import grip_name, rope_segment
from .mjcf_world import ALL_BITS, CharacterEntry, ObjectSpec, WorldParams, character_bits, world_xml
from .pins import FootPins

_XYZW = np.array([1, 2, 3, 0])
_WXYZ = np.array([3, 0, 1, 2])

# vec(q1 * conj(q0)) = w0 v1 - w1 v0 + v0 x v1 as bilinear forms q0^T N_k q1 (w x y z), k = x, y, z
_VEC_Q1_Q0INV = np.zeros((3, 4, 4))
for _k, (_i, _j) in enumerate(((1, 2), (2, 0), (0, 1))):
    _VEC_Q1_Q0INV[_k, 0, 1 + _k] = 1.0
    _VEC_Q1_Q0INV[_k, 1 + _k, 0] = -1.0
    _VEC_Q1_Q0INV[_k, 1 + _i, 1 + _j] = 1.0
    _VEC_Q1_Q0INV[_k, 1 + _j, 1 + _i] = -1.0


@dataclass
class Shared:
    """What the worlds of one simulation share (owned by the Simulation)."""

    config: SimConfig
    counters: Dict[str, int]
    objects: List[ObjectSpec] = field(default_factory=list)
    holds: Dict[str, tuple] = field(default_factory=dict)   # object name -> (user_id, hand joint)
    pushes: List[tuple] = field(default_factory=list)  # (user_id, segment, force (3,), end time)
    sensor: Optional[SensorPose] = None
    features: Dict[str, list] = field(default_factory=dict)   # feature_world geometry (or none)
    grips: Dict[int, Dict[int, tuple]] = field(default_factory=dict)  # uid -> hand -> (feature, point)


def controller_for(config: SimConfig, n_characters: int) -> str:
    """The controller a world of ``n_characters`` uses: ``config.controller``, or for ``'auto'``
    actuator_pd below ``auto_explicit_from`` characters and explicit_pd from there on (the same
    control law, whichever is faster: each site actuator takes a Jacobian over every degree of
    freedom of its model, so actuator_pd grows with the square of the characters)."""
    if config.controller != 'auto':
        return config.controller
    return 'explicit_pd' if n_characters >= config.auto_explicit_from else 'actuator_pd'


class World:
    """A MuJoCo model with some characters (and the objects when ``with_objects``)."""

    def __init__(self, shared: Shared, chars: Sequence[Character], with_objects: bool,
                 time: float = 0.0, old: Sequence['World'] = ()):
        self.shared = shared
        self.config = shared.config
        self.counters = shared.counters
        self.chars: List[Character] = list(chars)
        self.with_objects = with_objects
        self.time = time
        self.pins = FootPins(self)
        self._twist_share = None   # twist_torques' (N,) shares when all characters share one
        self.model = self.data = None
        self.rebuild(old)

    # ------------------------------------------------------------------ model
    @property
    def objects(self) -> List[ObjectSpec]:
        return self.shared.objects if self.with_objects else []

    @property
    def floor(self) -> float:
        """Height of the floor under the targets (the lift of the sensor pose)."""
        return self.shared.sensor.lift if self.shared.sensor else 0.0

    def user_ids(self) -> List[int]:
        return [ch.user_id for ch in self.chars]

    def _world_params(self) -> WorldParams:
        c = self.config
        cp = CharacterParams(joint_damping=c.joint_damping, joint_armature=c.joint_armature,
                             friction=c.friction,
                             pin_solref=(2.0 * c.timestep, 1.0))  # stiffest MuJoCo allows
        cp = self.controller.character_params(c, cp)
        solver = c.solver if c.solver != 'auto' else self.controller.solver
        return WorldParams(timestep=c.timestep, integrator=c.integrator, solver=solver,
                           euler_implicit_damping=self.implicit_damping(), character=cp)

    def implicit_damping(self) -> bool:
        """Whether the Euler integrator treats the joint damping implicitly (see SimConfig)."""
        c = self.config
        return (c.implicit_joint_damping
                or c.timestep * c.joint_damping > 0.25 * c.joint_armature)

    def rebuild(self, old: Sequence['World'] = (), recompile: bool = True) -> None:
        """(Re)compile the model from the current characters and objects, keeping the state of
        everything that already existed here or in the ``old`` worlds (matched by name). With
        ``recompile=False`` the model is kept (a world taken back from the simulation's cache for
        the same characters): only the state is copied in from ``old``."""
        if recompile or self.model is None:
            self.controller_name = controller_for(self.config, len(self.chars))
            self.controller = make_controller(self.controller_name)
            entries = [CharacterEntry(ch.prefix, ch.body, tuple(ch.cur.positions[0]), ch.slot,
                                      ch.cur.positions) for ch in self.chars]
            xml = world_xml(entries, self.objects, self._world_params(),
                            self.shared.features or None, self.floor)
            m = mujoco.MjModel.from_xml_string(xml)
            d = mujoco.MjData(m)
            self.xml = xml
            sources = ([(self.model, self.data)] if self.model is not None else []) + \
                [(w.model, w.data) for w in old if w is not self]
        else:
            m, d = self.model, self.data
            d.eq_active[:] = m.eq_active0
            sources = [(w.model, w.data) for w in old if w is not self]
        for om, od in sources:
            _copy_state(om, od, m, d)
        d.time = self.time
        self.model, self.data = m, d
        for ch in self.chars:
            ch.bind(m)
            if not ch.spawned:
                ch.set_pose(m, d, ch.cur.positions, ch.cur.seg_quats)
                ch.spawned = True
        if self.with_objects:
            holds = self.shared.holds
            for name, (uid, hand) in list(holds.items()):
                if any(ch.user_id == uid for ch in self.chars) and self.obj_id(name) >= 0:
                    self._activate_hold(name, uid, hand, teleport=False)
                else:
                    del holds[name]
        for ch in self.chars:
            for j, pin in ch.pins.items():
                if pin.active:
                    self.pins.set(ch, j, True, pin.point)
        self._restore_grips()
        mujoco.mj_forward(m, d)
        self._pack_indices()
        self.controller.bind(self)
        self.pack_targets()
        self.counters['rebuilds' if recompile else 'reused_models'] += 1

    def close(self) -> None:
        """Free the MuJoCo model and data now (the simulation calls it on a world it drops: a
        model and data of a few characters are MBs that Python's collector does not count, so
        they must not wait for it). The world is unusable afterwards."""
        self.model = self.data = None
        self.controller = None
        self.chars = []
        self.tg = self.ix = self._pts = None

    def obj_id(self, name: str) -> int:
        return mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, f'obj_{name}')

    def character(self, user_id: int) -> Optional[Character]:
        return next((ch for ch in self.chars if ch.user_id == user_id), None)

    # ------------------------------------------------------------------ indices and targets
    def _pack_indices(self) -> None:
        """Index arrays over all characters (after every rebuild): the control law runs once,
        vectorised, for the whole world."""
        chars = self.chars
        n = len(chars)
        cat = (lambda xs, shape: np.concatenate(xs) if xs else np.zeros(shape))  # noqa: E731
        ix = SimpleNamespace()
        ix.jb = cat([c.joint_body for c in chars], (0,)).astype(int)
        ix.jl = cat([c.joint_local for c in chars], (0, 3))
        ix.sb = cat([c.seg_body for c in chars], (0,)).astype(int)
        child, parent = np.array(SEGMENT_CHILDREN), np.array(SEGMENT_PARENTS)
        ix.sc = cat([child + NUM_JOINTS * i for i in range(n)], (0,)).astype(int)
        ix.sp = cat([parent + NUM_JOINTS * i for i in range(n)], (0,)).astype(int)
        scale = (np.ones(len(SEGMENTS)) if self.config.twist_scale is None
                 else np.asarray(self.config.twist_scale, float))
        ix.tw_i = cat([c.twist_inertia * scale for c in chars], (0,))
        ix.tw_m = twist_forms(np.array([c.segment_axes_local for c in chars]).reshape(-1, 3))
        ix.jroot = self.model.body_rootid[ix.jb] if n else np.zeros(0, int)
        ix.ub, inv = np.unique(ix.jb, return_inverse=True)
        ix.sum_rows = np.zeros((len(ix.ub), len(ix.jb)))
        ix.sum_rows[inv, np.arange(len(ix.jb))] = 1.0
        ix.axis_site = (np.concatenate([c.axis_site_ids for c in chars]).astype(int)
                        if n and chars[0].axis_site_ids is not None else None)
        ix.js = (np.concatenate([c.joint_site_ids for c in chars]).astype(int)
                 if n and chars[0].joint_site_ids is not None else None)
        # character of every stacked joint / segment row (per-character frame times)
        ix.jchar = np.repeat(np.arange(n), NUM_JOINTS)
        ix.schar = np.repeat(np.arange(n), len(SEGMENTS))
        # output orientations by joint: the segment ending at the joint (root: the root body)
        by_joint = np.full(NUM_JOINTS, ROOT_SEGMENT)
        by_joint[list(SEGMENT_CHILDREN)] = np.arange(len(SEGMENTS))
        ix.jq = cat([by_joint + len(SEGMENTS) * i for i in range(n)], (0,)).astype(int)
        self.ix = ix
        self._pts = None
        self.pins.pack()

    def pack_targets(self) -> None:
        """Stacked target frames (previous, newest, velocities) of all characters for this
        advance; dodging characters get their arm targets replaced."""
        chars = self.chars
        if not chars:
            self.tg = None
            self.controller.targets_changed(self)
            return
        if len(chars) == 1:
            ch = chars[0]
            dodging = ch.dodge_until > self.time
            P0, P1 = ch.prev.positions, ch.cur.positions
            if dodging:
                P0, P1 = _dodge_targets(ch, P0), _dodge_targets(ch, P1)
            V = ch.velocity * 0.0 if dodging else ch.velocity
            Q0, Q1 = ch.prev.seg_quats, ch.cur.seg_quats
            T0, PER = np.array([ch.cur.sim_time]), np.array([ch.period])
        else:
            P0, P1, V = [], [], []
            for ch in chars:
                p0, p1 = ch.prev.positions, ch.cur.positions
                if ch.dodge_until > self.time:
                    p0, p1 = _dodge_targets(ch, p0), _dodge_targets(ch, p1)
                    V.append(ch.velocity * 0.0)
                else:
                    V.append(ch.velocity)
                P0.append(p0)
                P1.append(p1)
            P0, P1, V = np.concatenate(P0), np.concatenate(P1), np.concatenate(V)
            Q0 = np.concatenate([ch.prev.seg_quats for ch in chars])
            Q1 = np.concatenate([ch.cur.seg_quats for ch in chars])
            T0 = np.array([ch.cur.sim_time for ch in chars])
            PER = np.array([ch.period for ch in chars])
        Q0w, Q1w = Q0[:, _WXYZ], Q1[:, _WXYZ]     # w x y z from here on
        Q1w *= np.copysign(1.0, np.einsum('ij,ij->i', Q0w, Q1w))[:, None]
        # segment angular velocity over the frame: 2 vec(q1 q0^-1) / period (the rotation
        # vector to within 1 % up to 30 degrees per frame; q1 is on q0's side)
        W = np.einsum('ni,kij,nj->nk', Q0w, _VEC_Q1_Q0INV, Q1w)
        # one frame time and period for all characters (targets arriving together): the
        # interpolation shares are plain numbers
        t0s, pers = T0.tolist(), PER.tolist()
        uniform = all(x == t0s[0] for x in t0s) and all(x == pers[0] for x in pers)
        W *= 2.0 / pers[0] if uniform else (2.0 / PER)[self.ix.schar, None]
        self.tg = dict(P0=P0, dP=P1 - P0, V=V, Q0w=Q0w, dQw=Q1w - Q0w, W=W, T0=T0, PER=PER,
                       uniform=(float(T0[0]), float(PER[0])) if uniform else None)
        self.pins.refresh()
        self.controller.targets_changed(self)

    def frame_shares(self, times) -> np.ndarray:
        """Share (0..1) of every character's target interpolation reached at each of ``times``
        (T,): (T, N) -- linear over one frame period, then held."""
        tg = self.tg
        return np.minimum(np.maximum((np.array(times)[:, None] - tg['T0']) / tg['PER'], 0.0), 1.0)

    def share_at(self, t: float):
        """:meth:`frame_shares` at one time ``t``: a plain number when every character has the
        same frame time and period (targets arriving together: the common case), else (N,).
        The same numbers either way (one IEEE division, clamp), without numpy's per-call cost
        at every physics step."""
        u = self.tg['uniform']
        if u is None:
            return self.frame_shares((t,))[0]
        s = (t - u[0]) / u[1]
        return 1.0 if s > 1.0 else (0.0 if s < 0.0 else s)

    def targets_at(self, t: float, share=None):
        """Interpolated targets (N*20, 3) and their velocities at time ``t``: linear over one
        frame period, then held. ``share``: :meth:`share_at` ``t`` when the caller has it."""
        tg = self.tg
        if share is None:
            share = self.share_at(t)
        if isinstance(share, float):
            return tg['P0'] + share * tg['dP'], tg['V'] * (share < 1.0)
        sj = share[self.ix.jchar][:, None]
        return tg['P0'] + sj * tg['dP'], tg['V'] * (sj < 1.0)

    def points_now(self) -> np.ndarray:
        """:meth:`joint_points` of the state after the last advance, computed once (the health
        check and the states share it); anything else that moves the bodies clears it."""
        if self._pts is None:
            self._pts = self.joint_points()
        return self._pts

    def joint_points(self) -> np.ndarray:
        """World positions (N*20, 3) of the joint points (the joint sites, which MuJoCo computes
        in every step's kinematics)."""
        if self.ix.js is not None:
            return self.data.site_xpos[self.ix.js]
        d, jb = self.data, self.ix.jb
        xm = d.xmat[jb].reshape(-1, 3, 3)
        return d.xpos[jb] + (xm @ self.ix.jl[:, :, None])[:, :, 0]

    # ------------------------------------------------------------------ Eq. 2
    def twist_torques(self, t: float, tg: Dict, pts: np.ndarray, damped: bool = True,
                      share=None) -> np.ndarray:
        """Eq. 2 torques (N*19, 3) about each segment's own axis, bounded by max_torque; with
        ``damped=False`` only ``Ke_i dtheta + Kd_i theta'_t`` (N*19,) for the twist actuators, which
        subtract ``Kd_i theta'`` and bound the sum at every step themselves. ``share``: the
        characters' interpolation shares at ``t`` when the caller has them."""
        d, g, ix = self.data, self.config.gains, self.ix
        if share is None:
            share = self.share_at(t)
        if damped and ix.axis_site is None:   # the axes between joint points: one compiled loop
            if isinstance(share, float):
                n = len(tg['T0'])
                if self._twist_share is None or len(self._twist_share) != n:
                    self._twist_share = np.empty(n)
                self._twist_share.fill(share)
                share = self._twist_share
            out = np.empty((len(ix.sb), 3))
            twist_kernel(out, d.xquat, ix.sb, ix.tw_m, tg['Q0w'], tg['dQw'], share, ix.schar,
                         pts, ix.sc, ix.sp, tg['W'], d.cvel, g.twist_ke * ix.tw_i,
                         g.twist_kd * ix.tw_i, float(g.max_torque))
            return out
        if isinstance(share, float) or len(share) == 1:
            ss = float(share) if isinstance(share, float) else float(share[0])
            q_t = tg['Q0w'] + ss * tg['dQw']
        else:
            ss = share[ix.schar]
            q_t = tg['Q0w'] + ss[:, None] * tg['dQw']
        err = twist_angle(d.xquat[ix.sb], ix.tw_m, q_t)   # w x y z; q_t need not be unit
        if ix.axis_site is not None:   # the axis sites' z (the twist actuators' axis)
            axes = d.site_xmat[ix.axis_site][:, 2::3]
        else:
            axes = pts[ix.sc] - pts[ix.sp]
            axes /= np.maximum(np.sqrt(np.einsum('ij,ij->i', axes, axes)), 1e-9)[:, None]
        rate_t = np.einsum('ij,ij->i', tg['W'], axes) * (ss < 1.0)  # target twist rate
        if not damped:
            return twist_drive(err, rate_t, g.twist_ke, g.twist_kd, ix.tw_i)
        rate = np.einsum('ij,ij->i', d.cvel[ix.sb, :3], axes)
        tau = pd_twist_torque(err, rate_t, rate, g.twist_ke * ix.tw_i, g.twist_kd * ix.tw_i,
                              g.max_torque)
        return tau[:, None] * axes

    # ------------------------------------------------------------------ stepping
    def advance(self, nsteps: int) -> None:
        """Simulate ``nsteps`` time steps with the world's controller, then check its health."""
        if self.config.dodge:
            self._update_dodge()
        self.pack_targets()
        self.controller.advance(self, nsteps)
        self._pts = None
        self.check_health()

    def apply_pushes(self, t: float) -> None:
        pushes = self.shared.pushes
        if pushes:
            xfrc = self.data.xfrc_applied
            for uid, k, f, t_end in pushes:
                if t < t_end:
                    ch = self.character(uid)
                    if ch is not None:
                        xfrc[ch.seg_body[k], :3] += f

    # ------------------------------------------------------------------ health
    def check_health(self) -> None:
        """Stretched virtual joints are conflicts (counted; released if badly stretched); a
        non-finite state resets every character to its target."""
        d, c = self.data, self.config
        if any(pin.active for _, _, pin in self.pins.feet):
            self.pins.check(self.points_now())
        for name, (uid, hand) in list(self.shared.holds.items()):
            ch = self.character(uid)
            if ch is None or not self.with_objects:
                continue
            spec = next(o for o in self.objects if o.name == name)
            b = self.obj_id(name)
            grip_w = d.xpos[b] + d.xmat[b].reshape(3, 3) @ spec.grip
            gap = float(np.linalg.norm(ch.joint_points(d)[hand] - grip_w))
            if gap > c.conflict_tolerance:
                self.counters['constraint_conflict'] += 1
            if gap > c.conflict_release:
                self.release(name)
                self.counters['virtual_joint_released'] += 1
        w = d.warning[mujoco.mjtWarning.mjWARN_BADQACC]
        # a sum is finite only when every term is (or overflows: a blown-up state too)
        bad = not math.isfinite(float(d.qpos.sum()) + float(d.qvel.sum())) or w.number > 0
        if bad:
            self.counters['nan_reset'] += 1
            w.number = 0
            self.reset_to_targets()

    def reset_to_targets(self) -> None:
        m, d = self.model, self.data
        t = self.time
        mujoco.mj_resetData(m, d)
        for ch in self.chars:
            for pin in ch.pins.values():
                pin.active = False
            ch.set_pose(m, d, ch.cur.positions, ch.cur.seg_quats)
        d.eq_active[:] = m.eq_active0
        for name, (uid, hand) in list(self.shared.holds.items()):
            if self.with_objects and self.character(uid) is not None:
                self._activate_hold(name, uid, hand, teleport=True)
        self._restore_grips()
        d.time = t
        mujoco.mj_forward(m, d)
        self._pts = None

    # ------------------------------------------------------------------ objects and holds
    def hold(self, object_name: str, uid: int, hand_j: int) -> None:
        self._activate_hold(object_name, uid, hand_j, teleport=True)

    def release(self, object_name: str) -> None:
        if object_name in self.shared.holds:
            uid, hand = self.shared.holds.pop(object_name)
            e = self._hold_eq(uid, hand, object_name)
            if e >= 0:
                self.data.eq_active[e] = 0
            self._set_object_bits(object_name, ALL_BITS, ALL_BITS)

    def _hold_eq(self, uid, hand, obj) -> int:
        return mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_EQUALITY,
                                 f'u{uid}_hold_{obj}_{JOINT_NAMES[hand]}')

    def _set_object_bits(self, name, ct, ca) -> None:
        b = self.obj_id(name)
        for g in range(self.model.ngeom):
            if self.model.geom_bodyid[g] == b:
                self.model.geom_contype[g] = ct
                self.model.geom_conaffinity[g] = ca

    def _activate_hold(self, name, uid, hand, teleport: bool) -> None:
        m, d = self.model, self.data
        ch = self.character(uid)
        spec = next(o for o in self.objects if o.name == name)
        e = self._hold_eq(uid, hand, name)
        _, local = joint_anchor(ch.body, hand)
        m.eq_data[e, 0:3] = local
        m.eq_data[e, 3:6] = spec.grip
        d.eq_active[e] = 1
        bit, aff = character_bits(ch.slot)
        self._set_object_bits(name, bit, aff)  # the holder's hand does not collide with it
        if teleport:
            mujoco.mj_forward(m, d)
            hand_p = ch.joint_points(d)[hand]
            oid = self.obj_id(name)
            adr = m.jnt_qposadr[m.body_jntadr[oid]]
            q = d.qpos[adr + 3:adr + 7]
            qx = np.array([q[1], q[2], q[3], q[0]])
            d.qpos[adr:adr + 3] = hand_p - quat_rotate(qx, spec.grip)
            dadr = m.jnt_dofadr[m.body_jntadr[oid]]
            d.qvel[dadr:dadr + 6] = 0.0
            mujoco.mj_forward(m, d)

    # ------------------------------------------------------------------ feature grips
    def _grip_eq(self, ch: Character, hand: int, body: str) -> int:
        return mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_EQUALITY,
                                 grip_name(ch.prefix, hand, body))

    def set_grip(self, ch: Character, hand: int, body: str, local=None) -> None:
        """Connect ``ch``'s hand joint point to ``local`` in ``body`` ('world' or a rope
        segment); None: let go."""
        e = self._grip_eq(ch, hand, body)
        if e < 0:
            return
        if local is not None:
            self.model.eq_data[e, 0:3] = joint_anchor(ch.body, hand)[1]
            self.model.eq_data[e, 3:6] = local
        self.data.eq_active[e] = 0 if local is None else 1

    def _restore_grips(self) -> None:
        for ch in self.chars:
            for hand, (_, body, local) in self.shared.grips.get(ch.user_id, {}).items():
                self.set_grip(ch, hand, body, local)

    def _body_frame(self, body: str):
        if body == 'world':
            return np.zeros(3), np.eye(3)
        b = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, body)
        return self.data.xpos[b], self.data.xmat[b].reshape(3, 3)

    def feature_axes(self) -> Dict[str, list]:
        """{feature: [(a, b, body)]}: the axes a hand can hold now (bars raised by the lift, rope
        segments where they are)."""
        up = np.array([0.0, 0.0, self.floor])
        out = {}
        for name, geoms in self.shared.features.items():
            ax = []
            for i, g in enumerate(geoms):
                if g.type == 'capsule':
                    ax.append((g.vec('from') + up, g.vec('to') + up, 'world'))
                elif g.type == 'rock':      # a point: the hand grips the hold's centre
                    ax.append((g.vec('center') + up, g.vec('center') + up, 'world'))
                elif g.type == 'rope':
                    seg = g.num('length')
                    for s in range(int(g.data['segments'])):
                        body = rope_segment(name, i, s)
                        p, r = self._body_frame(body)
                        ax.append((p.copy(), p - seg * r[:, 2], body))
            if ax:
                out[name] = ax
        return out

    def grip_points(self, user_id: int) -> Dict[int, np.ndarray]:
        """{hand: world point} of a character's grips now (where the anchors have moved to)."""
        out = {}
        for hand, (_, body, local) in self.shared.grips.get(user_id, {}).items():
            p, r = self._body_frame(body)
            out[hand] = p + r @ local
        return out

    def update_grips(self, engaged: Dict[int, Dict[int, str]]) -> None:
        """Grip and release the characters' hands to follow ``engaged`` ({uid: {hand:
        feature}}, :func:`physics_sim.feature_holds.grip_changes`)."""
        if not self.shared.features:
            return
        grips = self.shared.grips
        axes = None
        for ch in self.chars:
            want = engaged.get(ch.user_id, {})
            held = grips.get(ch.user_id, {})
            if not want and not held:
                continue
            if axes is None:
                axes = self.feature_axes()
            pts = ch.joint_points(self.data)
            grab, release = grip_changes(want, held, {h: pts[h] for h in want}, axes,
                                         self.config.grip_reach)
            for h in release:
                self.set_grip(ch, h, held.pop(h)[1], None)
            for h, (f, body, point) in grab.items():
                p, r = self._body_frame(body)
                local = r.T @ (point - p)
                self.set_grip(ch, h, body, local)
                held[h] = (f, body, local)
                self.counters['grips'] += 1
            if held:
                grips[ch.user_id] = held
            else:
                grips.pop(ch.user_id, None)

    # ------------------------------------------------------------------ dodge (Fig. 4)
    def _update_dodge(self) -> None:
        c, d = self.config, self.data
        for ch in self.chars:
            head = ch.joint_points(d)[HEAD]
            for o in self.objects:
                if o.kind != 'ball' or o.name in self.shared.holds:
                    continue
                b = self.obj_id(o.name)
                adr = self.model.jnt_dofadr[self.model.body_jntadr[b]]
                v = d.qvel[adr:adr + 3]
                r = d.xpos[b] - head
                vv = float(v @ v)
                if vv < 1.0:
                    continue
                tc = -float(r @ v) / vv
                if 0.0 < tc < c.dodge_time and np.linalg.norm(r + tc * v) < c.dodge_distance:
                    ch.dodge_until = self.time + c.dodge_hold

    # ------------------------------------------------------------------ state
    def bounds(self) -> np.ndarray:
        """(N, 2, 2): every character's horizontal bounding box (min xy, max xy) of its joint
        points and of its target's, after the last advance."""
        if not self.chars:
            return np.zeros((0, 2, 2))
        pts = self.points_now()[:, :2].reshape(len(self.chars), NUM_JOINTS, 2)
        tgt = np.array([ch.cur.positions[:, :2] for ch in self.chars])
        both = np.concatenate([pts, tgt], axis=1)
        return np.stack([both.min(axis=1), both.max(axis=1)], axis=1)

    def states(self, sensor: SensorPose) -> Dict[int, CharacterState]:
        """Every character's state, computed for all of them at once."""
        chars = self.chars
        if not chars:
            return {}
        d = self.data
        pts = self.points_now()
        qs = d.xquat[self.ix.sb][:, _XYZW][self.ix.jq]  # by joint, x y z w
        ps, qss = sensor.to_sensor(pts), sensor.quat_to_sensor(qs)
        out = {}
        for i, ch in enumerate(chars):
            r = slice(i * NUM_JOINTS, (i + 1) * NUM_JOINTS)
            out[ch.user_id] = CharacterState(
                user_id=ch.user_id, positions=pts[r], orientations=qs[r],
                positions_sensor=ps[r], orientations_sensor=qss[r], stamp_ns=ch.cur.stamp_ns,
                pinned={JOINT_NAMES[j]: p.active for j, p in ch.pins.items()},
                target_world=ch.cur.positions.copy())
        return out


def _copy_state(om, od, m, d) -> None:
    """qpos / qvel of every joint of ``m`` that ``om`` has too (by name)."""
    for j in range(m.njnt):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
        oj = mujoco.mj_name2id(om, mujoco.mjtObj.mjOBJ_JOINT, name)
        if oj < 0:
            continue
        nq = {0: 7, 1: 4, 2: 1, 3: 1}[int(m.jnt_type[j])]
        nv = {0: 6, 1: 3, 2: 1, 3: 1}[int(m.jnt_type[j])]
        d.qpos[m.jnt_qposadr[j]:m.jnt_qposadr[j] + nq] = \
            od.qpos[om.jnt_qposadr[oj]:om.jnt_qposadr[oj] + nq]
        d.qvel[m.jnt_dofadr[j]:m.jnt_dofadr[j] + nv] = \
            od.qvel[om.jnt_dofadr[oj]:om.jnt_dofadr[oj] + nv]


def _dodge_targets(ch: Character, p_t: np.ndarray) -> np.ndarray:
    """Forearms raised in front of the head (Shum & Ho 2012, Sec. 8.2)."""
    p = p_t.copy()
    q0 = ch.cur.seg_quats[0]
    fwd = quat_rotate(q0, np.array([1.0, 0.0, 0.0]))
    left = quat_rotate(q0, np.array([0.0, 1.0, 0.0]))
    up = np.array([0.0, 0.0, 1.0])
    head = p_t[HEAD]
    s = ch.body.height / 1.75
    for side, sh, el, wr, hd in ((1.0, SHOULDER_LEFT, ELBOW_LEFT, WRIST_LEFT, HAND_LEFT),
                                 (-1.0, SHOULDER_RIGHT, ELBOW_RIGHT, WRIST_RIGHT, HAND_RIGHT)):
        p[el] = p_t[sh] + s * (0.22 * fwd - 0.05 * up + side * 0.08 * left)
        p[wr] = head + s * (0.22 * fwd + 0.02 * up + side * 0.06 * left)
        p[hd] = head + s * (0.24 * fwd + 0.10 * up + side * 0.04 * left)
    return p


__all__ = ['World', 'Shared', 'controller_for']
