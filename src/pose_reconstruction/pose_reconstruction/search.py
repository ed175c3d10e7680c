"""The database searches of the reconstruction, in one place (Shum et al. 2013, Eq. 9).

* :meth:`DatabaseSearch.knn_search` — the K nearest postures under the reliability-weighted
  distance of Eq. 9, optionally minimised over a translation (unreliable root); brute force (two
  BLAS products over the database) or a cKDTree proposal re-ranked exactly;
* :meth:`DatabaseSearch.knn_scaled` — the same minimised over a uniform scale too (the user's
  height not measured yet), ranked by a scale-free shape distance;
* :meth:`DatabaseSearch.database_yaw` — the rotation about the vertical by which the reliable
  joints are off the database (per posture a closed-form weighted 2-D Procrustes).

The database matrices they use are computed once per database and shared read-only by every user
(:func:`knn_arrays`, :func:`yaw_arrays`, kept in ``DatabaseArrays.derived``).
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from skeleton_core.model import NUM_JOINTS

from .posture_space import as_database_arrays

KNN_MODES = ('brute', 'kdtree')
# From this many postures on, the brute-force KNN screens the database in single precision (half
# the memory traffic of the matrix-vector product that dominates a large database's frame) and
# ranks the best SCREEN_FACTOR * K candidates exactly in double precision: the same neighbours
# unless a true neighbour falls out of a candidate list many times longer than K.
SCREEN_FROM = 8192
SCREEN_FACTOR = 4


def knn_arrays(db) -> tuple:
    """The database matrices of the KNN searches, computed once per database (shared read-only
    by every optimizer on it: a new user costs no pass over the database):
    ``|x_j|^2`` (N, 20); Eq. 9 for every posture as one matrix-vector product,
    ``[|x_j|^2 (20) | x (60)] . [w | -2 w q]`` (N, 80); and the coordinate rows of every posture
    (N * 3, 20), for weighted centroids (translate=True)."""
    arrays = db.derived.get('knn')
    if arrays is None:
        sq = np.einsum('njd,njd->nj', db.positions, db.positions)
        XA = np.ascontiguousarray(np.hstack((sq, db.flat)))
        coord = np.ascontiguousarray(db.positions.transpose(0, 2, 1).reshape(-1, NUM_JOINTS),
                                     dtype=float)
        for a in (sq, XA, coord):
            a.setflags(write=False)
        arrays = db.derived['knn'] = (sq, XA, coord)
    return arrays


def screen_arrays(db):
    """Single-precision copies of the KNN matrices (``XA``, ``coord``) for a large database,
    computed once per database and shared; None below SCREEN_FROM postures."""
    if db.size < SCREEN_FROM:
        return None
    arrays = db.derived.get('knn32')
    if arrays is None:
        _, XA, coord = knn_arrays(db)
        arrays = (np.ascontiguousarray(XA, dtype=np.float32),
                  np.ascontiguousarray(coord, dtype=np.float32))
        for a in arrays:
            a.setflags(write=False)
        db.derived['knn32'] = arrays
    return arrays


def yaw_arrays(db) -> tuple:
    """The database's horizontal coordinates as complex numbers (N, 20) and heights (N, 20),
    computed once per database and shared."""
    arrays = db.derived.get('yaw')
    if arrays is None:
        P = db.positions
        Yh = np.ascontiguousarray(P[..., 0] + 1j * P[..., 1])
        Yz = np.ascontiguousarray(P[..., 2], dtype=float)
        for x in (Yh, Yz):
            x.setflags(write=False)
        arrays = db.derived['yaw'] = (Yh, Yz)
    return arrays


class DatabaseSearch:
    """Searches of one database (shared arrays) with this user's K and KNN mode (the values of
    :class:`~.optimizer.OptimizerConfig`)."""

    def __init__(self, db, k: int, knn: str, kdtree_dims: int, kdtree_candidates: int):
        self.db = as_database_arrays(db)
        self._X = self.db.flat
        self.arrays = knn_arrays(self.db)
        self._Xsq_joint, self._XA, self._Xcoord = self.arrays
        self._screen = screen_arrays(self.db)
        self._kdtree = None
        self.k = 0
        self.knn = knn
        self.kdtree_dims = int(kdtree_dims)
        self.kdtree_candidates = int(kdtree_candidates)
        self.configure(k=k, knn=knn, kdtree_dims=kdtree_dims, kdtree_candidates=kdtree_candidates)

    def configure(self, k: int, knn: str, kdtree_dims: int, kdtree_candidates: int) -> None:
        """Set K (capped at the database size) and the KNN mode; (re)builds the k-d tree when
        the mode or its dimension changes. Values are validated by the caller."""
        if knn not in KNN_MODES:
            raise ValueError(f'knn must be one of {KNN_MODES}')
        rebuild = knn == 'kdtree' and (knn != self.knn or int(kdtree_dims) != self.kdtree_dims
                                       or self._kdtree is None)
        self.k = min(int(k), self.db.size)
        self.knn, self.kdtree_dims = knn, int(kdtree_dims)
        self.kdtree_candidates = int(kdtree_candidates)
        if rebuild:
            self._build_kdtree()

    def _build_kdtree(self) -> None:
        from scipy.spatial import cKDTree   # (only knn='kdtree': scipy.spatial takes 0.3 s to import)
        X = self._X
        self._kd_mean = X.mean(axis=0)
        _, _, vt = np.linalg.svd(X - self._kd_mean, full_matrices=False)
        self._kd_axes = vt[:self.kdtree_dims]
        self._kdtree = cKDTree((X - self._kd_mean) @ self._kd_axes.T)

    def knn_search(self, query: np.ndarray, weights: np.ndarray, translate: bool = False):
        """K nearest database postures under Eq. 9 with per-joint ``weights`` (20,).

        ``translate``: the distance is minimised over a translation of the query (for a query
        whose root, and so its origin, is unreliable): ``sum_i w_i |x_i - q_i - t|^2`` at the best
        ``t`` = weighted centroid of x - that of q. Returns ``(idx, distances, t (K, 3))`` then.

        ``knn='brute'``: exact, two BLAS matrix-vector products over the whole database (from
        SCREEN_FROM postures on in single precision, the best candidates re-ranked in double).
        ``knn='kdtree'``: approximate; a cKDTree in a global PCA space proposes
        ``kdtree_candidates * K`` postures (unreliable joints filled from the database mean),
        which are re-ranked exactly by Eq. 9.
        """
        w = np.asarray(weights, float)
        q = np.asarray(query, float)
        if self.knn == 'kdtree' and self._kdtree is not None:
            qf = np.where((w >= 0.5)[:, None], q, self._kd_mean.reshape(NUM_JOINTS, 3)).ravel()
            m = min(self.db.size, self.k * self.kdtree_candidates)
            _, cand = self._kdtree.query((qf - self._kd_mean) @ self._kd_axes.T, k=m)
            cand = np.atleast_1d(cand)
            P = self.db.positions[cand]
            d = np.einsum('njd,j->n', (P - q) ** 2, w)
            order = np.argsort(d)[:self.k]
            return cand[order], d[order]
        wq = w[:, None] * q
        v = np.concatenate((w, -2.0 * wq.ravel()))
        if self._screen is not None and SCREEN_FACTOR * self.k < self.db.size:
            return self._knn_screened(v, w, wq, q, translate)
        d = self._XA @ v
        d += float(np.einsum('jd,jd->', wq, q))
        if translate:
            ws = max(float(w.sum()), 1e-12)
            shift = (self._Xcoord @ w).reshape(-1, 3)
            shift -= wq.sum(axis=0)
            shift *= 1.0 / ws
            d -= ws * np.einsum('nd,nd->n', shift, shift)
        k = self.k
        idx = d.argpartition(k - 1)[:k] if k < len(d) else np.arange(len(d))
        dk = d[idx]
        order = np.argsort(dk)
        dk = dk[order]
        np.maximum(dk, 0.0, out=dk)
        idx = idx[order]
        if translate:
            return idx, dk, shift[idx]
        return idx, dk

    @property
    def batchable(self) -> bool:
        """:meth:`knn_search_many` gives :meth:`knn_search`'s neighbours (exact brute force, no
        single-precision screening)."""
        return self.knn == 'brute' and not (self._screen is not None
                                            and SCREEN_FACTOR * self.k < self.db.size)

    def knn_search_many(self, queries: np.ndarray, weights: np.ndarray):
        """:meth:`knn_search` (brute force, no translation) of several queries (U, 20, 3) with
        their weights (U, 20) in one matrix product over the database: ``(idx (U, K),
        distances (U, K))``. Only when :attr:`batchable`. The distances equal the one-query
        search's to rounding (a matrix product instead of matrix-vector products)."""
        W = np.asarray(weights, float)
        Q = np.asarray(queries, float)
        WQ = W[:, :, None] * Q
        Vm = np.concatenate((W, -2.0 * WQ.reshape(len(W), -1)), axis=1)       # (U, 80)
        XAT = self.db.derived.get('knn_T')
        if XAT is None:   # (80, N) contiguous: a small-U product over it is 2-3x faster
            XAT = self.db.derived['knn_T'] = np.ascontiguousarray(self._XA.T)
            XAT.setflags(write=False)
        D = Vm @ XAT                                                          # (U, N)
        D += np.einsum('ujd,ujd->u', WQ, Q)[:, None]
        k = self.k
        if k < D.shape[1]:
            idx = D.argpartition(k - 1, axis=1)[:, :k]
        else:
            idx = np.broadcast_to(np.arange(D.shape[1]), D.shape)
        # np.take_along_axis's gathers, indexed directly (the same arrays, less dispatch)
        rows = np.arange(len(D))[:, None]
        dk = D[rows, idx]
        order = dk.argsort(axis=1)
        dk = dk[rows, order]
        np.maximum(dk, 0.0, out=dk)
        return idx[rows, order], dk

    def _knn_screened(self, v, w, wq, q, translate: bool):
        """:meth:`knn_search` (brute) of a large database: Eq. 9 screened in single precision,
        the best ``SCREEN_FACTOR * k`` re-ranked exactly."""
        XA32, coord32 = self._screen
        d32 = XA32 @ v.astype(np.float32)
        ws = max(float(w.sum()), 1e-12)
        if translate:
            shift32 = (coord32 @ w.astype(np.float32)).reshape(-1, 3)
            shift32 -= wq.sum(axis=0).astype(np.float32)
            shift32 *= np.float32(1.0 / ws)
            d32 -= np.float32(ws) * np.einsum('nd,nd->n', shift32, shift32)
        m = SCREEN_FACTOR * self.k
        cand = np.argpartition(d32, m - 1)[:m]
        d = self._XA[cand] @ v
        d += float(np.einsum('jd,jd->', wq, q))
        if translate:
            shift = self._Xcoord.reshape(-1, 3, NUM_JOINTS)[cand] @ w
            shift -= wq.sum(axis=0)
            shift *= 1.0 / ws
            d -= ws * np.einsum('nd,nd->n', shift, shift)
        order = np.argsort(d)[:self.k]
        idx, dk = cand[order], np.maximum(d[order], 0.0)
        if translate:
            return idx, dk, shift[order]
        return idx, dk

    def knn_scaled(self, query: np.ndarray, weights: np.ndarray, translate: bool = False,
                   scale_range: tuple = (0.5, 2.0)):
        """K nearest database postures under Eq. 9 minimised over a uniform scale ``s`` of the
        query (in ``scale_range``) and, with ``translate``, a translation:
        ``sum_i w_i |x_i - s q_i - t|^2``. For a query whose size is unknown (the user's height
        not measured yet). Exact (brute force, a few BLAS products over the database).
        Returns ``(idx (K,), distances (K,), scales (K,))``."""
        w = np.asarray(weights, float)
        q = np.asarray(query, float)
        wq = w[:, None] * q
        sxx = self._Xsq_joint @ w                              # sum_i w_i |x_i|^2
        sxq = self._X @ wq.ravel()                             # sum_i w_i x_i . q_i
        sqq = float(np.einsum('jd,jd->', wq, q))
        if translate:
            ws = max(float(w.sum()), 1e-12)
            cx = (self._Xcoord @ w).reshape(-1, 3) * (1.0 / ws)    # weighted centroids
            cq = wq.sum(axis=0) * (1.0 / ws)
            sxx = sxx - ws * np.einsum('nd,nd->n', cx, cx)
            sxq = sxq - ws * (cx @ cq)
            sqq -= ws * float(cq @ cq)
        sqq = max(sqq, 1e-12)
        s = np.clip(sxq * (1.0 / sqq), scale_range[0], scale_range[1])
        # rank by the scale-free shape distance 1 - cos^2 of the two (centred) configurations:
        # Eq. 9 at the best scale, sxx - sxq^2 / sqq, would favour compact database postures
        # (shrinking the query towards them costs little)
        d = 1.0 - np.maximum(sxq, 0.0) ** 2 / (np.maximum(sxx, 1e-12) * sqq)
        k = self.k
        idx = np.argpartition(d, k - 1)[:k] if k < len(d) else np.arange(len(d))
        idx = idx[np.argsort(d[idx])]
        return idx, np.maximum(d[idx], 0.0), s[idx]

    def database_yaw(self, query: np.ndarray, w: np.ndarray, centre: bool, scaled: bool = False,
                     neighbours: int = 5, threshold: float = 0.5) -> Optional[float]:
        """The rotation about the vertical by which the reliable joints of ``query`` (20, 3) are
        off the database: Eq. 9 over the reliable joints minimised, for every database posture,
        over that rotation (closed-form weighted 2-D Procrustes; with ``centre``, i.e. the root
        unreliable, over a translation too: weighted centroids removed); the circular
        inverse-distance weighted mean of the rotations of the ``neighbours`` nearest.
        Unlike a fit to the KNN neighbours of the query at its current heading, which favour
        that heading, no heading is preferred. ``scaled``: minimised over a uniform scale of the
        query as well (while the user's height is not known). None with fewer than two reliable
        joints."""
        rel = w >= threshold
        if rel.sum() < 2:
            return None
        wr = np.where(rel, w, 0.0)
        ws = float(wr.sum())
        q = np.where(rel[:, None], query, 0.0)  # the other rows do not count (nor a NaN there)
        if centre:
            q = q - (wr @ q) * (1.0 / ws)
        Yh, Yz = yaw_arrays(self.db)
        sq, coord = self._Xsq_joint, self._Xcoord
        # sum_j w_j conj(q_j) y_j with the horizontal coordinates as complex numbers: its angle
        # is the best rotation of q onto y, and sum_j w_j |y_j - rot q_j|^2 (horizontal) is
        # sum_j w_j (|y_j|^2 + |q_j|^2) - 2 |c| at that rotation. With q centred, y's centroid
        # drops out of c and of the vertical cross term and leaves -|w| |centroid|^2.
        c = Yh @ (wr * (q[:, 0] - 1j * q[:, 1]))                   # (N,)
        ac = np.abs(c)
        syy = sq @ wr                                               # sum_j w_j |y_j|^2
        if centre:
            yc = (coord @ wr).reshape(-1, 3)
            syy -= np.einsum('nd,nd->n', yc, yc) * (1.0 / ws)
        sqq = float(wr @ np.einsum('jd,jd->j', q, q))
        sxq = Yz @ (wr * q[:, 2])                                  # the vertical: not rotated
        sxq += ac
        if scaled:
            # minimised over a uniform scale of the query too: the shape distance of
            # knn_scaled (the user's height is not known yet)
            d = 1.0 - np.maximum(sxq, 0.0) ** 2 / (np.maximum(syy, 1e-12) * max(sqq, 1e-12))
        else:
            d = syy - 2.0 * sxq
            d += sqq
        k = min(int(neighbours), len(d))
        idx = np.argpartition(d, k - 1)[:k]
        a = ac[idx]
        if a.max() < 1e-9:
            return None
        inv = 1.0 / (np.maximum(d[idx], 0.0) + 1e-6)
        return float(np.angle(inv @ (c[idx] / np.maximum(a, 1e-12))))
