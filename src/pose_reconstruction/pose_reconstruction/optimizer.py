"""Natural-posture-space optimizer, "method C" (Shum et al. 2013, Sec. V-B and VI; Table V).

Per frame, on a query posture already normalised and retargeted to the database's standard body:

1. reliability-weighted K nearest neighbours (Eq. 9, K = 30; :mod:`.search`);
2. local PCA of the neighbours: the natural posture space (20 dimensions);
3. minimise ``E = w_c E_c + w_s E_s + w_k E_k + w_m E_m`` (Eq. 10-15, weights 1.0, 0.5, 1.5,
   0.25) over the latent coordinates, with

   * ``E_c = sum_i R_i |x_i - q_i|^2``                  control (Eq. 9-10)
   * ``E_s = min_n sum_i |x_i - p^n_i|^2 / 20``          style, closest neighbour (Eq. 11)
   * ``E_k = sum_s (l_s(x) - L_s)^2 / 19``               kinematics, standard lengths (Eq. 12)
   * ``E_m = sum_i |x_i - 2 x^-1_i + x^-2_i|^2 / 20``    movement continuity (Eq. 13-14)

   ``solver='stochastic'`` is the paper's local stochastic search (``steps`` x ``samples``, warm
   started from the previous frame's solution, stopping as soon as no sample improves);
   ``solver='gauss_newton'`` minimises the same energy in the same latent space by Gauss-Newton
   (the closest neighbour of E_s and the segment directions of E_k re-linearised each iteration,
   everything else exactly quadratic), which is deterministic;
4. target joint orientations: the inverse-distance-weighted average of the neighbours'
   orientations (Markley average, geometry.quat_average).

Method B is this with every reliability 1 (``Reconstructor(use_reliability=False)``).
All costs are vectorised over samples, joints and neighbours.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, Optional, Sequence

import numpy as np

from skeleton_core.geometry import quat_average
from skeleton_core.model import (NUM_JOINTS, NUM_SEGMENTS, SEGMENT_CHILDREN, SEGMENT_CHILD_INDEX,
                                 SEGMENT_PARENTS, SEGMENT_PARENT_INDEX)
from skeleton_core import jit
from skeleton_core.params import check, param

from .posture_space import as_database_arrays
from .search import KNN_MODES, DatabaseSearch

kernels = jit.lazy_module('pose_reconstruction.kernels')   # (numba: when first used)


SOLVERS = ('stochastic', 'gauss_newton')
# flat coordinate indices of the segments' child and parent joints, by coordinate (the x of every
# segment, then y, then z): ``flat[_SEGX_C] - flat[_SEGX_P]`` is the (57,) segment vector block of
# the energy matrix (child - parent, one subtraction per component)
_SEGX_C = np.array([3 * c + k for k in range(3) for c in SEGMENT_CHILDREN])
_SEGX_P = np.array([3 * p + k for k in range(3) for p in SEGMENT_PARENTS])


def local_pca(Yc: np.ndarray, dims: int):
    """Principal axes of centred rows ``Yc`` (K, 60): ``(V (d, 60) orthonormal rows, singular
    values (d,))``, d <= dims, dropping numerically empty directions. For K < 60 the K x K Gram
    matrix is diagonalised (cheaper than an SVD of Yc)."""
    V, s, _ = _local_pca(Yc, dims)
    return V, s


def _local_pca(Yc: np.ndarray, dims: int, G: Optional[np.ndarray] = None, eig=None):
    """:func:`local_pca` plus the latent coordinates of the rows, ``Yc V^T`` (K, d) (from the
    Gram matrix ``G = Yc Yc^T`` when K < 60: ``U_d s``, no further product). ``eig``: the
    ``np.linalg.eigh`` of ``G`` when already computed (several users' at once)."""
    K, D = Yc.shape
    if K < D:
        lam, U = eig if eig is not None else np.linalg.eigh(Yc @ Yc.T if G is None else G)
        lam, U = lam[::-1], U[:, ::-1]
        keep = lam > max(lam[0], 1e-300) * 1e-10
        d = int(min(dims, keep.sum()))
        s = np.sqrt(lam[:d])
        Ud = U[:, :d]
        V = (Ud.T @ Yc) / s[:, None]
        zn = Ud * s
    else:
        _, s, vt = np.linalg.svd(Yc, full_matrices=False)
        keep = s > max(s[0], 1e-300) * 1e-5
        d = int(min(dims, keep.sum()))
        V, s = vt[:d], s[:d]
        zn = Yc @ V.T
    if d == 0:  # every neighbour identical: a zero-dimensional space (the mean only)
        return np.zeros((1, D)), np.zeros(1), np.zeros((K, 1))
    return V, s, zn


@dataclass
class OptimizerResult:
    positions: np.ndarray                 # (20, 3) normalised standard-body posture
    orientations: Optional[np.ndarray]    # (20, 4) normalised frame, or None
    neighbours: np.ndarray                # (K,) database indices
    distances: np.ndarray                 # (K,) Eq. 9 distances
    energy: float
    steps: int                            # optimisation iterations run
    timings_ms: Dict[str, float] = field(default_factory=dict)
    shift: Optional[np.ndarray] = None    # (3,) translation added to the query (translate=True)
    terms_fn: Optional[Callable[[], Dict[str, float]]] = field(default=None, repr=False)
    _terms: Optional[Dict[str, float]] = field(default=None, repr=False)

    @property
    def terms(self) -> Dict[str, float]:
        """The four energy terms of the solution (computed when first asked for)."""
        if self._terms is None:
            self._terms = self.terms_fn() if self.terms_fn is not None else {}
        return self._terms


@dataclass
class OptimizerConfig:
    """Parameters of methods B / C (:class:`NaturalPostureOptimizer`; Shum et al. 2013 Table V,
    Eq. 15)."""

    k: int = param(30, 'Table V: neighbours of the KNN search (Eq. 9)', range=(2, 1000))
    pca_dims: int = param(20, 'Table V: dimensions of the natural posture space', range=(1, 60),
                          public=False)
    steps: int = param(20, 'Table V: maximum optimisation steps', range=(0, 1000))
    samples: int = param(100, 'Table V: samples per optimisation step', range=(1, 100000))
    w_control: float = param(1.0, 'Eq. 15: weight of the control term E_c', range=(0.0, 1000.0),
                             public=False)
    w_style: float = param(8.0, 'Eq. 15: weight of the style term E_s (the paper: 0.5, '
                           'preset shum2013)', range=(0.0, 1000.0), public=False)
    w_kinematics: float = param(1.5, 'Eq. 15: weight of the kinematics term E_k',
                                range=(0.0, 1000.0), public=False)
    w_continuity: float = param(0.25, 'Eq. 15: weight of the continuity term E_m',
                                range=(0.0, 1000.0), public=False)
    step_scale: float = param(0.5, 'stochastic search: sample spread in neighbour standard '
                              'deviations', range=(1e-4, 100.0), public=False)
    solver: str = param('stochastic', 'stochastic (paper) or gauss_newton (deterministic)',
                        choices=SOLVERS, public=False)
    gn_iterations: int = param(6, 'gauss_newton: maximum iterations', range=(1, 1000),
                               public=False)
    seed: int = param(0, 'random seed of the stochastic search', range=(0, 2 ** 31 - 1),
                      public=False)
    knn: str = param('brute', 'KNN search: brute (exact BLAS) or kdtree (approximate)',
                     choices=KNN_MODES, public=False)
    kdtree_dims: int = param(12, 'kdtree: global PCA dimensions of the tree', range=(1, 60),
                             public=False)
    kdtree_candidates: int = param(4, 'kdtree: candidates fetched per neighbour', range=(1, 100),
                                   public=False)


_INT_PARAMS = tuple(n for n, t in OptimizerConfig.__annotations__.items() if t == 'int')
_FLOAT_PARAMS = tuple(n for n, t in OptimizerConfig.__annotations__.items() if t == 'float')


class NaturalPostureOptimizer:
    """Methods B/C core. Stateless apart from the RNG: the caller passes the previous solutions.
    Parameters: :class:`OptimizerConfig` fields as keywords (or ``config``)."""

    def __init__(self, db, config: Optional[OptimizerConfig] = None, **params):
        kernels.warm_up()   # the compiled kernels, once per process: not on a user's first frame
        self.db = as_database_arrays(db)
        self.body = self.db.body
        self.L = self.body.segment_lengths.copy()  # (19,)
        self._Lcol = self.L[:, None]
        self._X = self.db.flat
        self.search: Optional[DatabaseSearch] = None
        self.config = config or OptimizerConfig()
        self.configure(**params)
        self.rng = np.random.default_rng(self.seed)

    def configure(self, **kw) -> None:
        """Change parameters (validated against :class:`OptimizerConfig`)."""
        unknown = set(kw) - set(_INT_PARAMS) - set(_FLOAT_PARAMS) - {'solver', 'knn'}
        if unknown:
            raise ValueError(f'unknown optimizer parameters: {sorted(unknown)}')
        kw = {k: (int(v) if k in _INT_PARAMS else float(v) if k in _FLOAT_PARAMS else v)
              for k, v in kw.items()}
        cfg = dataclasses.replace(self.config, **kw)
        check(cfg)
        self.config = cfg
        # what must be equal for optimizers to be solved in one batch (solve_batch)
        self._batch_key = dataclasses.astuple(dataclasses.replace(cfg, seed=0))
        for name in _INT_PARAMS + _FLOAT_PARAMS + ('solver', 'knn'):
            setattr(self, name, getattr(cfg, name))
        self.k = min(self.k, self.db.size)
        if self.search is None:
            self.search = DatabaseSearch(self.db, self.k, self.knn, self.kdtree_dims,
                                         self.kdtree_candidates)
        else:
            self.search.configure(self.k, self.knn, self.kdtree_dims, self.kdtree_candidates)

    def reset_rng(self) -> None:
        self.rng = np.random.default_rng(self.seed)

    # -- energy -------------------------------------------------------------------------------
    def _setup(self, Y: np.ndarray, query: np.ndarray, weights: np.ndarray,
               continuity_target: Optional[np.ndarray], pre=None):
        """Local PCA of the neighbours ``Y`` (K, 60) and the constants of the energy.

        Every term is evaluated in the latent space: with ``x = mu + V^T z`` (V orthonormal rows)
        E_c is a quadratic form in z, |x - a|^2 = |z - z_a|^2 + |residual_a|^2 for E_s and E_m,
        and the segment vectors of E_k are affine in z (``seg0 + z dV``). The weighted sum of the
        quadratic and linear parts and every product with z are gathered into one matrix ``W``
        so that :meth:`energy` needs one matrix product per batch.
        ``pre``: ``(mu, Yc, G, eigh of G or None)`` already computed (:func:`solve_batch`).
        """
        K = len(Y)
        if pre is None:
            mu = Y.sum(axis=0) * (1.0 / K)
            Yc = Y - mu
            G = Yc @ Yc.T
            eig = None
        else:
            mu, Yc, G, eig = pre
        V, s, zn = _local_pca(Yc, self.pca_dims, G, eig)
        d = V.shape[0]
        znsq = np.einsum('kd,kd->k', zn, zn)
        res_n = np.maximum(np.diagonal(G) - znsq, 0.0)
        sd = s * (1.0 / np.sqrt(max(K - 1, 1)))
        q = query.ravel()
        w60 = np.repeat(weights, 3)
        mq = mu - q
        Vw = V * w60
        A_c = Vw @ V.T                                        # E_c = z A z + b z + c
        b_c = 2.0 * (Vw @ mq)
        c_c = float(mq @ (w60 * mq))
        zn_sq = znsq + res_n
        S = dict(mu=mu, V=V, zn=zn, zn_sq=zn_sq, res_n=res_n, sd=sd,
                 q=q, w60=w60, A_c=A_c, b_c=b_c, c_c=c_c, c=None)
        # fused energy: E = z Q z + [z W](linear) + const + w_s/20 min_n(zn_sq - 2 z zn) + w_k E_k
        # WT (d + 57 + K, d + 1) acting on [z; 1]: rows Q z + lin (so z.(Q z + lin) = quadratic +
        # linear part), the segment vectors seg0 + dV^T z by coordinate (x block, y, z), and
        # |z_n|^2 - 2 z_n.z per neighbour (E_s = min_n of it + |z|^2, the latter in Q)
        n3 = 3 * NUM_SEGMENTS
        WT = np.empty((d + n3 + K, d + 1))
        inv_j = 1.0 / NUM_JOINTS
        np.multiply(A_c, self.w_control, out=WT[:d, :d])       # Q
        Qdiag = WT.reshape(-1)[:d * (d + 2):d + 2]             # a view of Q's diagonal
        lin = self.w_control * b_c
        const = self.w_control * c_c
        if continuity_target is not None:
            c = continuity_target.ravel()
            zc = V @ (c - mu)
            cm = c - mu
            res_c = max(float(cm @ cm - zc @ zc), 0.0)
            S.update(c=c, zc=zc, res_c=res_c)
            lin = lin - (2.0 * self.w_continuity * inv_j) * zc
            const += self.w_continuity * inv_j * (float(zc @ zc) + res_c)
            Qdiag += self.w_continuity * inv_j
        Qdiag += self.w_style * inv_j                          # |z|^2 of E_s (min over n aside)
        WT[:d, d] = lin
        Vt = V.T
        np.subtract(Vt.take(_SEGX_C, axis=0), Vt.take(_SEGX_P, axis=0), out=WT[d:d + n3, :d])
        np.subtract(mu.take(_SEGX_C), mu.take(_SEGX_P), out=WT[d:d + n3, d])
        np.multiply(zn, -2.0, out=WT[d + n3:, :d])
        WT[d + n3:, d] = zn_sq
        S.update(WT=WT, const=const, d=d)
        return S

    @staticmethod
    def _segment_basis(S: dict):
        """``(seg0 (57,), dV (d, 57))``: the segment vectors (segment-major, x y z) of ``mu`` and
        of the principal axes, read back from the energy matrix."""
        d, n = S['d'], NUM_SEGMENTS
        blk = S['WT'][d:d + 3 * n]                             # (57, d + 1), by coordinate
        seg = blk.reshape(3, n, d + 1).transpose(1, 0, 2).reshape(3 * n, d + 1)
        return seg[:, d], seg[:, :d].T

    def _energy_t(self, ZT: np.ndarray, S: dict, P: Optional[np.ndarray] = None,
                  sq: Optional[np.ndarray] = None) -> np.ndarray:
        """Eq. 15 for samples stored as the columns of ``ZT`` (d + 1, M), last row 1 -> (M,).
        ``P`` (d + 57 + K, M) and ``sq`` (57, M): optional work arrays (reused across steps)."""
        P = np.matmul(S['WT'], ZT, out=P)
        return kernels.energy_from_products(P, ZT, S['d'], S['const'], self.L, self.w_kinematics,
                                    self.w_style, sq)

    def energy(self, Z: np.ndarray, S: dict) -> np.ndarray:
        """Eq. 15 for a batch of latent samples ``Z`` (M, d) -> (M,): the weighted sum of
        :meth:`energy_terms`, from one matrix product."""
        Z = np.asarray(Z, float)
        ZT = np.empty((Z.shape[1] + 1, Z.shape[0]))
        ZT[:-1] = Z.T
        ZT[-1] = 1.0
        return self._energy_t(ZT, S)

    def energy_terms(self, Z: np.ndarray, S: dict) -> Dict[str, np.ndarray]:
        zz = np.sum(Z * Z, axis=1)
        ec = np.sum((Z @ S['A_c']) * Z, axis=1) + Z @ S['b_c'] + S['c_c']          # Eq. 9-10
        dz = zz[:, None] - 2.0 * (Z @ S['zn'].T) + S['zn_sq'][None, :]
        es = np.maximum(dz.min(axis=1), 0.0) / NUM_JOINTS                          # Eq. 11
        seg0, dV = self._segment_basis(S)
        seg = (seg0 + Z @ dV).reshape(len(Z), NUM_SEGMENTS, 3)
        ln = np.sqrt(np.einsum('msk,msk->ms', seg, seg))
        ek = np.sum((ln - self.L) ** 2, axis=1) / NUM_SEGMENTS                     # Eq. 12
        if S['c'] is None:
            em = np.zeros(len(Z))
        else:                                                                      # Eq. 13-14
            em = (zz - 2.0 * (Z @ S['zc']) + S['zc'] @ S['zc'] + S['res_c']) / NUM_JOINTS
        return {'control': ec, 'style': es, 'kinematics': ek, 'continuity': em}

    # -- solvers ------------------------------------------------------------------------------
    def _stochastic(self, z0: np.ndarray, e0: float, S: dict):
        z, e = z0, e0
        sigma = self.step_scale * np.maximum(S['sd'], 1e-6)
        steps = 0
        d = len(z)
        ZT = np.empty((d + 1, self.samples))
        ZT[d] = 1.0
        sig = sigma[:, None]
        zc = np.asarray(z, float)[:, None]
        Z3, sig3 = ZT[None], sig[None]
        normal = self.rng.standard_normal
        Zs = ZT[:d]
        P = np.empty((S['WT'].shape[0], self.samples))
        sq = np.empty((3 * NUM_SEGMENTS, self.samples))
        for _ in range(self.steps):
            steps += 1
            normal(out=Zs)
            kernels.scale_samples_many(Z3, sig3, zc[None], d)   # Zs * sig + zc, in place
            E = self._energy_t(ZT, S, P, sq)
            j = int(E.argmin())
            ej = float(E[j])
            if ej < e:
                e = ej
                zc = ZT[:d, j:j + 1].copy()
            else:
                break  # no sample improves: stop (Sec. VI-E)
        z = zc[:, 0]
        return z, e, steps

    def _gauss_newton(self, z0: np.ndarray, e0: float, S: dict):
        V, mu = S['V'], S['mu']
        d = V.shape[0]
        Vt = V.T                                              # (60, d)
        wq = self.w_control * S['w60']
        # quadratic parts: w_c E_c + w_m E_m (+ w_s E_s for a fixed closest neighbour)
        H0 = (V * wq) @ Vt                                    # (d, d)
        g_c = (wq * (mu - S['q'])) @ Vt                       # gradient/2 of E_c at z = 0
        cm = 0.0 if S['c'] is None else self.w_continuity / NUM_JOINTS
        g_m = 0.0 if S['c'] is None else cm * ((mu - S['c']) @ Vt)
        cs = self.w_style / NUM_JOINTS
        ck = self.w_kinematics / NUM_SEGMENTS
        Vr = Vt.reshape(NUM_JOINTS, 3, d)
        dV = Vr[SEGMENT_CHILD_INDEX] - Vr[SEGMENT_PARENT_INDEX]                          # (19, 3, d)
        eye = np.eye(d)
        z, e = z0, e0
        it = 0
        for it in range(1, self.gn_iterations + 1):
            n = int(np.argmin(np.sum((S['zn'] - z) ** 2, axis=1)))  # closest neighbour (E_s)
            x = (mu + z @ V).reshape(NUM_JOINTS, 3)
            seg = x[SEGMENT_CHILD_INDEX] - x[SEGMENT_PARENT_INDEX]
            ln = np.linalg.norm(seg, axis=1)
            u = seg / np.maximum(ln, 1e-9)[:, None]
            Jk = np.einsum('sk,skd->sd', u, dV)                # (19, d)
            rk = ln - self.L - Jk @ z                          # l(z') ~ rk + Jk z'
            H = H0 + (cs + cm) * eye + ck * (Jk.T @ Jk)
            b = -(g_c + g_m - cs * S['zn'][n] + ck * (Jk.T @ rk))
            z_new = np.linalg.solve(H + 1e-9 * eye, b)
            e_new = float(self.energy(z_new[None], S)[0])
            if e_new < e:
                step = np.linalg.norm(z_new - z)
                z, e = z_new, e_new
                if step < 1e-6:
                    break
            else:
                break
        return z, e, it

    # -- one frame ----------------------------------------------------------------------------
    def solve(self, query: np.ndarray, weights: np.ndarray,
              previous: Sequence[np.ndarray] = (), translate: bool = False) -> OptimizerResult:
        """``query`` (20, 3) normalised standard-body posture, ``weights`` (20,) reliabilities,
        ``previous`` up to two earlier solutions, most recent first, in the query's frame.
        ``translate``: the query's origin (its root) is not trusted: the KNN search is translation
        invariant and the query is moved by the neighbours' inverse-distance-weighted mean
        translation (``OptimizerResult.shift``) before the optimisation."""
        t0 = time.perf_counter()
        w = np.asarray(weights, float)
        if w.min() < 0.0 or w.max() > 1.0:
            w = np.clip(w, 0.0, 1.0)
        w_knn = w if w.sum() > 1e-6 else np.ones_like(w)
        shift = None
        query = np.asarray(query, float)
        if translate:
            idx, dist, shifts = self.search.knn_search(query, w_knn, translate=True)
            inv = 1.0 / (dist + 1e-6)
            shift = (inv @ shifts) / inv.sum()
            query = query + shift
        else:
            idx, dist = self.search.knn_search(query, w_knn)
        t1 = time.perf_counter()
        if len(previous) >= 2:
            c = 2.0 * previous[0] - previous[1]
        elif len(previous) == 1:
            c = previous[0]
        else:
            c = None
        S = self._setup(self._X.take(idx, axis=0), query, w, c)
        t2 = time.perf_counter()
        # initial sample: best of the neighbours' mean, the previous solution and the nearest one
        starts = _initial_samples(S, previous)
        e_starts = self.energy(starts, S)
        j = int(e_starts.argmin())
        z0, e0 = starts[j], float(e_starts[j])
        if self.solver == 'gauss_newton':
            z, e, steps = self._gauss_newton(z0, e0, S)
        else:
            z, e, steps = self._stochastic(z0, e0, S)
        x = (S['mu'] + z @ S['V']).reshape(NUM_JOINTS, 3)
        t3 = time.perf_counter()
        ori = None
        if self.db.orientations is not None:
            inv = 1.0 / (dist + 1e-6)
            Q = self.db.orientations.take(idx, axis=0)        # (K, 20, 4)
            ori = quat_average(Q.swapaxes(0, 1), np.broadcast_to(inv, (NUM_JOINTS, len(idx))))
        t4 = time.perf_counter()
        zs = z[None]
        return OptimizerResult(
            positions=x, orientations=ori, neighbours=idx, distances=dist, energy=e,
            steps=steps, shift=shift, timings_ms={'knn': 1e3 * (t1 - t0), 'local_pca': 1e3 * (t2 - t1),
                                     'optimise': 1e3 * (t3 - t2), 'orientations': 1e3 * (t4 - t3)},
            terms_fn=lambda: {k: float(v[0]) for k, v in self.energy_terms(zs, S).items()})


def _initial_samples(S: dict, previous: Sequence[np.ndarray]) -> np.ndarray:
    """The search's candidate starts in the local space ``S``: the neighbours' mean (0), the
    nearest neighbour and, with a previous solution, that one."""
    V, mu = S['V'], S['mu']
    starts = np.empty((3 if len(previous) else 2, V.shape[0]))
    starts[0] = 0.0
    starts[1] = S['zn'][0]
    if len(previous):
        starts[2] = V @ (previous[0].ravel() - mu)
    return starts


def _batchable(opt: NaturalPostureOptimizer, first: NaturalPostureOptimizer) -> bool:
    """``opt`` can be solved in one batch with ``first``: the same database and parameters
    (the seed aside: every optimizer keeps its own random stream), the stochastic solver and
    the exact brute-force KNN."""
    return (opt._X is first._X and opt.solver == 'stochastic' and opt.search.batchable
            and opt._batch_key == first._batch_key)


def solve_batch(opts: Sequence[NaturalPostureOptimizer], queries: Sequence[np.ndarray],
                weights: Sequence[np.ndarray], previous: Sequence[Sequence[np.ndarray]],
                translate: Sequence[bool]) -> list:
    """:meth:`NaturalPostureOptimizer.solve` of several users' frames (one optimizer each, its
    own random stream) at once: one KNN matrix product over the database for every query whose
    root is reliable, the neighbours' Gram matrices and their eigendecompositions stacked, each
    step of the stochastic search one stacked matrix product and one energy kernel call for the
    users still searching, and the orientation averages stacked. The results are those of the
    users' own ``solve`` calls (the same random draws; distances to rounding). Optimizers that
    differ (parameters, solver, KNN mode, database) are solved one by one."""
    n = len(opts)
    if n == 0:
        return []
    first = opts[0]
    if n < 2 or not all(_batchable(o, first) for o in opts):
        return [o.solve(q, w, p, translate=t)
                for o, q, w, p, t in zip(opts, queries, weights, previous, translate)]
    t0 = time.perf_counter()
    ws, qs = [], []
    for w, q in zip(weights, queries):
        w = np.asarray(w, float)
        if w.min() < 0.0 or w.max() > 1.0:
            w = np.clip(w, 0.0, 1.0)
        ws.append(w)
        qs.append(np.asarray(q, float))
    knn = [None] * n
    shifts = [None] * n
    plain = [i for i in range(n) if not translate[i]]
    for i in range(n):
        if translate[i]:   # the translation-invariant search: one by one (an unreliable root)
            w_knn = ws[i] if ws[i].sum() > 1e-6 else np.ones_like(ws[i])
            idx, dist, sh = opts[i].search.knn_search(qs[i], w_knn, translate=True)
            inv = 1.0 / (dist + 1e-6)
            shifts[i] = (inv @ sh) / inv.sum()
            qs[i] = qs[i] + shifts[i]
            knn[i] = (idx, dist)
    if plain:
        # (np.array of a list of equal-shaped arrays: np.stack's array, ~3 us less dispatch)
        W = np.array([ws[i] if ws[i].sum() > 1e-6 else np.ones_like(ws[i]) for i in plain])
        IDX, DIST = first.search.knn_search_many(np.array([qs[i] for i in plain]), W)
        for r, i in enumerate(plain):
            knn[i] = (IDX[r], DIST[r])
    t1 = time.perf_counter()
    conts = []
    for p in previous:
        conts.append(2.0 * p[0] - p[1] if len(p) >= 2 else p[0] if len(p) == 1 else None)
    K = first.k
    IDX = np.array([knn[i][0] for i in range(n)])
    Y = first._X.take(IDX.ravel(), axis=0).reshape(n, K, -1)
    mu = Y.sum(axis=1) * (1.0 / K)
    Yc = Y - mu[:, None, :]
    G = Yc @ Yc.swapaxes(1, 2)
    eig = np.linalg.eigh(G) if K < Y.shape[2] else None
    Ss = _setup_many(opts, Y, mu, Yc, G, eig, qs, ws, conts)
    t2 = time.perf_counter()
    # initial sample of each user: the best of the neighbours' mean, the previous solution and
    # the nearest neighbour (as solve), evaluated for the users of one shape at once
    starts = [_initial_samples(S, p) for S, p in zip(Ss, previous)]
    zs, es, steps = [None] * n, [0.0] * n, [0] * n
    by_start: Dict[tuple, list] = {}
    for i, S in enumerate(Ss):
        by_start.setdefault((S['WT'].shape, len(starts[i])), []).append(i)
    for members in by_start.values():
        d = Ss[members[0]]['d']
        ZT = np.ones((len(members), d + 1, len(starts[members[0]])))
        for r, i in enumerate(members):
            ZT[r, :d] = starts[i].T
        P = np.matmul(np.array([Ss[i]['WT'] for i in members]), ZT)
        E = kernels.energy_many(P, ZT, d, np.array([Ss[i]['const'] for i in members]),
                                first.L, first.w_kinematics, first.w_style)
        for r, i in enumerate(members):
            j = int(E[r].argmin())
            zs[i], es[i] = starts[i][j], float(E[r, j])
    groups: Dict[tuple, list] = {}
    for i, S in enumerate(Ss):   # the same latent dimension and neighbours: one stacked search
        groups.setdefault(S['WT'].shape, []).append(i)
    for members in groups.values():
        _stochastic_many(opts, Ss, members, zs, es, steps)
    t3 = time.perf_counter()
    X = [(S['mu'] + z @ S['V']).reshape(NUM_JOINTS, 3) for S, z in zip(Ss, zs)]
    oris = [None] * n
    if first.db.orientations is not None:
        DIST = np.array([knn[i][1] for i in range(n)])
        inv = 1.0 / (DIST + 1e-6)                                            # (n, K)
        Q = first.db.orientations.take(IDX, axis=0)                          # (n, K, 20, 4)
        avg = quat_average(Q.swapaxes(1, 2),
                           np.broadcast_to(inv[:, None, :], (n, NUM_JOINTS, K)))
        oris = list(avg)
    t4 = time.perf_counter()
    share = 1e3 / n
    timings = {'knn': share * (t1 - t0), 'local_pca': share * (t2 - t1),
               'optimise': share * (t3 - t2), 'orientations': share * (t4 - t3)}
    out = []
    for i, (o, S) in enumerate(zip(opts, Ss)):
        zi = zs[i][None]
        out.append(OptimizerResult(
            positions=X[i], orientations=oris[i], neighbours=knn[i][0], distances=knn[i][1],
            energy=es[i], steps=steps[i], shift=shifts[i], timings_ms=dict(timings),
            terms_fn=lambda o=o, zi=zi, S=S: {k: float(v[0])
                                               for k, v in o.energy_terms(zi, S).items()}))
    return out


def _stochastic_many(opts, Ss, members, zs, es, steps) -> None:
    """:meth:`NaturalPostureOptimizer._stochastic` of the users ``members`` (the same energy
    matrix shape), step by step together: each draws its samples from its own random stream, as
    alone; a user whose samples do not improve stops (Sec. VI-E), the others go on. Updates
    ``zs``, ``es``, ``steps`` in place."""
    first = opts[members[0]]
    M, n_steps = first.samples, first.steps
    if n_steps <= 0:
        return
    d = Ss[members[0]]['d']
    act = list(members)
    u = len(act)
    Z = np.empty((u, d + 1, M))
    Z[:, d] = 1.0
    WT = np.array([Ss[i]['WT'] for i in act])
    SIG = np.array([opts[i].step_scale * np.maximum(Ss[i]['sd'], 1e-6) for i in act])[:, :, None]
    ZC = np.array([np.asarray(zs[i], float) for i in act])[:, :, None]
    const = np.array([Ss[i]['const'] for i in act])
    E0 = np.array([es[i] for i in act])
    P = np.empty((u, WT.shape[1], M))
    rngs = [opts[i].rng.standard_normal for i in act]
    L, w_k, w_s = first.L, first.w_kinematics, first.w_style
    for k in range(1, n_steps + 1):
        for r, normal in enumerate(rngs):
            normal(out=Z[r, :d])
        kernels.scale_samples_many(Z, SIG, ZC, d)
        np.matmul(WT, Z, out=P)
        E = kernels.energy_many(P, Z, d, const, L, w_k, w_s)
        better = kernels.select_many(E, Z, d, ZC, E0)   # the improving users' new centres
        go = better if k < n_steps else np.zeros(u, bool)
        if go.all():
            continue
        for r, i in enumerate(act):    # the users that stop here: their result
            if not go[r]:
                zs[i], es[i], steps[i] = ZC[r, :, 0].copy(), float(E0[r]), k
        if not go.any():
            return
        keep = np.flatnonzero(go)
        act = [act[r] for r in keep]
        rngs = [rngs[r] for r in keep]
        u = len(act)
        Z, WT, SIG, ZC = Z[keep], WT[keep], SIG[keep], ZC[keep]
        const, E0 = const[keep], E0[keep]
        P = np.empty((u, WT.shape[1], M))


def _setup_many(opts, Y, mu, Yc, G, eig, qs, ws, conts) -> list:
    """:meth:`NaturalPostureOptimizer._setup` of stacked users (``Y`` (n, K, 60) and its
    ``mu``, ``Yc``, ``G``, ``eig``): the users whose local PCA keeps every one of ``pca_dims``
    dimensions and who have a continuity target (every frame after a user's first) as stacked
    array operations, the others one by one. The same numbers to rounding."""
    n, K, D = Y.shape
    first = opts[0]
    dims = first.pca_dims
    out = [None] * n
    full = []
    if eig is not None and dims < K:
        lam = eig[0][:, ::-1]
        keep = lam > np.maximum(lam[:, 0], 1e-300)[:, None] * 1e-10
        full = [i for i in range(n) if conts[i] is not None and keep[i].sum() >= dims]
    for i in range(n):
        if not full or i not in full:
            out[i] = opts[i]._setup(Y[i], qs[i], ws[i], conts[i],
                                    pre=(mu[i], Yc[i], G[i],
                                         None if eig is None else (eig[0][i], eig[1][i])))
    if not full:
        return out
    f = np.array(full)
    d = dims
    s = np.sqrt(lam[f, :d])                                               # (m, d)
    Ud = eig[1][f][:, :, ::-1][:, :, :d]                                   # (m, K, d)
    V = (Ud.swapaxes(1, 2) @ Yc[f]) / s[:, :, None]                    # (m, d, 60)
    zn = Ud * s[:, None, :]                                                # (m, K, d)
    znsq = np.einsum('mkd,mkd->mk', zn, zn)
    res_n = np.maximum(np.diagonal(G[f], axis1=1, axis2=2) - znsq, 0.0)
    sd = s * (1.0 / np.sqrt(max(K - 1, 1)))
    Q = np.array([np.asarray(qs[i], float).ravel() for i in full])         # (m, 60)
    W60 = np.repeat(np.array([ws[i] for i in full]), 3, axis=1)            # (m, 60)
    MU = mu[f]
    mq = MU - Q
    Vw = V * W60[:, None, :]
    A_c = Vw @ V.swapaxes(1, 2)                                        # (m, d, d)
    b_c = 2.0 * np.einsum('mdj,mj->md', Vw, mq)
    c_c = np.einsum('mj,mj->m', mq, W60 * mq)
    zn_sq = znsq + res_n
    C = np.array([conts[i].ravel() for i in full])
    cm = C - MU
    zc = np.einsum('mdj,mj->md', V, cm)
    res_c = np.maximum(np.einsum('mj,mj->m', cm, cm) - np.einsum('md,md->m', zc, zc), 0.0)
    wc = np.array([opts[i].w_control for i in full])
    wm = np.array([opts[i].w_continuity for i in full])
    wsty = np.array([opts[i].w_style for i in full])
    inv_j = 1.0 / NUM_JOINTS
    n3 = 3 * NUM_SEGMENTS
    WT = np.empty((len(full), d + n3 + K, d + 1))
    np.multiply(A_c, wc[:, None, None], out=WT[:, :d, :d])
    diag = np.arange(d)
    WT[:, diag, diag] += (wm * inv_j)[:, None]         # E_m's |z|^2, then E_s's, as _setup
    WT[:, diag, diag] += (wsty * inv_j)[:, None]
    WT[:, :d, d] = wc[:, None] * b_c - (2.0 * wm * inv_j)[:, None] * zc
    const = wc * c_c + wm * inv_j * (np.einsum('md,md->m', zc, zc) + res_c)
    Vt = V.swapaxes(1, 2)
    np.subtract(Vt[:, _SEGX_C], Vt[:, _SEGX_P], out=WT[:, d:d + n3, :d])
    np.subtract(MU[:, _SEGX_C], MU[:, _SEGX_P], out=WT[:, d:d + n3, d])
    np.multiply(zn, -2.0, out=WT[:, d + n3:, :d])
    WT[:, d + n3:, d] = zn_sq
    for r, i in enumerate(full):
        out[i] = dict(mu=MU[r], V=V[r], zn=zn[r], zn_sq=zn_sq[r], res_n=res_n[r], sd=sd[r],
                      q=Q[r], w60=W60[r], A_c=A_c[r], b_c=b_c[r], c_c=float(c_c[r]),
                      c=C[r], zc=zc[r], res_c=float(res_c[r]), WT=WT[r], const=float(const[r]),
                      d=d)
    return out
