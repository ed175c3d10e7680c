"""A message's users reconstructed together (reconstructor.process_batch, optimizer.solve_batch,
FusedProcessor.process_batch) give what each user's own Reconstructor gives, frame by frame."""
import numpy as np
import pytest

from pose_reconstruction import kernels
from pose_reconstruction.fused import FusedProcessor
from pose_reconstruction.optimizer import NaturalPostureOptimizer, solve_batch
from pose_reconstruction.posture_space import as_database_arrays
from pose_reconstruction.reconstructor import Reconstructor, process_batch
from pose_reconstruction.synthetic import corrupt_clip, random_database, smooth_clip
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import HIP_CENTER, INFERRED, NUM_JOINTS

FRAMES = 60


@pytest.fixture(scope='module')
def db():
    return as_database_arrays(random_database(1500, seed=3))


@pytest.fixture(scope='module')
def streams():
    """Four users at different places and heights; the third one's root is occluded (INFERRED
    and 15 cm off) for a third of the clip, so its KNN search is the translation-invariant one."""
    out = []
    for u in range(4):
        _, truth = smooth_clip(FRAMES, seed=30 + u, height=1.5 + 0.08 * u)
        truth = truth + np.array([0.6 * u - 0.9, 0.1 * u, 0.0])
        obs, ts = corrupt_clip(truth, seed=40 + u)
        if u == 2:
            obs[20:40, HIP_CENTER] += (0.0, 0.15, -0.1)
            ts[20:40, HIP_CENTER] = INFERRED
        out.append((obs, ts))
    return out


def _frames(streams, t, users=None):
    users = range(len(streams)) if users is None else users
    return [SkeletonFrame(positions=streams[u][0][t], tracking_state=streams[u][1][t],
                          user_id=u + 1, stamp_ns=(t + 1) * 33_333_333, frame_id='kinect')
            for u in users]


def _same(a, b):
    assert not isinstance(b, Exception), b
    np.testing.assert_allclose(b.positions, a.positions, rtol=0, atol=1e-9)
    assert (a.orientations is None) == (b.orientations is None)
    if a.orientations is not None:
        np.testing.assert_allclose(b.orientations, a.orientations, rtol=0, atol=1e-9)
    assert np.array_equal(b.reliability, a.reliability)
    assert b.user_id == a.user_id and b.stamp_ns == a.stamp_ns


def test_batched_users_equal_each_users_own_reconstruction(db, streams):
    """Each user keeps its own random stream (here: its own seed), so the stochastic search
    draws the same samples as alone: the same neighbours, steps and outputs every frame."""
    kw = [dict(seed=u) for u in range(len(streams))]
    alone = [Reconstructor(db, **k) for k in kw]
    batch = [Reconstructor(db, **k) for k in kw]
    translated = 0
    for t in range(FRAMES):
        frames = _frames(streams, t)
        ref = [r.process(f) for r, f in zip(alone, frames)]
        out = process_batch(batch, frames)
        for a, b, ra, rb in zip(ref, out, alone, batch):
            _same(a, b)
            assert np.array_equal(rb.last_result.neighbours, ra.last_result.neighbours)
            assert rb.last_result.steps == ra.last_result.steps
            assert rb.last_result.energy == pytest.approx(ra.last_result.energy, abs=1e-9)
            translated += rb.last_result.shift is not None
    assert translated >= 10   # the occluded root went through the batch too
    # the stochastic search ran several steps (the batched one stops each user on its own)
    assert len({r.last_result.steps for r in batch}) >= 1 and max(
        r.last_result.steps for r in batch) >= 2


def test_users_joining_and_leaving_and_other_settings(db, streams):
    """A batch of users with other settings (the Gauss-Newton solver, another K) is solved one
    by one and still equals the users alone; users joining later start their own state."""
    kw = [dict(seed=1), dict(solver='gauss_newton'), dict(seed=2, k=12), dict(seed=3)]
    alone = [Reconstructor(db, **k) for k in kw]
    batch = [Reconstructor(db, **k) for k in kw]
    for t in range(30):
        users = [0, 1] if t < 10 else [0, 2, 3] if t < 20 else [0, 1, 2, 3]
        frames = _frames(streams, t, users)
        ref = [alone[u].process(f) for u, f in zip(users, frames)]
        out = process_batch([batch[u] for u in users], frames)
        for a, b in zip(ref, out):
            _same(a, b)


def test_fused_processors_in_one_batch_equal_each_alone(db, streams):
    """The node's processors with every output wanted (reliability, completion): the batched
    call gives each user's own tuple; a processor given twice in a message goes frame after
    frame."""
    values = {'optimizer.k': 20, 'completion.pca_dims': 7}
    alone = [FusedProcessor(db, values) for _ in streams]
    batch = [FusedProcessor(db, values) for _ in streams]
    for t in range(25):
        wanted = (True, t % 2 == 0, t >= 10)
        frames = _frames(streams, t)
        ref = [p.process(f, wanted) for p, f in zip(alone, frames)]
        out = FusedProcessor.process_batch(batch, frames, wanted)
        for a, b in zip(ref, out):
            assert not isinstance(b, Exception), b
            _same(a[0], b[0])
            for x, y in zip(a[1:], b[1:]):
                assert (x is None) == (y is None)
                if x is not None:
                    _same(x, y)
    twice = [FusedProcessor(db, values)]
    f0, f1 = _frames(streams, 0, [0]), _frames(streams, 1, [0])
    ref = FusedProcessor(db, values)
    expect = [ref.process(f0[0], (True, False, False)), ref.process(f1[0], (True, False, False))]
    got = FusedProcessor.process_batch(twice * 2, f0 + f1, (True, False, False))
    for a, b in zip(expect, got):
        _same(a[0], b[0])


def test_a_users_bad_frame_stays_that_users(db, streams):
    """An exception in one user's frame is returned in its place; the others are computed."""
    recs = [Reconstructor(db, seed=u) for u in range(3)]
    ref = [Reconstructor(db, seed=u) for u in range(3)]
    frames = _frames(streams, 0, [0, 1, 2])
    broken = frames[1].copy()
    broken.positions = np.full((NUM_JOINTS, 2), 0.0)   # not (20, 3): the reliability refuses it
    out = process_batch(recs, [frames[0], broken, frames[2]])
    assert isinstance(out[1], Exception)
    _same(ref[0].process(frames[0]), out[0])
    _same(ref[2].process(frames[2]), out[2])


def test_batched_knn_equals_one_query_search(db):
    opt = NaturalPostureOptimizer(db, k=25)
    rng = np.random.default_rng(4)
    Q = np.asarray(db.positions[[3, 500, 900]], float) + rng.normal(0, 0.02, (3, NUM_JOINTS, 3))
    W = rng.uniform(0.0, 1.0, (3, NUM_JOINTS))
    idx, dist = opt.search.knn_search_many(Q, W)
    for q, w, i, d in zip(Q, W, idx, dist):
        i1, d1 = opt.search.knn_search(q, w)
        assert list(i) == list(i1)
        np.testing.assert_allclose(d, d1, rtol=1e-12, atol=1e-12)


def test_solve_batch_of_one_is_solve(db):
    a, b = NaturalPostureOptimizer(db, seed=5), NaturalPostureOptimizer(db, seed=5)
    q = np.asarray(db.positions[10], float) + 0.01
    w = np.linspace(0.3, 1.0, NUM_JOINTS)
    ra = a.solve(q, w)
    rb = solve_batch([b], [q], [w], [[]], [False])[0]
    assert np.array_equal(ra.positions, rb.positions) and ra.steps == rb.steps


def test_energy_many_numba_and_numpy_agree_with_the_one_user_kernel(db):
    pytest.importorskip('numba')
    opt = NaturalPostureOptimizer(db, k=30)
    rng = np.random.default_rng(2)
    Ps, ZTs, consts = [], [], []
    for u in range(3):
        q = np.asarray(db.positions[100 * u], float) + 0.02
        w = rng.uniform(0.2, 1.0, NUM_JOINTS)
        idx, _ = opt.search.knn_search(q, w)
        S = opt._setup(opt._X.take(idx, axis=0), q, w, q + 0.01)
        ZT = np.vstack([rng.normal(0.0, 0.2, (S['d'], 40)), np.ones(40)])
        Ps.append(S['WT'] @ ZT)
        ZTs.append(ZT)
        consts.append(S['const'])
    P, ZT, const = np.stack(Ps), np.stack(ZTs), np.array(consts)
    d = ZT.shape[1] - 1
    args = (P, ZT, d, const, opt.L, opt.w_kinematics, opt.w_style)
    a, b = kernels._energy_many_numba(*args), kernels._energy_many_numpy(*args)
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    for u in range(3):
        one = kernels._energy_numba(P[u], ZT[u], d, const[u], opt.L, opt.w_kinematics,
                                    opt.w_style)
        assert np.array_equal(a[u], one)


def test_direction_spreads_of_several_users_equal_each_users():
    from pose_reconstruction.segment_output import (neighbour_direction_spread,
                                                    neighbour_direction_spreads)
    rng = np.random.default_rng(0)
    Y = rng.normal(size=(4, 30, NUM_JOINTS, 3))
    dist = rng.uniform(0.01, 1.0, (4, 30))
    many = neighbour_direction_spreads(Y, dist)
    for y, d, m in zip(Y, dist, many):
        np.testing.assert_allclose(m, neighbour_direction_spread(y, d), rtol=0, atol=1e-12)


def test_database_segment_units_give_the_neighbours_spreads_bit_for_bit(db):
    """The neighbours' unit segment directions taken from the database's table (computed once)
    are the numbers computed from the neighbours' postures: the same spreads to the bit, one
    user and several."""
    from pose_reconstruction.segment_output import (database_segment_units,
                                                    neighbour_direction_spread,
                                                    neighbour_direction_spreads)
    U = database_segment_units(db)
    assert U is database_segment_units(db)           # once per database
    assert U.flags['C_CONTIGUOUS'] and not U.flags['WRITEABLE']   # rows taken cheaply, shared
    rng = np.random.default_rng(1)
    idx = rng.integers(0, db.size, (3, 30))
    dist = rng.uniform(0.01, 1.0, (3, 30))
    Y = db.flat.take(idx, axis=0).reshape(3, 30, NUM_JOINTS, 3)
    many = neighbour_direction_spreads(Y, dist)
    assert np.array_equal(neighbour_direction_spreads(None, dist, U.take(idx, axis=0)), many)
    for r in range(3):
        one = neighbour_direction_spread(Y[r], dist[r])
        assert np.array_equal(neighbour_direction_spread(None, dist[r], U.take(idx[r], axis=0)),
                              one)


def test_stochastic_step_kernels_numba_and_numpy_agree():
    pytest.importorskip('numba')
    rng = np.random.default_rng(4)
    u, d, m = 5, 7, 40
    for trial in range(20):
        Z0 = rng.normal(size=(u, d + 1, m))
        SIG = rng.uniform(0.01, 2.0, (u, d, 1))
        ZC0 = rng.normal(size=(u, d, 1))
        E = rng.normal(size=(u, m))
        E[1, 3] = E[1, 9] = E[1].min() - 1.0      # a tie: the first minimum wins
        if trial % 2:
            E[2, 11] = np.nan                       # NaN: numpy's argmin takes the first NaN
            E[3, 0] = np.nan
        E0 = np.nanmin(E, axis=1) + 0.1
        E0[0] = -np.inf                             # a user whose samples do not improve
        runs = []
        for scale, select in ((kernels._scale_samples_many_numba, kernels._select_many_numba),
                              (kernels._scale_samples_many_numpy, kernels._select_many_numpy)):
            Z, ZC, e0 = Z0.copy(), ZC0.copy(), E0.copy()
            scale(Z, SIG, ZC, d)
            better = select(E, Z, d, ZC, e0)
            runs.append((Z, ZC, e0, np.asarray(better)))
        for a, b in zip(*runs):
            assert np.array_equal(a, b, equal_nan=True)
        assert runs[0][3].any() and not runs[0][3].all()
        assert np.array_equal(runs[0][0][:, d], Z0[:, d])   # the row of ones is left alone


def _energy_one_sample_at_a_time(P, ZT, d, const, L, w_k, w_s):
    # Eq. 15 sample by sample (the kernels' arithmetic before their loops ran over rows outside)
    n, m = L.shape[0], P.shape[1]
    K = P.shape[0] - d - 3 * n
    ck, cs = w_k / n, w_s / NUM_JOINTS
    e = np.empty(m)
    for j in range(m):
        acc = 0.0
        for i in range(d):
            acc += P[i, j] * ZT[i, j]
        ek = 0.0
        for s in range(n):
            x, y, z = P[d + s, j], P[d + n + s, j], P[d + 2 * n + s, j]
            r = np.sqrt(x * x + y * y + z * z) - L[s]
            ek += r * r
        best = P[d + 3 * n, j]
        for k in range(1, K):
            v = P[d + 3 * n + k, j]
            if v < best:
                best = v
        e[j] = acc + const + ek * ck + best * cs
    return e


def test_energy_kernels_compute_each_sample_in_the_same_order():
    """The compiled kernels loop over rows outside and samples inside (vectorised); every
    sample's sums and minimum keep their order: the numbers of one sample at a time, bit for
    bit (NaN included)."""
    numba = pytest.importorskip('numba')
    ref = numba.njit(_energy_one_sample_at_a_time)
    rng = np.random.default_rng(6)
    for t in range(40):
        u, d, k, m = 3, int(rng.integers(1, 25)), int(rng.integers(2, 40)), int(rng.integers(1, 130))
        P = rng.normal(size=(u, d + 57 + k, m)) * rng.uniform(0.01, 10.0)
        if t % 4 == 0:
            P[1, d + 57 + 1, 0] = np.nan
        ZT = rng.normal(size=(u, d + 1, m))
        const, L = rng.normal(size=u), rng.uniform(0.05, 0.5, 19)
        many = kernels._energy_many_numba(P, ZT, d, const, L, 0.7, 8.0)
        for r in range(u):
            want = ref(P[r], ZT[r], d, const[r], L, 0.7, 8.0)
            assert np.array_equal(many[r], want, equal_nan=True)
            assert np.array_equal(kernels._energy_numba(P[r], ZT[r], d, const[r], L, 0.7, 8.0),
                                  want, equal_nan=True)
