"""Target and character orientations: segment orientations derived from joint positions when the
input has none (minimal-twist frames hanging from a pelvis frame), orientations by joint <-> by
segment, and a posture as the ball-joint quaternions of the character's MJCF."""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from skeleton_core import jit
from skeleton_core.geometry import quat_conjugate, quat_multiply
from skeleton_core.model import (HIP_CENTER, HIP_LEFT, HIP_RIGHT, NUM_JOINTS, SEGMENT_CHILD_INDEX,
                                 SEGMENT_CHILDREN, SEGMENT_PARENTS, SEGMENTS, SPINE)

from .mjcf_body import ROOT_SEGMENT, body_order, segment_parent_body


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


def _segment_quats_python(positions: np.ndarray, rest_offsets: np.ndarray) -> np.ndarray:
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


def _tree_array() -> np.ndarray:
    """(19, 4) int: (segment, parent body, parent joint, child joint) in body order."""
    return np.array([(k, segment_parent_body(k), SEGMENT_PARENTS[k], SEGMENT_CHILDREN[k])
                     for k in body_order()], np.int64)


_TREE_A = _tree_array()
_PELVIS_JOINTS = np.array([HIP_LEFT, HIP_RIGHT, SPINE, HIP_CENTER], np.int64)
_REST_ARRAYS: dict = {}   # id(rest offsets) -> (the array, its unit directions (20, 3))


def _segment_quats_kernel(p, rest, tree, pelvis, q):
    """Numba twin of :func:`_segment_quats_python` (the same arithmetic, in the same order)."""
    hl, hr, sp, hc = pelvis[0], pelvis[1], pelvis[2], pelvis[3]
    for row in range(tree.shape[0]):
        k, pb, pj, cj = tree[row, 0], tree[row, 1], tree[row, 2], tree[row, 3]
        if pb < 0:   # pelvis frame: y left, z up the spine, x forward
            yx, yy, yz = p[hl, 0] - p[hr, 0], p[hl, 1] - p[hr, 1], p[hl, 2] - p[hr, 2]
            n = np.sqrt(yx * yx + yy * yy + yz * yz)
            if n > 1e-9:
                yx, yy, yz = yx / n, yy / n, yz / n
            else:
                yx, yy, yz = 0.0, 1.0, 0.0
            zx, zy, zz = p[sp, 0] - p[hc, 0], p[sp, 1] - p[hc, 1], p[sp, 2] - p[hc, 2]
            dz = zx * yx + zy * yy + zz * yz
            zx, zy, zz = zx - dz * yx, zy - dz * yy, zz - dz * yz
            n = np.sqrt(zx * zx + zy * zy + zz * zz)
            if n > 1e-9:
                zx, zy, zz = zx / n, zy / n, zz / n
            else:
                zx, zy, zz = 0.0, 0.0, 1.0
            xx, xy, xz = yy * zz - yz * zy, yz * zx - yx * zz, yx * zy - yy * zx
            r00, r11, r22 = xx, yy, zz
            tr = r00 + r11 + r22
            if tr > 0.0:
                s = 2.0 * np.sqrt(tr + 1.0)
                a0, a1, a2, a3 = (yz - zy) / s, (zx - xz) / s, (xy - yx) / s, 0.25 * s
            elif r00 >= r11 and r00 >= r22:
                s = 2.0 * np.sqrt(max(1.0 + r00 - r11 - r22, 1e-300))
                a0, a1, a2, a3 = 0.25 * s, (yx + xy) / s, (zx + xz) / s, (yz - zy) / s
            elif r11 >= r22:
                s = 2.0 * np.sqrt(max(1.0 + r11 - r00 - r22, 1e-300))
                a0, a1, a2, a3 = (yx + xy) / s, 0.25 * s, (zy + yz) / s, (zx - xz) / s
            else:
                s = 2.0 * np.sqrt(max(1.0 + r22 - r00 - r11, 1e-300))
                a0, a1, a2, a3 = (zx + xz) / s, (zy + yz) / s, 0.25 * s, (xy - yx) / s
            n = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2 + a3 * a3) * (-1.0 if a3 < 0 else 1.0)
            q[k, 0], q[k, 1], q[k, 2], q[k, 3] = a0 / n, a1 / n, a2 / n, a3 / n
            continue
        x, y, z, w = q[pb, 0], q[pb, 1], q[pb, 2], q[pb, 3]
        vx, vy, vz = rest[cj, 0], rest[cj, 1], rest[cj, 2]
        tx, ty, tz = 2.0 * (y * vz - z * vy), 2.0 * (z * vx - x * vz), 2.0 * (x * vy - y * vx)
        rx = vx + w * tx + y * tz - z * ty
        ry = vy + w * ty + z * tx - x * tz
        rz = vz + w * tz + x * ty - y * tx
        dx, dy, dz = p[cj, 0] - p[pj, 0], p[cj, 1] - p[pj, 1], p[cj, 2] - p[pj, 2]
        n = np.sqrt(dx * dx + dy * dy + dz * dz)
        if n > 1e-9:
            dx, dy, dz = dx / n, dy / n, dz / n
        else:
            dx, dy, dz = rx, ry, rz
        dot = rx * dx + ry * dy + rz * dz
        if 1.0 + dot < 1e-9:   # opposite: half a turn about an axis orthogonal to the rest dir
            ox, oy, oz = 0.0, rz, -ry                       # rest x (1, 0, 0)
            if np.sqrt(ox * ox + oy * oy + oz * oz) < 1e-6:
                ox, oy, oz = -rz, 0.0, rx                   # rest x (0, 1, 0)
            n = np.sqrt(ox * ox + oy * oy + oz * oz)
            ax, ay, az, aw = ox / n, oy / n, oz / n, 0.0
        else:
            ax, ay, az, aw = ry * dz - rz * dy, rz * dx - rx * dz, rx * dy - ry * dx, 1.0 + dot
            n = 1.0 / np.sqrt(ax * ax + ay * ay + az * az + aw * aw)
            ax, ay, az, aw = ax * n, ay * n, az * n, aw * n
        q[k, 0] = aw * x + ax * w + ay * z - az * y
        q[k, 1] = aw * y - ax * z + ay * w + az * x
        q[k, 2] = aw * z + ax * y - ay * x + az * w
        q[k, 3] = aw * w - ax * x - ay * y - az * z


_segment_quats_numba = jit.njit(_segment_quats_kernel)


def _segment_quats_compiled(positions: np.ndarray, rest_offsets: np.ndarray) -> np.ndarray:
    entry = _REST_ARRAYS.get(id(rest_offsets))
    if entry is None or entry[0] is not rest_offsets:
        if len(_REST_ARRAYS) > 64:
            _REST_ARRAYS.clear()
        entry = _REST_ARRAYS[id(rest_offsets)] = (rest_offsets,
                                                  np.array(_unit_rest(rest_offsets), float))
    q = np.empty((len(SEGMENTS), 4))
    _segment_quats_numba(np.ascontiguousarray(positions, dtype=float), entry[1], _TREE_A,
                         _PELVIS_JOINTS, q)
    return q


# World orientation (x, y, z, w) of every segment (19, SEGMENTS order) from joint positions (20, 3):
# the root segment follows the pelvis frame; every other segment is its parent body's orientation
# followed by the shortest arc turning the parent-carried rest direction onto the segment's
# direction (no twist added). Compiled by numba where available (one call per target frame and
# character), else the scalar Python of _segment_quats_python; both give the same numbers.
segment_quats_from_positions = jit.pick(_segment_quats_compiled, _segment_quats_python)


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


__all__ = ['quat_between', 'segment_quats_from_positions', 'joint_quats_to_segment',
           'segment_quats_to_joints', 'is_identity', 'ball_qpos']
