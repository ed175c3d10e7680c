"""Compiled per-frame steps of the reliability (Eq. 1-8) and of the plausibility's segment terms.

:meth:`.reliability.ReliabilityEstimator.update` runs once per sensor, user and frame: with several
sensors (the fusion, issue 31) that is 12 calls per capture for 2 sensors x 6 users, and its ~50
numpy calls on 20-element arrays cost far more than their arithmetic. These kernels do the same
arithmetic in one compiled call each (:mod:`skeleton_core.jit`: numba when installed and
``KINECT_NUMBA`` is not 0). The numpy formulation stays in ``reliability.py`` / ``plausibility.py``
(the twin, used when numba is off); ``test_reliability.py`` runs both on the same streams and checks
that they agree to float rounding (sums taken in another order: ~1e-16).

State is passed in as arrays and updated in place (rings ordered oldest first).
"""
from __future__ import annotations

import math

import numpy as np

from skeleton_core import jit


def _eq18_step(p, ln, ref, tracked, rt, rp, use_rp, judge_tracked, d_min, theta_floor, theta_roof,
               last_p, last_d, last_n, stage, theta, theta_n, minima, minima_n, gauss,
               inc, inc_mean, seg_par, seg_child, out_rb, out_rk):
    """One frame of Eq. 1-8 (ReliabilityEstimator.update's numeric core). ``stage[0]``: 0 no
    previous frame, 1 one, 2 two or more. ``theta`` (f_b, J) / ``minima`` (f_total, J): rings,
    oldest row first, ``theta_n[0]`` / ``minima_n[0]`` rows filled. Returns the reliability (J,);
    R_b and R_k go to ``out_rb`` / ``out_rk``."""
    nj = p.shape[0]
    ns = ln.shape[0]
    f_b = theta.shape[0]
    # Eq. 1-4: one new angle per frame
    if stage[0] >= 1:
        d = np.empty((nj, 3))
        n = np.empty(nj)
        for j in range(nj):
            s = 0.0
            for k in range(3):
                d[j, k] = p[j, k] - last_p[j, k]
                s += d[j, k] * d[j, k]
            n[j] = math.sqrt(s)
        if stage[0] >= 2:
            if theta_n[0] < f_b:
                row = theta_n[0]
                theta_n[0] += 1
            else:
                for r in range(f_b - 1):
                    theta[r, :] = theta[r + 1, :]
                row = f_b - 1
            for j in range(nj):
                if n[j] > d_min and last_n[j] > d_min:
                    dot = d[j, 0] * last_d[j, 0] + d[j, 1] * last_d[j, 1] + d[j, 2] * last_d[j, 2]
                    c = dot / (n[j] * last_n[j])
                    c = max(c, -1.0)
                    c = min(c, 1.0)
                    theta[row, j] = math.acos(c)
                else:
                    theta[row, j] = 0.0
        last_d[:, :] = d
        last_n[:] = n
        stage[0] = 2
    else:
        stage[0] = 1
    last_p[:, :] = p
    span = theta_roof - theta_floor
    for j in range(nj):
        if theta_n[0] > 0:
            m = 0.0
            for r in range(theta_n[0]):
                m += theta[r, j]
            m /= f_b
            out_rb[j] = 1.0 - max(min(m, theta_roof) - theta_floor, 0.0) / span
        else:
            out_rb[j] = 1.0
    # Eq. 5-6 (a TRACKED joint judged by its segments to TRACKED joints when judge_tracked;
    # ``inc``: the segments each joint is judged by, reliability._JUDGED_BY)
    ds = np.empty(ns)
    both = np.empty(ns)
    for s in range(ns):
        v = abs(ln[s] - ref[s]) / max(ref[s], 1e-6)
        ds[s] = min(v, 1.0)
        both[s] = 1.0 if (tracked[seg_par[s]] and tracked[seg_child[s]]) else 0.0
    for j in range(nj):
        a = 0.0
        for s in range(ns):
            a += inc_mean[j, s] * ds[s]
        rk = 1.0 - a
        if judge_tracked and tracked[j]:
            cnt = 0.0
            b = 0.0
            for s in range(ns):
                cnt += inc[j, s] * both[s]
                b += inc[j, s] * (ds[s] * both[s])
            rk = 1.0 - b / max(cnt, 1.0)
        out_rk[j] = rk
    # Eq. 7-8
    f_total = minima.shape[0]
    if minima_n[0] < f_total:
        row = minima_n[0]
        minima_n[0] += 1
    else:
        for r in range(f_total - 1):
            minima[r, :] = minima[r + 1, :]
        row = f_total - 1
    for j in range(nj):
        minima[row, j] = min(min(out_rb[j], out_rk[j]), rt[j])
    cnt_m = minima_n[0]
    out = np.empty(nj)
    for j in range(nj):
        acc = 0.0
        for r in range(cnt_m):
            acc += gauss[cnt_m, r] * minima[r, j]
        if use_rp:
            acc = min(acc, rp[j])
        out[j] = min(max(acc, 0.0), 1.0)
    return out


def _segment_terms(seg, seg_len, both, ref, last_rel, has_last, last_both, latch, last_bone,
                   blame, tol, tol_m, reject, max_step, latch_frames):
    """PlausibilityCheck's bone-length and segment-speed terms and their blame (its ``_bones``,
    ``_speed`` and the min over BLAME): returns the per-joint value (J,); ``latch`` and
    ``last_bone`` (the bone-length scores) are updated."""
    ns = seg.shape[0]
    nj = blame.shape[1]
    score = np.empty(ns)
    for s in range(ns):
        b = 1.0
        if both[s]:
            r = ref[s]
            excess = abs(seg_len[s] - r) - (tol * r + tol_m)
            v = 1.0 - max(excess, 0.0) / max(reject * r, 1e-6)
            if math.isfinite(v):
                b = min(max(v, 0.0), 1.0)
        sp = 1.0
        if has_last:
            st = 0.0
            for k in range(3):
                dd = seg[s, k] - last_rel[s, k]
                st += dd * dd
            st = math.sqrt(st)
            jump = both[s] and last_both[s] and st > max_step
            # the jump back: a latched snap ending, or a rejected length becoming right
            ended = jump and (latch[s] > 0 or (last_bone[s] < 1.0 and b >= 1.0))
            if jump and not ended:
                latch[s] = 1
            if ended:
                latch[s] = 0
            if latch[s] > 0:
                latch[s] += 1
            if latch[s] > latch_frames:
                latch[s] = 0
            if latch[s] > 0 or jump:
                sp = 0.0
        score[s] = min(b, sp)
        last_bone[s] = b
    out = np.ones(nj)
    for s in range(ns):
        for j in range(nj):
            if blame[s, j] and score[s] < out[j]:
                out[j] = score[s]
    return out


eq18_step = jit.njit(_eq18_step)
segment_terms = jit.njit(_segment_terms)


def _skeleton_jump(p, tracked, anchor, anchor_ok, jumped, jump_m, jump_frames):
    """PlausibilityCheck._jump after its first frame: True when the joints TRACKED now and when
    last plausible moved, in the median, more than ``jump_m`` (at most ``jump_frames`` frames in a
    row); else the anchor follows the tracked joints. ``jumped`` (1,) and the anchor updated."""
    nj = p.shape[0]
    cnt = 0
    for j in range(nj):
        if tracked[j] and anchor_ok[j]:
            cnt += 1
    if cnt >= 3:
        dist = np.empty(cnt)
        i = 0
        for j in range(nj):
            if tracked[j] and anchor_ok[j]:
                s = 0.0
                for k in range(3):
                    dd = p[j, k] - anchor[j, k]
                    s += dd * dd
                dist[i] = math.sqrt(s)
                i += 1
        dist.sort()
        d = dist[cnt // 2] if cnt % 2 else (dist[cnt // 2 - 1] + dist[cnt // 2]) / 2.0
        if d > jump_m and jumped[0] < jump_frames:
            jumped[0] += 1
            return True
    jumped[0] = 0
    for j in range(nj):
        if tracked[j]:
            for k in range(3):
                anchor[j, k] = p[j, k]
            anchor_ok[j] = True
    return False


skeleton_jump = jit.njit(_skeleton_jump)


_warm = False


def warm_up() -> float:
    """Compile (or load from the on-disk cache) every kernel of this module now, once per process:
    at a node's start, not on a user's first frame (a cold compile takes seconds). Returns the
    time taken (s); 0 when numba is off or already done."""
    global _warm
    if _warm or not jit.enabled():
        return 0.0
    import time
    from skeleton_core.model import (NUM_JOINTS, NUM_SEGMENTS, SEGMENT_CHILD_INDEX,
                                     SEGMENT_PARENT_INDEX)
    t0 = time.perf_counter()
    nj, ns = NUM_JOINTS, NUM_SEGMENTS
    p = np.zeros((nj, 3))
    ones_j, ones_s = np.ones(nj), np.ones(ns)
    tracked = np.ones(nj, bool)
    par = np.asarray(SEGMENT_PARENT_INDEX, np.int64)
    child = np.asarray(SEGMENT_CHILD_INDEX, np.int64)
    inc = np.zeros((nj, ns))
    eq18_step(p, ones_s, ones_s, tracked, ones_j, ones_j, True, True, 0.03, 1.5, 2.3,
              np.zeros((nj, 3)), np.zeros((nj, 3)), np.zeros(nj), np.zeros(1, np.int64),
              np.zeros((3, nj)), np.zeros(1, np.int64), np.zeros((6, nj)), np.zeros(1, np.int64),
              np.ones((7, 6)), inc, inc, par, child, np.empty(nj), np.empty(nj))
    seg = np.zeros((ns, 3))
    both = np.ones(ns, bool)
    segment_terms(seg, ones_s, both, ones_s, seg, True, both, np.zeros(ns, np.int64),
                  np.ones(ns), np.zeros((ns, nj), bool), 0.4, 0.03, 1.0, 0.27, 45)
    skeleton_jump(p, tracked, np.zeros((nj, 3)), tracked.copy(), np.zeros(1, np.int64), 0.35, 15)
    _warm = True
    return time.perf_counter() - t0
