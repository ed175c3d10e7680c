"""Compiled per-frame steps of the reliability (Eq. 1-8) and of the plausibility's segment terms.

:meth:`.reliability.ReliabilityEstimator.update` runs once per sensor, user and frame: with several
sensors (the fusion) that is 12 calls per capture for 2 sensors x 6 users, and its ~50
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
                   blame, parent_seg, tol, tol_m, reject, max_step, latch_frames, held, transient,
                   latched_score):
    """PlausibilityCheck's bone-length and segment-speed terms and their blame (its ``_bones``,
    ``_speed`` and the min over BLAME): returns the per-joint value (J,); ``latch``,
    ``last_bone`` (the bone-length scores) and ``held`` (frames each segment has stayed where it
    is, TRACKED, without a jump) are updated; a jump from a place held fewer than ``transient``
    frames is the end of a failure, and so is the jump of a segment whose segment above
    (``parent_seg``, -1: none; parents first) ended a failure in this frame; a latched segment
    (after its jump frame) scores ``latched_score``."""
    ns = seg.shape[0]
    nj = blame.shape[1]
    score = np.empty(ns)
    ended_s = np.zeros(ns, np.bool_)
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
            steady = both[s] and last_both[s]
            jump = steady and st > max_step
            # the jump back: a latched snap ending, a rejected length becoming right, or a
            # jump away from a place just taken (a transient)
            ended = jump and (latch[s] > 0 or (last_bone[s] < 1.0 and b >= 1.0)
                              or held[s] < transient
                              or (parent_seg[s] >= 0 and ended_s[parent_seg[s]]))
            ended_s[s] = ended
            if steady and not jump:
                held[s] += 1
            else:
                held[s] = 0
            if jump and not ended:
                latch[s] = 1
            if ended:
                latch[s] = 0
            if latch[s] > 0:
                latch[s] += 1
            if latch[s] > latch_frames:
                latch[s] = 0
            if jump:
                sp = 0.0
            elif latch[s] > 0:
                sp = latched_score
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


def _median_sorted(v, n):
    """The median of the first ``n`` values of ``v``, sorted in place (np.median's value; ``v``
    is the caller's scratch array: no copy per frame)."""
    w = v[:n]
    w.sort()
    return w[n // 2] if n % 2 else (w[n // 2 - 1] + w[n // 2]) / 2.0


_median_j = jit.njit(_median_sorted)


def _skeleton_jump(p, tracked, anchor, anchor_ok, jumped, jump_m, jump_frames, vel):
    """PlausibilityCheck._jump after its first frame: True when the joints TRACKED now and when
    last plausible are, in the median, more than ``jump_m`` from where they were then moved on by
    the body's velocity ``vel`` (3,: m per frame) for the frames since (at most ``jump_frames``
    frames in a row); else the anchor follows the tracked joints and ``vel`` the component-wise
    median of their displacement per frame (half new, half old). ``jumped`` (1,), the anchor and
    ``vel`` updated."""
    nj = p.shape[0]
    cnt = 0
    for j in range(nj):
        if tracked[j] and anchor_ok[j]:
            cnt += 1
    if cnt >= 3:
        since = jumped[0] + 1.0            # frames since the anchor was plausible
        dist = np.empty(cnt)
        i = 0
        for j in range(nj):
            if tracked[j] and anchor_ok[j]:
                s = 0.0
                for k in range(3):
                    dd = p[j, k] - (anchor[j, k] + since * vel[k])
                    s += dd * dd
                dist[i] = math.sqrt(s)
                i += 1
        d = _median_j(dist, cnt)
        if d > jump_m and jumped[0] < jump_frames:
            jumped[0] += 1
            return True
        for k in range(3):                 # dist is free now: the per-axis scratch
            i = 0
            for j in range(nj):
                if tracked[j] and anchor_ok[j]:
                    dist[i] = (p[j, k] - anchor[j, k]) / since
                    i += 1
            vel[k] = 0.5 * vel[k] + 0.5 * _median_j(dist, cnt)
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
    eq18_reacquired_step(p, ones_s, ones_s, tracked, ones_j, ones_j, True, True, 0.03, 1.5, 2.3,
                         np.zeros((nj, 3)), np.zeros((nj, 3)), np.zeros(nj),
                         np.zeros(1, np.int64), np.zeros((3, nj)), np.zeros(1, np.int64),
                         np.zeros((6, nj)), np.zeros(1, np.int64), np.ones((7, 6)), inc, inc,
                         par, child, np.empty(nj), np.empty(nj), np.zeros((6, nj)),
                         np.zeros(1, np.int64), np.empty(nj))
    seg = np.zeros((ns, 3))
    both = np.ones(ns, bool)
    segment_terms(seg, ones_s, both, ones_s, seg, True, both, np.zeros(ns, np.int64),
                  np.ones(ns), np.zeros((ns, nj), bool), np.full(ns, -1, np.int64), 0.4,
                  0.03, 1.0, 0.27, 45, np.zeros(ns, np.int64), 3, 0.0)
    skeleton_jump(p, tracked, np.zeros((nj, 3)), tracked.copy(), np.zeros(1, np.int64), 0.35, 15,
                  np.zeros(3))
    idx4 = np.arange(4, dtype=np.int64)
    out = [np.empty(nj) for _ in range(4)]
    plausibility_step(p, tracked, seg, ones_s, both, ones_s, np.zeros((nj, 3)), tracked.copy(),
                      np.zeros(1, np.int64), 0.35, 15, np.zeros(3), True, seg, True, both,
                      np.zeros(ns, np.int64), np.ones(ns), np.zeros((ns, nj), bool),
                      np.full(ns, -1, np.int64), 0.4, 0.03, 1.0, 0.27, 45,
                      np.zeros(ns, np.int64), 3, 0.0, np.zeros(2), idx4,
                      tracked.copy(), tracked.copy(), 1.9, 0.3, True,
                      np.zeros(150), np.zeros(150), np.zeros(5, np.int64), np.zeros(2), idx4,
                      0.08, 30, 0.05, 0.12, 0.25, out[0], out[1], out[2], out[3],
                      np.zeros(4, np.int64))
    _warm = True
    return time.perf_counter() - t0


def _wrap(a):
    """plausibility._wrap: the angle in [-pi, pi) (Python's float modulo)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _nmin(a, b):
    """np.minimum of two floats (NaN propagates)."""
    if a != a or b != b:
        return a + b
    return a if a <= b else b


def _plausibility_step(p, tracked, seg, seg_len, both, ref,
                       anchor, anchor_ok, jumped, jump_m, jump_frames, jump_vel, check_jump,
                       last_rel, has_last, last_both, latch, last_bone, blame, parent_seg,
                       tol, tol_m,
                       reject, max_step, latch_frames, held, transient, latched_score,
                       lr_state, girdles, arms, legs, lr_flip, heading_rate, lr_unswap,
                       fl_ring, fl_sorted, fl_meta, fl_state, feet, ankle_height, fl_stale,
                       floor_tolerance, floor_reject, floor_quantile,
                       out_seg, out_lr, out_fl, out_v, flags):
    """PlausibilityCheck.update after its first frame, in one call: the whole-skeleton jump
    (flags[0]; ``jump_vel`` the body's velocity, :func:`_skeleton_jump`), the segment terms
    (``out_seg``; ``latch`` and ``last_bone`` updated; the caller keeps ``seg`` / ``both`` as
    the next frame's ``last_rel`` / ``last_both``), left/right against the heading
    (``out_lr``; ``lr_state`` = [heading known, heading]; flags[1] = the swap flags were set,
    flags[2] / flags[3] = arms / legs swapped), the floor (``out_fl``; the window as a ring
    ``fl_ring`` and its finite values sorted in ``fl_sorted``, ``fl_meta`` = [ring start, ring
    length, sorted length, NaNs in the ring, frames since a foot was TRACKED: beyond
    ``fl_stale`` the window is emptied], ``fl_state`` = [floor known, floor]) and their
    minimum (``out_v``). ``girdles``: (shoulder_l, shoulder_r, hip_l, hip_r); ``feet``: (foot_l,
    foot_r, ankle_l, ankle_r). Returns True on a jump (then nothing else is updated);
    ``check_jump`` False: the first frame (the anchor was just set), no jump test."""
    nj = p.shape[0]
    flags[1] = 0
    if check_jump and skeleton_jump(p, tracked, anchor, anchor_ok, jumped, jump_m, jump_frames,
                                    jump_vel):
        flags[0] = 1
        return True
    flags[0] = 0
    blamed = segment_terms(seg, seg_len, both, ref, last_rel, has_last, last_both, latch,
                           last_bone, blame, parent_seg, tol, tol_m, reject, max_step,
                           latch_frames,
                           held, transient, latched_score)
    for j in range(nj):
        out_seg[j] = blamed[j]
        out_lr[j] = 1.0
    # left/right against the heading (PlausibilityCheck._left_right)
    sl, sr, hl, hr = girdles[0], girdles[1], girdles[2], girdles[3]
    hs = math.atan2(-(p[sl, 0] - p[sr, 0]), p[sl, 1] - p[sr, 1])
    hh = math.atan2(-(p[hl, 0] - p[hr, 0]), p[hl, 1] - p[hr, 1])
    if lr_state[0] == 0.0:
        lr_state[1] = math.atan2(math.sin(hs) + math.sin(hh), math.cos(hs) + math.cos(hh))
        lr_state[0] = 1.0
    else:
        heading = lr_state[1]
        ds = abs(_wrap_j(hs - heading))
        dh = abs(_wrap_j(hh - heading))
        apart = abs(_wrap_j(hs - hh)) > lr_flip
        a_sw = apart and ds > lr_flip and dh <= lr_flip
        l_sw = apart and dh > lr_flip and ds <= lr_flip
        flags[1] = 1
        flags[2] = 1 if a_sw else 0
        flags[3] = 1 if l_sw else 0
        taken = False
        if a_sw:
            if not lr_unswap:
                for j in range(nj):
                    if arms[j]:
                        out_lr[j] = 0.0
            target = hh
        elif l_sw:
            if not lr_unswap:
                for j in range(nj):
                    if legs[j]:
                        out_lr[j] = 0.0
            target = hs
        else:
            target = math.atan2(math.sin(hs) + math.sin(hh), math.cos(hs) + math.cos(hh))
            if ds > lr_flip and dh > lr_flip:
                lr_state[1] = target
                taken = True
        if not taken:
            lr_state[1] = _wrap_j(heading + heading_rate * _wrap_j(target - heading))
    # the floor (PlausibilityCheck._floor, _floor_push, _floor_quantile)
    low = 0.0
    have = False
    for k in range(4):
        j = feet[k]
        if tracked[j]:
            z = p[j, 2] - (ankle_height if k >= 2 else 0.0)
            if not have or z < low:     # Python's min over the list: the first of equals
                low = z
                have = True
    if have and fl_meta[4] > fl_stale:   # no foot seen for long: the floor forgotten
        fl_meta[0], fl_meta[1], fl_meta[2], fl_meta[3] = 0, 0, 0, 0
        fl_state[0] = 0.0
    if have:
        fl_meta[4] = 0
        w = fl_ring.shape[0]
        start, n, ns, nan = fl_meta[0], fl_meta[1], fl_meta[2], fl_meta[3]
        if n == w:                      # evict the oldest
            old = fl_ring[start]
            if old != old:
                nan -= 1
            else:
                i = 0
                while i < ns and fl_sorted[i] < old:      # bisect_left
                    i += 1
                for k in range(i, ns - 1):
                    fl_sorted[k] = fl_sorted[k + 1]
                ns -= 1
            fl_ring[start] = low
            start = (start + 1) % w
        else:
            fl_ring[(start + n) % w] = low
            n += 1
        if low != low:
            nan += 1
        else:
            i = ns
            while i > 0 and fl_sorted[i - 1] > low:       # insort (bisect_right)
                fl_sorted[i] = fl_sorted[i - 1]
                i -= 1
            fl_sorted[i] = low
            ns += 1
        fl_meta[0], fl_meta[1], fl_meta[2], fl_meta[3] = start, n, ns, nan
        if n >= 5:
            if nan > 0:
                fl_state[1] = np.nan
            else:
                pos = (ns - 1) * floor_quantile
                lo = int(math.floor(pos))
                hi = min(lo + 1, ns - 1)
                t = pos - lo
                a = fl_sorted[lo]
                b = fl_sorted[hi]
                d = b - a
                fl_state[1] = b - d * (1.0 - t) if t >= 0.5 else a + d * t
            fl_state[0] = 1.0
    else:
        fl_meta[4] += 1
    if fl_state[0] == 0.0:
        for j in range(nj):
            out_fl[j] = 1.0
    else:
        fl = fl_state[1]
        span = floor_reject - floor_tolerance
        for j in range(nj):
            score = 1.0 - ((fl - p[j, 2]) - floor_tolerance) / span
            out_fl[j] = _nmin(_nmax(score, 0.0), 1.0)
    for j in range(nj):
        out_v[j] = _nmin(_nmin(out_seg[j], out_lr[j]), out_fl[j])
    return False


def _nmax(a, b):
    """np.maximum of two floats (NaN propagates)."""
    if a != a or b != b:
        return a + b
    return a if a >= b else b


_wrap_j = jit.njit(_wrap)
_nmin = jit.njit(_nmin)
_nmax = jit.njit(_nmax)
plausibility_step = jit.njit(_plausibility_step)


def _reacquired_step(r, rb, rk, rt, rp, use_rp, bk, bk_n, gauss, out):
    """ReliabilityEstimator._reacquired on the reliability ``r`` (J,) of Eq. 8: ``min(R_b, R_k)``
    appended to the window ``bk`` (f_total, J; rows oldest first, ``bk_n[0]`` filled), the
    reliability at least its Gaussian-weighted sum capped by ``R_t``, at most ``rp`` when
    ``use_rp``, in [0, 1] -> ``out``. The element-wise steps are np.minimum / np.maximum /
    np.clip's (NaN propagates) and the weighted sum is np.dot's BLAS product, the one numpy's
    ``@`` computes: the twin's bits."""
    nj = r.shape[0]
    f_total = bk.shape[0]
    n = bk_n[0]
    if n < f_total:
        n += 1
        bk_n[0] = n
    else:
        for q in range(f_total - 1):
            bk[q, :] = bk[q + 1, :]
    for j in range(nj):
        bk[n - 1, j] = _nmin(rb[j], rk[j])
    w = np.empty(n)
    for q in range(n):
        w[q] = gauss[n, q]
    now = np.dot(w, bk[:n])
    for j in range(nj):
        v = _nmax(r[j], _nmin(now[j], rt[j]))
        if use_rp:
            v = _nmin(v, rp[j])
        if v == v:                      # np.clip(v, 0, 1): max then min, NaN kept
            v = v if v > 0.0 else 0.0
            v = v if v < 1.0 else 1.0
        out[j] = v


reacquired_step = jit.njit(_reacquired_step)


def _eq18_reacquired_step(p, ln, ref, tracked, rt, rp, use_rp, judge_tracked, d_min,
                          theta_floor, theta_roof, last_p, last_d, last_n, stage, theta, theta_n,
                          minima, minima_n, gauss, inc, inc_mean, seg_par, seg_child, out_rb,
                          out_rk, bk, bk_n, out):
    """:func:`_eq18_step` then :func:`_reacquired_step` on its result, in one call (the
    reliability with the plausibility stage on): the reliability goes to ``out``, R_b and R_k to
    ``out_rb`` / ``out_rk``."""
    r = eq18_step(p, ln, ref, tracked, rt, rp, use_rp, judge_tracked, d_min, theta_floor,
                  theta_roof, last_p, last_d, last_n, stage, theta, theta_n, minima, minima_n,
                  gauss, inc, inc_mean, seg_par, seg_child, out_rb, out_rk)
    reacquired_step(r, out_rb, out_rk, rt, rp, use_rp, bk, bk_n, gauss, out)


eq18_reacquired_step = jit.njit(_eq18_reacquired_step)
