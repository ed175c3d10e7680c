"""Compiled per-track step of the multi-sensor fusion (:mod:`.fusion` steps 4, 6, 7 and the track's
new facing) in one call.

:meth:`.fusion.MultiSensorFusion.fuse` runs once per capture and track; its numpy formulation
(``_resolve_mirror``, :func:`.fusion.fuse_views`, :func:`.fusion.hold_relative`, :func:`.fusion.facing`:
~60 numpy calls on 20-joint arrays per track) cost ~0.3 ms per user in Python overhead, more than
its arithmetic. This kernel does the same arithmetic in one compiled call (:mod:`skeleton_core.jit`:
numba when installed and ``KINECT_NUMBA`` is not 0); the numpy code in ``fusion.py`` stays as the
twin (used when numba is off) and ``tests/test_fusion.py`` runs both on sensor-model streams.

The one difference is float rounding in the facing: the twin's :func:`.posture_space.heading_yaw`
takes the float32 reliabilities as weights in float32 arithmetic (numpy's scalar promotion), the
kernel in float64 (differences ~1e-7 rad in a facing compared against +-0.5).
"""
from __future__ import annotations

import math

import numpy as np

from skeleton_core import jit
from skeleton_core.model import HEADING_JOINTS, MIRROR, NUM_JOINTS, PARENTS

# the kernel's index arrays: each joint's mirror twin, the joints that have one, the parents, the
# hip and shoulder joints of the facing
MIRROR_I = np.asarray(MIRROR, np.int64)
LR_I = np.array([j for j in range(NUM_JOINTS) if MIRROR[j] != j], np.int64)
PARENTS_I = np.asarray(PARENTS, np.int64)
HEADING_I = np.asarray(HEADING_JOINTS, np.int64)


def _max(a, b):
    """Python's ``max(a, b)`` (``a`` unless ``b > a``: NaN in ``a`` stays)."""
    return b if b > a else a


def _min(a, b):
    """Python's ``min(a, b)`` (``a`` unless ``b < a``)."""
    return b if b < a else a


_max_j = jit.njit(_max)
_min_j = jit.njit(_min)


def _facing(p, w, heading, out):
    """:func:`.fusion.facing` (heading_yaw on the hip and shoulder lines) into ``out`` (2,).
    ``heading``: (hip_l, hip_r, shoulder_l, shoulder_r)."""
    hl, hr, sl, sr = heading[0], heading[1], heading[2], heading[3]
    wh = _min_j(_max_j(float(w[hl]), 1e-3), _max_j(float(w[hr]), 1e-3))
    ws = _min_j(_max_j(float(w[sl]), 1e-3), _max_j(float(w[sr]), 1e-3))
    lx = wh * (p[hl, 0] - p[hr, 0]) + ws * (p[sl, 0] - p[sr, 0])
    ly = wh * (p[hl, 1] - p[hr, 1]) + ws * (p[sl, 1] - p[sr, 1])
    yaw = math.atan2(-lx, ly)
    out[0] = math.cos(yaw)
    out[1] = math.sin(yaw)


_facing_j = jit.njit(_facing)


def _fuse_track(P, TS, R, has_face, ref_face, has_ref_pos, ref_pos, hold, rel, mirror, lr,
                parents, heading, state_weight, mirror_cos, eps,
                out_p, out_ts, out_r, out_best, flips, out_face):
    """One track's views ``P`` (V, J, 3) / ``TS`` (V, J) uint8 / ``R`` (V, J) float32 (permuted in
    place where a view is mirrored; ``flips`` (V,) set to 1 there) -> the fused skeleton in
    ``out_p`` / ``out_ts`` / ``out_r`` (float32), the heaviest view per joint in ``out_best``
    (orientation), the fused facing in ``out_face``; ``rel`` (J, 3) the hold's segment vectors
    (NaN: not seen), updated when ``hold``. ``ref_face`` / ``ref_pos``: the track's previous facing
    and fused positions when ``has_face`` / ``has_ref_pos``."""
    nv = P.shape[0]
    nj = P.shape[1]
    face = np.empty(2)
    tmp_p = np.empty((nj, 3))
    tmp_t = np.empty(nj, np.uint8)
    tmp_r = np.empty(nj, np.float32)
    for v in range(nv):
        flips[v] = 0
    # step 4: mirror (fusion._resolve_mirror)
    if not (nv == 1 and not has_face):
        ref_i = 0
        best_m = -np.inf
        for v in range(nv):           # np.argmax of the nan-mean reliabilities (first NaN wins)
            s = 0.0
            c = 0
            for j in range(nj):
                x = float(R[v, j])
                if x == x:
                    s += x
                    c += 1
            m = s / c if c > 0 else np.nan
            if m != m:
                ref_i = v
                break
            if m > best_m:
                best_m = m
                ref_i = v
        rf = np.empty(2)
        if has_face:
            rf[0] = ref_face[0]
            rf[1] = ref_face[1]
        else:
            _facing_j(P[ref_i], R[ref_i], heading, rf)
        for v in range(nv):
            if not has_face and v == ref_i:
                continue
            _facing_j(P[v], R[v], heading, face)
            c = face[0] * rf[0] + face[1] * rf[1]
            if c > mirror_cos:
                flip = False
            elif c < -mirror_cos:
                flip = True
            else:                      # a profile view: the labelling nearer the reference
                keep = 0.0
                swap = 0.0
                for k in range(lr.shape[0]):
                    j = lr[k]
                    a = 0.0
                    b = 0.0
                    for d in range(3):
                        r = ref_pos[j, d] if has_ref_pos else P[ref_i, j, d]
                        x = P[v, j, d] - r
                        y = P[v, mirror[j], d] - r
                        a += x * x
                        b += y * y
                    keep += math.sqrt(a)
                    swap += math.sqrt(b)
                flip = swap < keep
            if flip:
                flips[v] = 1
                for j in range(nj):
                    m = mirror[j]
                    for d in range(3):
                        tmp_p[j, d] = P[v, m, d]
                    tmp_t[j] = TS[v, m]
                    tmp_r[j] = R[v, m]
                for j in range(nj):
                    for d in range(3):
                        P[v, j, d] = tmp_p[j, d]
                    TS[v, j] = tmp_t[j]
                    R[v, j] = tmp_r[j]
    # step 6: the reliability-weighted mean (fusion.fuse_views)
    if nv == 1:
        for j in range(nj):
            for d in range(3):
                out_p[j, d] = P[0, j, d]
            out_ts[j] = TS[0, j]
            out_r[j] = R[0, j]
            out_best[j] = 0
    else:
        w = np.empty(nv)
        for j in range(nj):
            tot = 0.0
            rmax = -np.inf
            tmax = 0
            for v in range(nv):
                r = float(R[v, j])
                if r != r:
                    r = 0.0
                if r > rmax:
                    rmax = r
                t = TS[v, j]
                if t > tmax:
                    tmax = t
                sw = state_weight[t] if t <= 2 else state_weight[2]
                w[v] = min(max(r, 0.0), 1.0) * sw
                tot += w[v]
            if tot < eps:             # no view trusts the joint: the tracking state alone
                tot = 0.0
                for v in range(nv):
                    t = TS[v, j]
                    w[v] = (state_weight[t] if t <= 2 else state_weight[2]) + eps
                    tot += w[v]
            best = 0
            for v in range(nv):
                w[v] /= tot
                if w[v] > w[best]:
                    best = v
            for d in range(3):
                acc = 0.0
                for v in range(nv):
                    acc += w[v] * P[v, j, d]
                out_p[j, d] = acc
            out_ts[j] = tmax
            out_r[j] = rmax
            out_best[j] = best
    # step 7: a joint no view tracks held relative to its parent (fusion.hold_relative)
    if hold:
        for j in range(1, nj):        # ascending = parents first: a held child follows its parent
            if out_ts[j] != 2 and rel[j, 0] == rel[j, 0]:
                pj = parents[j]
                for d in range(3):
                    out_p[j, d] = out_p[pj, d] + rel[j, d]
        for j in range(1, nj):
            if out_ts[j] == 2 and out_ts[parents[j]] == 2:
                pj = parents[j]
                for d in range(3):
                    rel[j, d] = out_p[j, d] - out_p[pj, d]
    _facing_j(out_p, out_r, heading, out_face)


fuse_track = jit.njit(_fuse_track)

_warm = False


def warm_up() -> float:
    """Compile (or load from numba's disk cache) the kernel now, once per process (a node's
    configure, not a user's first frame). Returns the time taken (s); 0 when numba is off or done."""
    global _warm
    if _warm or not jit.enabled():
        return 0.0
    import time
    t0 = time.perf_counter()
    nj = NUM_JOINTS
    fuse_track(np.zeros((2, nj, 3)), np.full((2, nj), 2, np.uint8), np.ones((2, nj), np.float32),
               False, np.zeros(2), False, np.zeros((nj, 3)), True, np.full((nj, 3), np.nan),
               MIRROR_I, LR_I, PARENTS_I, HEADING_I, np.array([0.0, 0.05, 1.0]), 0.5, 1e-9,
               np.empty((nj, 3)), np.empty(nj, np.uint8), np.empty(nj, np.float32),
               np.empty(nj, np.int64), np.empty(2, np.uint8), np.empty(2))
    _warm = True
    return time.perf_counter() - t0
