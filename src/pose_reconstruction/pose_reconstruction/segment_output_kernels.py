"""Compiled per-user arithmetic of the segment output (:meth:`.segment_output.SegmentOutput.output_rows`
after the user's lengths: the blended directions, ``filled_memory_s``, ``position_fit`` and the
smoothing filter's arguments) in one call.

Its numpy formulation (``output_rows``, ``_remembered``, ``_fit_positions``: ~100 numpy calls on
19- and 20-row arrays per user and message) cost ~40-50 us per user in Python overhead, more than
its arithmetic. This kernel does the same arithmetic element by element (:mod:`skeleton_core.jit`:
numba when installed and ``KINECT_NUMBA`` is not 0); the numpy code in ``segment_output.py`` stays
as the twin (used when numba is off) and ``test/test_segment_output_kernel.py`` compares them.

The one difference is float rounding in sums: numpy's matrix products (BLAS) and ``exp`` may
add and round in another order than the loops here (differences ~1e-16 m in the rows).
"""
from __future__ import annotations

import math

import numpy as np

from skeleton_core import jit
from skeleton_core.model import (HIP_LEFT, HIP_RIGHT, ROOT, SEGMENT_CHILD_INDEX,
                                 SEGMENT_PARENT_INDEX, SHOULDER_LEFT,
                                 SHOULDER_RIGHT)

CHILD_I = np.asarray(SEGMENT_CHILD_INDEX, np.int64)
PARENT_I = np.asarray(SEGMENT_PARENT_INDEX, np.int64)
# the torso joints of body_fit.torso_weight: hip left/right, shoulder left/right
TORSO_I = np.array([HIP_LEFT, HIP_RIGHT, SHOULDER_LEFT, SHOULDER_RIGHT], np.int64)

# bits of the kernel's result: which of the smoothing filter's optional arguments are set
HAS_SCALE, HAS_SPEED, HAS_LEAD = 1, 2, 4


def _output_core(solution, rot, has_rot, obs, seg_obs, len_obs, w, L, trust, thr, fused_w,
                 fusion_mode, observation_weight, memory_s, seen_u, seen_age, dt, root,
                 has_root, fit, fit_iterations, chain, half_inv_degree, child, parent,
                 smooth_on, filled_scale, anchored_on, seg_below, torso, trusted_scale,
                 smooth_lead, vr, u, scale, speed, lead):
    """One user's :meth:`~.segment_output.SegmentOutput.output_rows` after its lengths ``L``
    (19,): the rows into ``vr`` (20, 3), the blended directions into ``u`` (19, 3), the smoothing
    filter's ``scale`` / ``speed`` / ``lead`` (20,) when ``smooth_on``; the returned bits say
    which of those three are set. ``rot`` (3, 3) the yaw rotation of the solution's segments when
    ``has_rot``; ``fused_w`` (19,) ``direction_fusion``'s weights when ``fusion_mode`` is 1
    (2: ``observation_weight``, 0: neither); ``seen_u`` / ``seen_age`` the ``filled_memory_s``
    state (updated in place when ``memory_s > 0``); ``root`` (3,) the root when ``has_root``
    (else the observed one)."""
    ns_ = child.shape[0]
    nj = obs.shape[0]
    thr_c = max(thr, 1e-6)
    inv_thr = 1.0 / thr_c
    us = np.empty((ns_, 3))
    uo = np.empty((ns_, 3))
    zero = np.empty(ns_, np.bool_)
    rel_frac = np.empty(ns_)
    beta = np.empty(ns_)
    reliable = np.empty(ns_, np.bool_)
    any_reliable = False
    for s in range(ns_):
        c = child[s]
        p = parent[s]
        a0 = solution[c, 0] - solution[p, 0]
        a1 = solution[c, 1] - solution[p, 1]
        a2 = solution[c, 2] - solution[p, 2]
        if has_rot:
            b0 = a0 * rot[0, 0] + a1 * rot[0, 1] + a2 * rot[0, 2]
            b1 = a0 * rot[1, 0] + a1 * rot[1, 1] + a2 * rot[1, 2]
            b2 = a0 * rot[2, 0] + a1 * rot[2, 1] + a2 * rot[2, 2]
            a0, a1, a2 = b0, b1, b2
        n = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        n = max(n, 1e-9)
        us[s, 0] = a0 / n
        us[s, 1] = a1 / n
        us[s, 2] = a2 / n
        lo = len_obs[s]
        zero[s] = lo <= 1e-9
        if zero[s]:
            uo[s, 0] = us[s, 0]
            uo[s, 1] = us[s, 1]
            uo[s, 2] = us[s, 2]
        else:
            m = max(lo, 1e-9)
            uo[s, 0] = seg_obs[s, 0] / m
            uo[s, 1] = seg_obs[s, 1] / m
            uo[s, 2] = seg_obs[s, 2] / m
        wmin = min(w[p], w[c])
        rel_frac[s] = min(wmin * inv_thr, 1.0)
        b = rel_frac[s] * trust
        reliable[s] = wmin >= thr
        if reliable[s]:
            any_reliable = True
        if fusion_mode == 1:
            x = fused_w[s] * (1.0 if reliable[s] else 0.0)
            b = max(b, x)
        elif fusion_mode == 2:
            x = observation_weight * (1.0 if reliable[s] else 0.0)
            b = max(b, x)
        beta[s] = b
    # filled_memory_s (SegmentOutput._remembered)
    if memory_s > 0.0:
        for s in range(ns_):
            seen_age[s] += dt
            if reliable[s] and not zero[s]:
                seen_u[s, 0] = uo[s, 0]
                seen_u[s, 1] = uo[s, 1]
                seen_u[s, 2] = uo[s, 2]
                seen_age[s] = 0.0
        if trust > 0.0:
            for s in range(ns_):
                if reliable[s] and not zero[s]:
                    continue
                m = trust * math.exp(-seen_age[s] / memory_s) * (1.0 - rel_frac[s])
                if not m > 1e-3:
                    continue
                v0 = us[s, 0] + m * (seen_u[s, 0] - us[s, 0])
                v1 = us[s, 1] + m * (seen_u[s, 1] - us[s, 1])
                v2 = us[s, 2] + m * (seen_u[s, 2] - us[s, 2])
                n = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
                if n > 1e-9:
                    us[s, 0] = v0 / n
                    us[s, 1] = v1 / n
                    us[s, 2] = v2 / n
    # the blend, at the user's lengths
    for s in range(ns_):
        b = beta[s]
        x0 = us[s, 0] + b * (uo[s, 0] - us[s, 0])
        x1 = us[s, 1] + b * (uo[s, 1] - us[s, 1])
        x2 = us[s, 2] + b * (uo[s, 2] - us[s, 2])
        nu = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        if nu <= 1e-9:
            x0, x1, x2 = us[s, 0], us[s, 1], us[s, 2]
        else:
            x0 /= nu
            x1 /= nu
            x2 /= nu
        u[s, 0] = x0
        u[s, 1] = x1
        u[s, 2] = x2
        vr[s, 0] = x0 * L[s]
        vr[s, 1] = x1 * L[s]
        vr[s, 2] = x2 * L[s]
    for k in range(3):
        vr[ns_, k] = root[k] if has_root else obs[ROOT, k]
    # position_fit (SegmentOutput._fit_positions)
    if fit > 0.0 and trust > 0.0:
        pull = np.empty(nj)
        any_pull = False
        for j in range(nj):
            pull[j] = (fit * trust) * min(w[j] * inv_thr, 1.0)
            if pull[j] != 0.0:
                any_pull = True
        if any_pull:
            _fit_positions_j(vr, obs, pull, L, rel_frac, beta, fit_iterations, chain,
                             half_inv_degree, child, parent)
    flags = 0
    if smooth_on:
        if filled_scale != 1.0:
            flags |= HAS_SCALE
            for s in range(ns_):
                scale[s] = filled_scale + (1.0 - filled_scale) * rel_frac[s]
            scale[ns_] = 1.0
            if anchored_on and not any_reliable:
                tw = max(min(w[torso[0]], w[torso[1]]), min(w[torso[2]], w[torso[3]]))
                if tw < thr:
                    any_anchored = False
                    for s in range(ns_):
                        mx = seg_below[s, 0] * w[0]
                        for j in range(1, nj):
                            x = seg_below[s, j] * w[j]
                            if x > mx:
                                mx = x
                        a = min(mx * inv_thr, 1.0)
                        speed[s] = a
                        if a != 0.0:
                            any_anchored = True
                    if any_anchored:
                        flags |= HAS_SPEED
                        for s in range(ns_):
                            speed[s] = scale[s] + speed[s] * (1.0 - scale[s])
                        speed[ns_] = scale[ns_]
        if trusted_scale != 1.0:
            g = trusted_scale - 1.0
            tr = trust * min(1.0, w[ROOT] / thr_c)
            for s in range(ns_ + 1):
                t = 1.0 + g * (beta[s] if s < ns_ else tr)
                if flags & HAS_SCALE:
                    scale[s] = scale[s] * t
                else:
                    scale[s] = t
                if flags & HAS_SPEED:
                    speed[s] = speed[s] * t
            flags |= HAS_SCALE
        if smooth_lead > 0.0:
            flags |= HAS_LEAD
            for s in range(ns_):
                lead[s] = smooth_lead * rel_frac[s]
            lead[ns_] = smooth_lead
    return flags


def _fit_positions(vr, obs, pull, L, rel_frac, beta, iterations, chain, half_inv_degree,
                   child, parent):
    """:meth:`~.segment_output.SegmentOutput._fit_positions` in place on ``vr`` (its
    ``seg_rel`` = ``rel_frac * (1 - beta)``)."""
    ns_ = child.shape[0]
    nj = obs.shape[0]
    p = np.empty((nj, 3))
    for j in range(nj):
        for k in range(3):
            acc = 0.0
            for s in range(ns_):
                if chain[j, s] != 0.0:
                    acc += chain[j, s] * vr[s, k]
            p[j, k] = vr[ns_, k] + acc
    ok = np.empty(nj, np.bool_)
    for j in range(nj):
        ok[j] = (math.isfinite(obs[j, 0]) and math.isfinite(obs[j, 1])
                 and math.isfinite(obs[j, 2]) and pull[j] > 0)
        if ok[j]:
            for k in range(3):
                p[j, k] += pull[j] * (obs[j, k] - p[j, k])
    corr = np.empty((nj, 3))
    for _ in range(iterations):
        corr[:] = 0.0
        for s in range(ns_):
            c = child[s]
            q = parent[s]
            d0 = p[c, 0] - p[q, 0]
            d1 = p[c, 1] - p[q, 1]
            d2 = p[c, 2] - p[q, 2]
            n = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            f = (n - L[s]) / max(n, 1e-9)
            corr[c, 0] += f * d0
            corr[c, 1] += f * d1
            corr[c, 2] += f * d2
            corr[q, 0] -= f * d0
            corr[q, 1] -= f * d1
            corr[q, 2] -= f * d2
        for j in range(nj):
            h = half_inv_degree[j]
            for k in range(3):
                p[j, k] -= h * corr[j, k]
    for s in range(ns_):
        c = child[s]
        q = parent[s]
        d0 = p[c, 0] - p[q, 0]
        d1 = p[c, 1] - p[q, 1]
        d2 = p[c, 2] - p[q, 2]
        n = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        good = n > 1e-9
        if good:
            r = L[s] / n
            f0, f1, f2 = d0 * r, d1 * r, d2 * r
            b = rel_frac[s] * (1.0 - beta[s])
        else:
            f0 = f1 = f2 = 0.0
            b = 0.0
        u0 = vr[s, 0] + b * (f0 - vr[s, 0])
        u1 = vr[s, 1] + b * (f1 - vr[s, 1])
        u2 = vr[s, 2] + b * (f2 - vr[s, 2])
        nu = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        if nu > 1e-9:
            r = L[s] / nu
            vr[s, 0] = u0 * r
            vr[s, 1] = u1 * r
            vr[s, 2] = u2 * r
    wsum = 0.0
    for j in range(nj):
        if ok[j]:
            wsum += pull[j]
    r0 = 0.0
    r1 = 0.0
    r2 = 0.0
    for j in range(nj):
        # q = p - chain @ v, the sum of the chain first (as the matrix product)
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        for s in range(ns_):
            if chain[j, s] != 0.0:
                a0 += chain[j, s] * vr[s, 0]
                a1 += chain[j, s] * vr[s, 1]
                a2 += chain[j, s] * vr[s, 2]
        q0 = p[j, 0] - a0
        q1 = p[j, 1] - a1
        q2 = p[j, 2] - a2
        if wsum > 0:
            wt = pull[j] if ok[j] else 0.0
            r0 += wt * q0
            r1 += wt * q1
            r2 += wt * q2
        else:
            r0 += q0
            r1 += q1
            r2 += q2
    if wsum > 0:
        vr[ns_, 0] = r0 / wsum
        vr[ns_, 1] = r1 / wsum
        vr[ns_, 2] = r2 / wsum
    else:
        vr[ns_, 0] = r0 / nj
        vr[ns_, 1] = r1 / nj
        vr[ns_, 2] = r2 / nj


_fit_positions_j = jit.njit(_fit_positions)
output_core = jit.njit(_output_core)
_warm = [False]


def warm_up() -> float:
    """Compile (or load from numba's cache) the kernel now, with the argument types of the real
    calls (a segment output's frames with and without a yaw and a root), rather than on a user's
    first frame; once per process, nothing without numba. Returns the time taken (s)."""
    if _warm[0] or not jit.enabled():
        return 0.0
    _warm[0] = True
    import time

    from skeleton_core.conversions import SkeletonFrame
    from skeleton_core.model import NUM_JOINTS, NUM_SEGMENTS, TRACKED

    from .segment_output import SegmentOutput, SegmentOutputConfig
    t0 = time.perf_counter()
    so = SegmentOutput(None, np.full(NUM_SEGMENTS, 0.3), lambda: True, 0.5, 'user',
                       SegmentOutputConfig())
    so.profile_lengths = np.full(NUM_SEGMENTS, 0.3)
    p = np.zeros((NUM_JOINTS, 3))
    p[:, 1] = np.arange(NUM_JOINTS) * 0.1
    f = SkeletonFrame(positions=p, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                      stamp_ns=1)
    so.output_rows(f, p, np.ones(NUM_JOINTS), 0.5)
    so.output_rows(f, p, np.ones(NUM_JOINTS), 0.5, yaw=0.1, root=p[0] + 0.0)
    return time.perf_counter() - t0


__all__ = ['CHILD_I', 'PARENT_I', 'TORSO_I', 'HAS_SCALE', 'HAS_SPEED', 'HAS_LEAD', 'output_core',
           'warm_up']
