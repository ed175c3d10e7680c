"""The hybrid PD controller of Shum & Ho 2012 (Sec. 6, Eq. 1-2) and Shum et al. 2013 (Eq. 16-17),
as plain numpy (no MuJoCo), so the equations can be tested by hand.

* Positional control (Eq. 1/16): for every joint ``F = Ke (p_t - p) + Kd (p'_t - p')``, the same
  gains for all joints, the force magnitude clamped to ``max_force``. It is applied as an external
  force at the joint point.
* Rotational control (Eq. 2/17): a torque about the segment's own axis only,
  ``T = Ke_i (theta_t - theta) + Kd_i (theta'_t - theta')``, per-segment gains, magnitude clamped to
  ``max_torque``. ``theta_t - theta`` is the twist (about the current segment axis) of the rotation
  from the current to the target segment orientation.

Also here: target segment orientations derived from joint positions when the input has none
(minimal-twist frames hanging from a pelvis frame), and the conversion of a posture into the ball
joint quaternions of the character.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np
from skeleton_core.geometry import quat_conjugate, quat_multiply, swing_twist
from skeleton_core.model import (HIP_CENTER, HIP_LEFT, HIP_RIGHT, NUM_JOINTS, SEGMENTS,
                                 SEGMENT_CHILDREN, SEGMENT_CHILD_INDEX, SEGMENT_PARENTS, SPINE)
from skeleton_core.params import param

from .mjcf_body import ROOT_SEGMENT, body_order, segment_parent_body


@dataclass
class Gains:
    """Controller gains and limits (the paper hand-tunes one Ke/Kd pair for all joints)."""

    ke: float = param(4000.0, 'Ke of Eq. 1 (N/m), shared by all joints', range=(0.0, 1e6),
                      name='kp')
    kd: float = param(100.0, 'Kd of Eq. 1 (N s/m), shared by all joints', range=(0.0, 1e4))
    max_force: float = param(800.0, 'bound on |F| of Eq. 1 (N)', range=(0.0, 1e5))
    twist_ke: float = param(400.0, 'Eq. 2 elasticity per unit axial inertia (1/s^2): Ke_i = '
                            'twist_kp * I_i (I_i = axial inertia + armature)', range=(0.0, 1e5),
                            name='twist_kp')
    twist_kd: float = param(40.0, 'Eq. 2 damping per unit axial inertia (1/s): Kd_i = twist_kd '
                            '* I_i', range=(0.0, 1e4))
    max_torque: float = param(50.0, 'bound on |T| of Eq. 2 (N m)', range=(0.0, 1e4))

    def validate(self) -> None:
        for name in ('ke', 'kd', 'max_force', 'twist_ke', 'twist_kd', 'max_torque'):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise ValueError(f'gain {name} must be finite and >= 0, got {v!r}')


def clamp_norm(v: np.ndarray, limit: float) -> np.ndarray:
    """Scale rows of ``v`` (..., 3) down so their norm is at most ``limit``."""
    v = np.asarray(v, float)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    scale = np.where(n > limit, limit / np.maximum(n, 1e-300), 1.0)
    return v * scale


def pd_force(p_target, p, v_target, v, ke: float, kd: float, max_force: float) -> np.ndarray:
    """Eq. 1: ``F = Ke (p_t - p) + Kd (v_t - v)`` per joint, |F| <= max_force. Shapes (N, 3)."""
    f = ke * (np.asarray(p_target, float) - p) + kd * (np.asarray(v_target, float) - v)
    return clamp_norm(f, max_force)


def twist_error(q_target, q_current, axis) -> np.ndarray:
    """Angle (rad, (-pi, pi]) about ``axis`` (N, 3) of the twist part of ``q_t * q^-1``."""
    rel = quat_multiply(q_target, quat_conjugate(q_current))
    rel = rel * np.where(rel[..., 3:4] < 0, -1.0, 1.0)  # shortest way round
    _, ang = swing_twist(rel, axis)
    return ang


def pd_twist_torque(angle_err, rate_target, rate, ke_i, kd_i, max_torque: float) -> np.ndarray:
    """Eq. 2 (scalar per segment): ``T = Ke_i dtheta + Kd_i (theta'_t - theta')`` clamped."""
    t = np.asarray(ke_i) * angle_err + np.asarray(kd_i) * (np.asarray(rate_target) - rate)
    return np.clip(t, -max_torque, max_torque)


def apply_at_points(forces, points, com) -> np.ndarray:
    """Wrench (6,) per body at its centre of mass for forces (N, 3) applied at points (N, 3):
    MuJoCo's ``xfrc_applied`` layout [force, torque]."""
    forces = np.asarray(forces, float)
    out = np.zeros(forces.shape[:-1] + (6,))
    out[..., :3] = forces
    out[..., 3:] = np.cross(np.asarray(points) - com, forces)
    return out


# -------------------------------------------------------------------------------------------
# Orientations
# -------------------------------------------------------------------------------------------
def quat_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Shortest-arc rotation (x, y, z, w) taking unit vector ``a`` to unit vector ``b`` (rows)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    c = np.cross(a, b)
    d = np.sum(a * b, axis=-1, keepdims=True)
    q = np.concatenate([c, 1.0 + d], axis=-1)
    # opposite vectors: rotate pi about any axis orthogonal to a
    opp = (1.0 + d[..., 0]) < 1e-9
    if np.any(opp):
        ortho = np.cross(a, np.array([1.0, 0.0, 0.0]))
        small = np.linalg.norm(ortho, axis=-1) < 1e-6
        ortho = np.where(small[..., None], np.cross(a, np.array([0.0, 1.0, 0.0])), ortho)
        q = np.where(opp[..., None], np.concatenate([ortho, np.zeros_like(d)], -1), q)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _pelvis_quat(p) -> tuple:
    """Pelvis frame (x forward, y left, z up the spine) of a posture given as nested lists of
    floats, as a rest-relative quaternion (x, y, z, w tuple)."""
    hl, hr, sp, hc = p[HIP_LEFT], p[HIP_RIGHT], p[SPINE], p[HIP_CENTER]
    y = _unit3((hl[0] - hr[0], hl[1] - hr[1], hl[2] - hr[2]), (0.0, 1.0, 0.0))
    z = (sp[0] - hc[0], sp[1] - hc[1], sp[2] - hc[2])
    dz = z[0] * y[0] + z[1] * y[1] + z[2] * y[2]
    z = _unit3((z[0] - dz * y[0], z[1] - dz * y[1], z[2] - dz * y[2]), (0.0, 0.0, 1.0))
    x = (y[1] * z[2] - y[2] * z[1], y[2] * z[0] - y[0] * z[2], y[0] * z[1] - y[1] * z[0])
    # rotation matrix with columns x, y, z -> quaternion (the larger-diagonal branch is stable)
    r00, r11, r22 = x[0], y[1], z[2]
    tr = r00 + r11 + r22
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = ((y[2] - z[1]) / s, (z[0] - x[2]) / s, (x[1] - y[0]) / s, 0.25 * s)
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * math.sqrt(max(1.0 + r00 - r11 - r22, 1e-300))
        q = (0.25 * s, (y[0] + x[1]) / s, (z[0] + x[2]) / s, (y[2] - z[1]) / s)
    elif r11 >= r22:
        s = 2.0 * math.sqrt(max(1.0 + r11 - r00 - r22, 1e-300))
        q = ((y[0] + x[1]) / s, 0.25 * s, (z[1] + y[2]) / s, (z[0] - x[2]) / s)
    else:
        s = 2.0 * math.sqrt(max(1.0 + r22 - r00 - r11, 1e-300))
        q = ((z[0] + x[2]) / s, (z[1] + y[2]) / s, 0.25 * s, (x[1] - y[0]) / s)
    n = math.sqrt(sum(c * c for c in q)) * (-1.0 if q[3] < 0 else 1.0)
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def _arc(a, b):
    """Shortest-arc quaternion turning unit vector ``a`` onto unit vector ``b`` (floats)."""
    d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    if 1.0 + d < 1e-9:  # opposite: half a turn about any axis orthogonal to a
        return tuple(float(c) for c in quat_between(np.array(a), np.array(b)))
    q = (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0], 1.0 + d)
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def _unit3(v, fallback):
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return (v[0] / n, v[1] / n, v[2] / n) if n > 1e-9 else fallback


_TREE = None   # (segment, parent body, parent joint, child joint) in body order, root first


def segment_quats_from_positions(positions: np.ndarray, rest_offsets: np.ndarray) -> np.ndarray:
    """World orientation (x, y, z, w) of every segment (19, SEGMENTS order) from joint positions
    (20, 3): the root segment follows the pelvis frame; every other segment is its parent body's
    orientation followed by the shortest arc turning the parent-carried rest direction onto the
    segment's direction (no twist added). Scalar code: one posture per target frame, where numpy's
    per-call cost on 3-vectors would dominate."""
    global _TREE
    if _TREE is None:
        _TREE = [(k, segment_parent_body(k), SEGMENT_PARENTS[k], SEGMENT_CHILDREN[k])
                 for k in body_order()]
    p = np.asarray(positions, float).tolist()
    rest = _unit_rest(rest_offsets)
    q = [None] * len(SEGMENTS)
    sqrt = math.sqrt
    for k, pb, pj, cj in _TREE:
        if pb < 0:
            q[k] = _pelvis_quat(p)
            continue
        # inlined (hot loop): rd = rotate(base, unit rest[cj]) (a unit vector); td = unit(p[cj] -
        # p[pj]) (rd if degenerate); q[k] = arc(rd, td) * base
        base = q[pb]
        x, y, z, w = base
        vx, vy, vz = rest[cj]
        tx, ty, tz = 2.0 * (y * vz - z * vy), 2.0 * (z * vx - x * vz), 2.0 * (x * vy - y * vx)
        rx = vx + w * tx + y * tz - z * ty
        ry = vy + w * ty + z * tx - x * tz
        rz = vz + w * tz + x * ty - y * tx
        a, b = p[cj], p[pj]
        dx, dy, dz = a[0] - b[0], a[1] - b[1], a[2] - b[2]
        n = sqrt(dx * dx + dy * dy + dz * dz)
        if n > 1e-9:
            dx, dy, dz = dx / n, dy / n, dz / n
        else:
            dx, dy, dz = rx, ry, rz
        dot = rx * dx + ry * dy + rz * dz
        if 1.0 + dot < 1e-9:
            ax, ay, az, aw = _arc((rx, ry, rz), (dx, dy, dz))
        else:
            ax, ay, az, aw = (ry * dz - rz * dy, rz * dx - rx * dz, rx * dy - ry * dx, 1.0 + dot)
            n = 1.0 / sqrt(ax * ax + ay * ay + az * az + aw * aw)
            ax, ay, az, aw = ax * n, ay * n, az * n, aw * n
        q[k] = (aw * x + ax * w + ay * z - az * y, aw * y - ax * z + ay * w + az * x,
                aw * z + ax * y - ay * x + az * w, aw * w - ax * x - ay * y - az * z)
    return np.array(q)


_REST_UNIT = (None, None)   # (rest offsets array, their unit directions as lists)


def _unit_rest(rest_offsets) -> list:
    """Unit rest directions (lists) of a body's rest offsets ((1, 0, 0) for a zero offset),
    remembered for the last array seen (one body per character, the same every frame)."""
    global _REST_UNIT
    if _REST_UNIT[0] is not rest_offsets:
        out = []
        for v in np.asarray(rest_offsets, float).tolist():
            n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            out.append((v[0] / n, v[1] / n, v[2] / n) if n > 1e-9 else (1.0, 0.0, 0.0))
        _REST_UNIT = (rest_offsets, out)
    return _REST_UNIT[1]


def joint_quats_to_segment(q_by_joint: np.ndarray) -> np.ndarray:
    """(20, 4) orientations by child joint (Skeleton.orientations) -> (19, 4) by segment."""
    return np.asarray(q_by_joint, float)[SEGMENT_CHILD_INDEX]


def segment_quats_to_joints(q_seg: np.ndarray) -> np.ndarray:
    """(19, 4) segment orientations -> (20, 4) by child joint; the root joint gets the root body's."""
    out = np.zeros((NUM_JOINTS, 4))
    out[SEGMENT_CHILD_INDEX] = q_seg
    out[HIP_CENTER] = q_seg[ROOT_SEGMENT]
    return out


def is_identity(q: Optional[np.ndarray]) -> bool:
    """True when every quaternion is (+/-) identity: Skeleton's "orientations unknown"."""
    if q is None:
        return True
    q = np.asarray(q, float)
    return bool(np.all(np.abs(np.abs(q[..., 3]) - 1.0) < 1e-9))


def ball_qpos(q_seg: np.ndarray) -> np.ndarray:
    """Ball joint quaternions (w, x, y, z; MuJoCo order) for segment world orientations (19, 4):
    ``q_local = q_parent^-1 q_child`` (body frames are world-aligned in the rest pose)."""
    out = np.zeros((len(SEGMENTS), 4))
    for k in range(len(SEGMENTS)):
        pb = segment_parent_body(k)
        loc = q_seg[k] if pb < 0 else quat_multiply(quat_conjugate(q_seg[pb]), q_seg[k])
        out[k] = (loc[3], loc[0], loc[1], loc[2])
    return out


__all__ = ['Gains', 'clamp_norm', 'pd_force', 'twist_error', 'pd_twist_torque', 'apply_at_points',
           'quat_between', 'segment_quats_from_positions',
           'joint_quats_to_segment', 'segment_quats_to_joints', 'is_identity', 'ball_qpos']
