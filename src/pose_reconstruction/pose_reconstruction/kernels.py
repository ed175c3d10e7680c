"""Compiled kernels of the reconstruction's hot loops (numba where available, :mod:`skeleton_core.jit`;
``KINECT_NUMBA=0`` runs the numpy twins). Each kernel has a numpy twin computing the same numbers
(src/pose_reconstruction/test/test_optimizer.py compares them).

* :func:`energy_from_products` -- Eq. 15 of every stochastic sample from the one matrix product
  ``P = WT [z; 1]`` of :meth:`NaturalPostureOptimizer._energy_t` (the quadratic and linear part,
  the segment lengths of E_k, the closest neighbour of E_s): one pass over ``P`` instead of about
  ten numpy calls per optimisation step (the loops run over ``P``'s rows outside and the samples
  inside: contiguous and vectorised, each sample's sums and minimum in the order of one sample at
  a time, so the numbers do not change with the layout);
* :func:`energy_many` -- the same for several users' stacked products at once (one call per
  optimisation step of a frame's users, :func:`~.optimizer.solve_batch`);
* :func:`scale_samples_many` / :func:`select_many` -- the rest of a stacked optimisation step:
  the standard normal draws scaled and moved to each user's centre, and each user's best sample
  taken when it improves (two strided broadcasts and an argmin, gather and masked copy in numpy;
  the same arithmetic, element by element, compiled).
"""
from __future__ import annotations

import time

import numpy as np
from skeleton_core import jit
from skeleton_core.model import NUM_JOINTS, NUM_SEGMENTS


def _energy_numpy(P, ZT, d, const, L, w_k, w_s, sq=None):
    n = NUM_SEGMENTS
    e = np.einsum('dm,dm->m', P[:d], ZT[:d])
    e += const
    Ps = P[d:d + 3 * n]
    sq = np.multiply(Ps, Ps, out=sq)                      # x^2, y^2, z^2 blocks
    ln = sq[:n]
    ln += sq[n:2 * n]
    ln += sq[2 * n:]
    np.sqrt(ln, out=ln)
    ln -= L[:, None]
    ek = np.einsum('sm,sm->m', ln, ln)
    ek *= w_k / NUM_SEGMENTS
    e += ek
    es = P[d + 3 * n:].min(axis=0)
    es *= w_s / NUM_JOINTS
    e += es
    return e


def _energy_kernel(P, ZT, d, const, L, w_k, w_s, sq=None):
    # each sample j: acc = sum_i P[i, j] ZT[i, j] (i in order), ek = sum_s (|segment s| - L_s)^2
    # (s in order), best = min_k of the style rows (k in order), e = acc + const + ek ck + best cs;
    # the loops run over the rows outside and the samples inside (contiguous, vectorised), each
    # sample's operations in the same order as one sample at a time
    n = L.shape[0]
    m = P.shape[1]
    K = P.shape[0] - d - 3 * n
    ck, cs = w_k / n, w_s / NUM_JOINTS
    e = np.empty(m)
    _energy_rows(P, ZT, d, const, L, ck, cs, n, K, m, e)
    return e


def _energy_rows(P, ZT, d, const, L, ck, cs, n, K, m, e):
    acc = np.zeros(m)
    for i in range(d):
        for j in range(m):
            acc[j] += P[i, j] * ZT[i, j]
    ek = np.zeros(m)
    for s in range(n):
        ls = L[s]
        for j in range(m):
            x, y, z = P[d + s, j], P[d + n + s, j], P[d + 2 * n + s, j]
            r = np.sqrt(x * x + y * y + z * z) - ls
            ek[j] += r * r
    best = P[d + 3 * n].copy()
    for k in range(1, K):
        for j in range(m):
            v = P[d + 3 * n + k, j]
            if v < best[j]:
                best[j] = v
    for j in range(m):
        e[j] = acc[j] + const + ek[j] * ck + best[j] * cs


def _energy_many_numpy(P, ZT, d, const, L, w_k, w_s, sq=None):
    return np.stack([_energy_numpy(P[u], ZT[u], d, const[u], L, w_k, w_s, sq)
                     for u in range(P.shape[0])])


def _energy_many_kernel(P, ZT, d, const, L, w_k, w_s, sq=None):
    # the arithmetic of _energy_kernel, in the same order, for each of the U stacked users
    U, m = P.shape[0], P.shape[2]
    n = L.shape[0]
    K = P.shape[1] - d - 3 * n
    ck, cs = w_k / n, w_s / NUM_JOINTS
    e = np.empty((U, m))
    for u in range(U):
        _energy_rows(P[u], ZT[u], d, const[u], L, ck, cs, n, K, m, e[u])
    return e


def _scale_samples_many_numpy(Z, SIG, ZC, d):
    Zs = Z[:, :d]
    Zs *= SIG
    Zs += ZC


def _scale_samples_many_kernel(Z, SIG, ZC, d):
    # Z[u, i, j] * SIG[u, i] + ZC[u, i], rounded after each operation as the numpy twin
    for u in range(Z.shape[0]):
        for i in range(d):
            s, c = SIG[u, i, 0], ZC[u, i, 0]
            for j in range(Z.shape[2]):
                Z[u, i, j] = Z[u, i, j] * s + c


def _select_many_numpy(E, Z, d, ZC, E0):
    u = E.shape[0]
    J = E.argmin(axis=1)
    EJ = E[np.arange(u), J]
    better = EJ < E0
    Jl = J.tolist()
    for r, b in enumerate(better.tolist()):
        if b:
            ZC[r] = Z[r, :d, Jl[r]:Jl[r] + 1]
    np.copyto(E0, EJ, where=better)
    return better


def _select_many_kernel(E, Z, d, ZC, E0):
    U, m = E.shape
    better = np.zeros(U, np.bool_)
    for u in range(U):
        j = 0   # numpy's argmin: the first minimum, or the first NaN
        best = E[u, 0]
        if not np.isnan(best):
            for k in range(1, m):
                v = E[u, k]
                if np.isnan(v):
                    j = k
                    best = v
                    break
                if v < best:
                    j = k
                    best = v
        if best < E0[u]:
            better[u] = True
            E0[u] = best
            for i in range(d):
                ZC[u, i, 0] = Z[u, i, j]
    return better


_energy_rows = jit.njit(_energy_rows)
_energy_numba = jit.njit(_energy_kernel)
_energy_many_numba = jit.njit(_energy_many_kernel)
# energy_from_products(P, ZT, d, const, L, w_k, w_s, sq=None) -> (M,): Eq. 15 of the M samples
# (columns of ZT, (d + 1, M), last row 1) from P = WT ZT ((d + 57 + K, M): the quadratic form's
# rows, the 57 segment coordinates by axis block, the K style rows); ``sq`` a (57, M) work array
# for the numpy twin
energy_from_products = jit.pick(_energy_numba, _energy_numpy)
# energy_many(P, ZT, d, const, L, w_k, w_s, sq=None) -> (U, M): the same for U users' stacked
# products (P (U, d + 57 + K, M), ZT (U, d + 1, M), const (U,)), the numbers of
# energy_from_products for each user
energy_many = jit.pick(_energy_many_numba, _energy_many_numpy)
_scale_samples_many_numba = jit.njit(_scale_samples_many_kernel)
_select_many_numba = jit.njit(_select_many_kernel)
# scale_samples_many(Z, SIG, ZC, d): in place, the first d rows of each user's samples Z
# (U, d + 1, M) times SIG (U, d, 1) plus ZC (U, d, 1) (the stochastic search's draws around
# each user's centre)
scale_samples_many = jit.pick(_scale_samples_many_numba, _scale_samples_many_numpy)
# select_many(E, Z, d, ZC, E0) -> (U,) bool: each user's best sample of E (U, M) (the first
# minimum) improves on E0 (U,): then ZC[u] (d, 1) <- that sample's Z[u, :d] and E0[u] <- its
# energy, in place
select_many = jit.pick(_select_many_numba, _select_many_numpy)

_warm = [False]


def warm_up() -> float:
    """Compile (or load from numba's cache) the kernels now, with the argument types of the real
    calls, rather than on a user's first frame; once per process, nothing without numba. Returns
    the time taken (s; 0 when numba is off or already done)."""
    if _warm[0] or energy_from_products is not _energy_numba:
        return 0.0
    _warm[0] = True
    t0 = time.perf_counter()
    d, m, k = 2, 4, 3
    P, ZT = np.ones((d + 3 * NUM_SEGMENTS + k, m)), np.ones((d + 1, m))
    L, sq = np.ones(NUM_SEGMENTS), np.empty((3 * NUM_SEGMENTS, m))
    for work in (None, sq):   # energy() passes no work array, the stochastic search one
        _energy_numba(P, ZT, d, 0.0, L, 1.0, 1.0, work)
    E = _energy_many_numba(P[None], ZT[None], d, np.zeros(1), L, 1.0, 1.0, sq)
    c = np.ones((1, d, 1))
    _scale_samples_many_numba(ZT[None], c, c, d)
    _select_many_numba(E, ZT[None], d, c, np.zeros(1))
    return time.perf_counter() - t0


__all__ = ['energy_from_products', 'energy_many', 'scale_samples_many', 'select_many', 'warm_up']
