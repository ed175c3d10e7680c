"""Methods B/C: natural-posture-space optimizer (Shum et al. 2013, Sec. V-VI)."""
import numpy as np
import pytest

from pose_reconstruction.optimizer import NaturalPostureOptimizer
from pose_reconstruction.posture_space import parent_relative_error
from pose_reconstruction.reconstructor import Reconstructor
from pose_reconstruction.synthetic import random_database, scenario
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import (ELBOW_RIGHT, HAND_LEFT, NUM_JOINTS, TRACKED, WRIST_LEFT,
                                 WRIST_RIGHT, segment_lengths, standard_body)


@pytest.fixture(scope='module')
def case():
    return scenario(frames=90)


@pytest.fixture(scope='module')
def small_db():
    return random_database(800, seed=5)


def run(db, obs, ts, **kw):
    r = Reconstructor(db, **kw)
    out = []
    for t in range(len(obs)):
        f = SkeletonFrame(positions=obs[t], tracking_state=ts[t], stamp_ns=t)
        out.append(r.process(f).positions)
    return np.array(out), r


def test_weighted_knn_matches_eq9_brute_force(small_db):
    opt = NaturalPostureOptimizer(small_db, k=10)
    q = np.asarray(small_db.positions[42], float) + 0.01
    w = np.linspace(0.0, 1.0, NUM_JOINTS)
    idx, d = opt.search.knn_search(q, w)
    ref = np.einsum('njd,j->n', (np.asarray(small_db.positions, float) - q) ** 2, w)  # Eq. 9
    assert set(idx) == set(np.argsort(ref)[:10])
    assert np.allclose(d, np.sort(ref)[:10], atol=1e-9)
    # a zero-weight joint does not matter at all
    q2 = q.copy()
    q2[0] += 10.0
    assert list(opt.search.knn_search(q2, w)[0]) == list(idx)


def test_energy_terms_match_equations(small_db):
    opt = NaturalPostureOptimizer(small_db, k=12, pca_dims=5, w_style=0.5)
    q = np.asarray(small_db.positions[3], float)
    w = np.full(NUM_JOINTS, 0.5)
    idx, _ = opt.search.knn_search(q, w)
    Y = np.asarray(small_db.flat, float)[idx]
    prev = [q + 0.01, q - 0.02]
    S = opt._setup(Y, q, w, 2 * prev[0] - prev[1])
    z = np.random.default_rng(0).normal(size=(3, 5)) * 0.05
    terms = opt.energy_terms(z, S)
    x = (S['mu'] + z @ S['V']).reshape(3, NUM_JOINTS, 3)
    ec = np.einsum('sjd,j->s', (x - q) ** 2, w)
    es = np.min([np.sum((x - y.reshape(NUM_JOINTS, 3)) ** 2, axis=(1, 2)) for y in Y], axis=0) / 20
    ek = np.sum((segment_lengths(x) - standard_body().segment_lengths) ** 2, axis=1) / 19
    em = np.sum((x - 2 * prev[0] + prev[1]) ** 2, axis=(1, 2)) / 20
    for name, ref in (('control', ec), ('style', es), ('kinematics', ek), ('continuity', em)):
        assert np.allclose(terms[name], ref, atol=1e-10), name
    e = opt.energy(z, S)
    assert np.allclose(e, 1.0 * ec + 0.5 * es + 1.5 * ek + 0.25 * em)


def test_keeps_reliable_joint_and_replaces_unreliable_one(case):
    db, truth, _, _ = case
    obs = truth.copy()
    ts = np.full((len(obs), NUM_JOINTS), TRACKED, np.uint8)
    bad = [WRIST_LEFT, HAND_LEFT]
    obs[:, bad] += (0.0, 0.0, 0.5)  # forearm end reported 50 cm too high ...
    ts[:, bad] = 1                   # ... and only inferred
    out, r = run(db, obs, ts, method='C')
    err = np.linalg.norm(out - truth, axis=2)[10:]
    assert np.median(err[:, WRIST_LEFT]) < 0.15       # replaced (raw error 0.5 m)
    assert np.median(err[:, ELBOW_RIGHT]) < 0.06      # reliable joints stay where observed
    # method B trusts the wrong wrist and is pulled towards it
    out_b, _ = run(db, obs, ts, method='B')
    err_b = np.linalg.norm(out_b - truth, axis=2)[10:]
    assert np.median(err[:, WRIST_LEFT]) < np.median(err_b[:, WRIST_LEFT])


@pytest.mark.parametrize('solver', ['stochastic', 'gauss_newton'])
def test_method_c_beats_raw_on_corrupted_clip(case, solver):
    db, truth, obs, ts = case
    raw = parent_relative_error(obs, truth)
    out, r = run(db, obs, ts, method='C', solver=solver)
    rec = parent_relative_error(out, truth)
    assert rec < 0.8 * raw, (rec, raw)
    # the vibrating right wrist (still reported TRACKED) is caught by the behaviour term
    assert r.reliability.reliability[WRIST_RIGHT] < 0.3
    assert np.all(np.isfinite(out))


def test_stochastic_search_is_seeded_and_stops_early(case):
    db, truth, obs, ts = case
    a, ra = run(db, obs[:20], ts[:20], method='C', seed=3)
    b, _ = run(db, obs[:20], ts[:20], method='C', seed=3)
    assert np.array_equal(a, b)
    assert ra.last_result.steps < 20  # no sample improved before the step limit


def test_orientations_and_output_scale(case):
    db, truth, obs, ts = case
    r = Reconstructor(db, method='C', output_scale='user')
    f = SkeletonFrame(positions=truth[0], tracking_state=ts[0] * 0 + TRACKED, user_id=3,
                      stamp_ns=5, frame_id='k')
    out = r.process(f)
    q = out.orientations
    assert q.shape == (NUM_JOINTS, 4) and np.allclose(np.linalg.norm(q, axis=1), 1.0)
    # the user (1.65 m) keeps a body of their own size, not the database's 1.75 m
    user = segment_lengths(out.positions).sum()
    assert user == pytest.approx(standard_body(1.65).segment_lengths.sum(), rel=0.03)


def test_trust_sensor_when_database_is_far(small_db):
    # a posture unlike any database posture (arms stretched up and back, 2.2 m wide)
    p = standard_body().rest_positions()
    p[[5, 6, 7], 1] += 0.6
    p[[9, 10, 11], 1] -= 0.6
    ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
    old = dict(output_mode='blend', trust_mode='distance')  # the earlier rule
    r = Reconstructor(small_db, method='C', trust_sensor_distance=0.05, **old)
    out = r.process(SkeletonFrame(positions=p, tracking_state=ts))
    assert np.allclose(out.positions, p)
    r2 = Reconstructor(small_db, method='C', trust_sensor_distance=100.0, **old)
    out2 = r2.process(SkeletonFrame(positions=p, tracking_state=ts))
    assert not np.allclose(out2.positions, p)


def _noisy_frames(p, frames, noise_m, seed=0):
    rng = np.random.default_rng(seed)
    return [p + rng.normal(0.0, noise_m, p.shape) for _ in range(frames)]


def test_noise_ratio_trusts_a_precise_sensor_far_from_the_database(small_db):
    # the same odd posture: observed with 2 mm noise, the database distance is ~100x the noise
    # -> the output follows the sensor's directions (segments mode: the user's rigid lengths)
    p = standard_body().rest_positions()
    p[[5, 6, 7], 1] += 0.6
    p[[9, 10, 11], 1] -= 0.6
    ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
    r = Reconstructor(small_db, method='C')
    outs = [r.process(SkeletonFrame(positions=f, tracking_state=ts, stamp_ns=i * 33_333_333))
            for i, f in enumerate(_noisy_frames(p, 40, 0.002))]
    assert r.trust_sensor == 1.0 and r.noise < 0.01
    err = np.linalg.norm(outs[-1].positions - p, axis=1)
    assert np.median(err) < 0.03
    L = np.array([segment_lengths(o.positions) for o in outs[20:]])
    # once frozen (length_frames trusted frames) the lengths are constant, although trusted
    assert r.segment_output.user_lengths is not None
    np.testing.assert_allclose(L, np.tile(r.segment_output.user_lengths, (len(L), 1)), atol=1e-12)
    # the database posture itself, observed with 3 cm noise: the distance is a few times the
    # noise -> the database is trusted (trust 0)
    q = np.asarray(small_db.positions[100], float)
    r2 = Reconstructor(small_db, method='C')
    for i, f in enumerate(_noisy_frames(q, 30, 0.03, seed=1)):
        r2.process(SkeletonFrame(positions=f, tracking_state=ts, stamp_ns=i * 33_333_333))
    assert r2.trust_sensor == 0.0


def test_segments_output_smoothing_and_lengths_parameters(small_db):
    p = standard_body(1.7).rest_positions()
    ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
    frames = _noisy_frames(p, 40, 0.01, seed=2)

    def jitter(**kw):
        r = Reconstructor(small_db, method='C', **kw)
        out = np.array([r.process(SkeletonFrame(positions=f, tracking_state=ts,
                                                stamp_ns=i * 33_333_333)).positions
                        for i, f in enumerate(frames)])
        return np.mean(np.linalg.norm(out[2:] - 2 * out[1:-1] + out[:-2], axis=2)), out
    j_on, out = jitter()
    j_off, _ = jitter(smooth_min_cutoff=0.0)
    assert j_on < 0.6 * j_off
    # symmetric lengths: left and right forearms equal
    from skeleton_core.model import ELBOW_LEFT
    L = segment_lengths(out[-1])
    seg = {c: k for k, c in enumerate(__import__('skeleton_core.model', fromlist=['x']).SEGMENT_CHILDREN)}
    assert L[seg[WRIST_LEFT]] == pytest.approx(L[seg[WRIST_RIGHT]])
    assert L[seg[ELBOW_LEFT]] == pytest.approx(L[seg[ELBOW_RIGHT]])
    for bad in (dict(output_mode='x'), dict(trust_mode='x'), dict(observation_weight=2.0),
                dict(length_frames=0), dict(smooth_d_cutoff=0.0)):
        with pytest.raises(ValueError):
            Reconstructor(small_db, method='C', **bad)


def test_invalid_parameters_refused(small_db):
    with pytest.raises(ValueError):
        Reconstructor(small_db, method='D')
    with pytest.raises(ValueError):
        Reconstructor(small_db, method='C', solver='newton')
    with pytest.raises(ValueError):
        Reconstructor(small_db, method='C', bogus=1)
    with pytest.raises(ValueError):
        NaturalPostureOptimizer(small_db, k=1)


def test_output_takes_the_users_observed_segment_lengths(small_db):
    # a user whose trunk is 30 % shorter than the standard proportions: after a few reliable
    # frames the output keeps the observed lengths, not the database's
    p = standard_body(1.7).rest_positions()
    from skeleton_core.model import SHOULDER_CENTER, SPINE, subtree
    above = subtree(SHOULDER_CENTER)
    p[above] -= (0.0, 0.0, 0.3 * (p[SHOULDER_CENTER, 2] - p[SPINE, 2]))
    ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
    r = Reconstructor(small_db, method='C', trust_sensor_distance=100.0,  # no sensor fallback
                      output_mode='blend', trust_mode='distance')
    for _ in range(12):
        out = r.process(SkeletonFrame(positions=p, tracking_state=ts))
    assert np.allclose(segment_lengths(out.positions), segment_lengths(p), atol=1e-6)


def test_fast_paths_equal_the_reference_functions():
    # query preparation, the quaternion yaw and the fused One Euro filter of the output stage
    # are rewritten as a few matrix products: same numbers as the straightforward functions
    from pose_reconstruction.posture_space import (STRICT_ANCESTORS, QueryPreparer,
                                                   fast_normalize, fast_retarget,
                                                   orientations_to_sensor)
    from skeleton_core.geometry import quat_from_yaw, quat_multiply
    from skeleton_core.filters import OneEuroFilter
    body = standard_body()
    prep = QueryPreparer(body, 0.5)
    rng = np.random.default_rng(7)
    for i in range(20):
        p = standard_body(1.6).rest_positions() + rng.normal(0, 0.05, (NUM_JOINTS, 3)) + [2, 1, 0]
        w = rng.uniform(0, 1, NUM_JOINTS)
        got = prep.prepare(p, w, 1.6)
        norm, tf = fast_normalize(p, np.maximum(w, 1e-3))
        ref = fast_retarget(norm, prep.lengths, prep.rest_dirs)
        bad = w < 0.5
        chain = (STRICT_ANCESTORS & bad[None, :]).any(axis=1)
        ref[chain] = norm[chain] * body.height / 1.6
        assert np.allclose(got.query, ref, atol=1e-12)
        assert float(got.transform.yaw) == pytest.approx(float(tf.yaw), abs=1e-12)
        q = rng.normal(size=(NUM_JOINTS, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        yaw = rng.uniform(-np.pi, np.pi)
        ref = quat_multiply(quat_from_yaw(np.asarray(yaw))[None, :], q)
        assert np.allclose(orientations_to_sensor(q, yaw), ref, atol=1e-12)
    a, b = OneEuroFilter(2.0, 10.0, 1.0, num_joints=20), OneEuroFilter(2.0, 10.0, 1.0, num_joints=20)
    ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
    for t in range(30):
        x = rng.normal(0, 0.1, (NUM_JOINTS, 3))
        stamp = t * 33_333_333
        assert np.allclose(a.update(x, None, stamp), b.update(x, ts, stamp), atol=1e-12)


def test_filled_segments_are_smoothed_more(small_db):
    # the right forearm and hand not tracked: those segments come from the database solution and
    # get smooth_filled_scale times the cutoff; the tracked segments are filtered as before
    from skeleton_core.model import HAND_RIGHT, NOT_TRACKED, SEGMENT_CHILDREN
    p = standard_body(1.7).rest_positions()
    frames = _noisy_frames(p, 60, 0.02, seed=3)
    ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
    ts[[WRIST_RIGHT, HAND_RIGHT]] = NOT_TRACKED

    def run_scale(scale, states, frames=frames):
        r = Reconstructor(small_db, method='C', smooth_filled_scale=scale)
        return np.array([r.process(SkeletonFrame(positions=f, tracking_state=states,
                                                 stamp_ns=i * 33_333_333)).positions
                         for i, f in enumerate(frames)])

    def seg_jitter(out, joint):
        k = list(SEGMENT_CHILDREN).index(joint)
        from skeleton_core.model import SEGMENT_PARENTS
        v = out[:, joint] - out[:, SEGMENT_PARENTS[k]]
        return np.mean(np.linalg.norm(v[2:] - 2 * v[1:-1] + v[:-2], axis=1))
    full, soft = run_scale(1.0, ts), run_scale(0.2, ts)
    assert seg_jitter(soft[20:], HAND_RIGHT) < 0.7 * seg_jitter(full[20:], HAND_RIGHT)
    # everything tracked and steady (every reliability 1): scale 1 everywhere, the same output
    all_ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
    quiet = _noisy_frames(p, 30, 0.002, seed=4)
    assert np.allclose(run_scale(1.0, all_ts, quiet), run_scale(0.2, all_ts, quiet), atol=1e-12)
    with pytest.raises(ValueError):
        Reconstructor(small_db, method='C', smooth_filled_scale=0.0)


def test_translation_invariant_knn_and_floating_root(small_db):
    opt = NaturalPostureOptimizer(small_db, k=8)
    rng = np.random.default_rng(9)
    q = np.asarray(small_db.positions[40], float) + rng.normal(0, 0.01, (NUM_JOINTS, 3))
    w = rng.uniform(0.2, 1.0, NUM_JOINTS)
    t = np.array([0.08, -0.05, 0.12])
    idx, d, shifts = opt.search.knn_search(q + t, w, translate=True)
    # the distance is Eq. 9 at the best translation, found exactly by brute force
    X = np.asarray(small_db.positions, float)
    best_t = np.einsum('njd,j->nd', X - (q + t), w) / w.sum()
    full = np.einsum('njd,j->n', (X - (q + t) - best_t[:, None]) ** 2, w)
    assert np.allclose(d, np.sort(full)[:8], atol=1e-9)
    assert np.allclose(shifts, best_t[idx], atol=1e-12)
    assert idx[0] == 40 and np.allclose(shifts[0], -t, atol=0.02)
    # a reconstructor whose root is not tracked and reported 15 cm off: with the database
    # trusted (trust 0) the root is put back
    from skeleton_core.model import NOT_TRACKED, ROOT
    p = np.asarray(small_db.positions[40], float) + [2.5, 0.0, 0.0]
    ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
    ts[ROOT] = NOT_TRACKED
    bad = p.copy()
    bad[ROOT] += (0.0, 0.0, 0.15)
    errs = {}
    for flag in (True, False):
        r = Reconstructor(small_db, method='C', float_root=flag, output_scale='standard',
                          trust_mode='distance', trust_sensor_distance=100.0)
        for i in range(20):
            out = r.process(SkeletonFrame(positions=bad, tracking_state=ts, stamp_ns=i * 33_333_333))
        errs[flag] = (np.linalg.norm(out.positions[ROOT] - p[ROOT]),
                      parent_relative_error(out.positions[None], p[None]))
    assert errs[True][0] < 0.03 < 0.1 < errs[False][0]
    assert errs[True][1] < errs[False][1]
    # a trusted sensor (trust 1) keeps its own root when the skeleton is chained from it (a
    # hand 2 cm off the database posture: with the hips and spine reliable next to the untracked
    # root -- reliability Eq. 6 does not blame them for it -- the match is otherwise exact, and
    # a distance of 0 is never trusted)
    bad[HAND_LEFT] += (0.0, 0.02, 0.0)
    r = Reconstructor(small_db, method='C', output_scale='standard', trust_mode='distance',
                      trust_sensor_distance=1e-6, position_fit=0.0)
    for i in range(20):
        out = r.process(SkeletonFrame(positions=bad, tracking_state=ts, stamp_ns=i * 33_333_333))
    assert r.trust_sensor == 1.0 and np.allclose(out.positions[ROOT], bad[ROOT], atol=1e-9)
    # with position_fit (default) the trusted *tracked* joints place the skeleton: the untracked
    # root, reported 15 cm off, no longer drags it
    r = Reconstructor(small_db, method='C', output_scale='standard', trust_mode='distance',
                      trust_sensor_distance=1e-6)
    for i in range(20):
        fit = r.process(SkeletonFrame(positions=bad, tracking_state=ts, stamp_ns=i * 33_333_333))
    assert r.trust_sensor == 1.0
    tracked = ts == TRACKED
    err = lambda q: np.linalg.norm(q[tracked] - p[tracked], axis=1).mean()  # noqa: E731
    assert err(fit.positions) < err(out.positions)
    assert np.linalg.norm(fit.positions[ROOT] - p[ROOT]) < 0.1


def test_scale_invariant_knn_matches_brute_force(small_db):
    opt = NaturalPostureOptimizer(small_db, k=8)
    X = np.asarray(small_db.positions, float)
    rng = np.random.default_rng(3)
    w = rng.uniform(0.0, 1.0, NUM_JOINTS)
    q = X[40] * 0.85 + [0.3, -0.2, 0.1]          # a smaller body, elsewhere
    for translate in (False, True):
        idx, d, s = opt.search.knn_scaled(q, w, translate=translate, scale_range=(0.5, 2.0))
        # brute force: centre (with translate), best scale, shape distance 1 - cos^2
        qc, Xc = q, X
        if translate:
            qc = q - (w @ q) / w.sum()
            Xc = X - np.einsum('j,njd->nd', w, X)[:, None] / w.sum()
        sxq = np.einsum('njd,jd,j->n', Xc, qc, w)
        sxx = np.einsum('njd,njd,j->n', Xc, Xc, w)
        sqq = np.einsum('jd,jd,j->', qc, qc, w)
        ref = 1.0 - np.maximum(sxq, 0) ** 2 / (sxx * sqq)
        assert np.allclose(d, np.sort(ref)[:8], atol=1e-9)
        assert np.allclose(s, np.clip(sxq / sqq, 0.5, 2.0)[idx], atol=1e-9)
    # translated and scaled: the original posture at the inverse scale, a perfect fit
    assert idx[0] == 40 and d[0] < 1e-9 and abs(s[0] - 1 / 0.85) < 1e-6
    # the scale range is respected
    _, _, s = opt.search.knn_scaled(q, w, translate=True, scale_range=(0.9, 1.1))
    assert s.max() <= 1.1 and s.min() >= 0.9


def _ends_only(p, frozen, ends):
    """A frame of a static posture ``p`` where only ``ends`` are tracked (reliability 1, as
    table3.subset_frames); the other joints NOT_TRACKED (0) at the positions of ``frozen``."""
    from skeleton_core.model import NOT_TRACKED
    ts = np.full(NUM_JOINTS, NOT_TRACKED, np.uint8)
    ts[list(ends)] = TRACKED
    obs = np.array(frozen, float)
    obs[list(ends)] = p[list(ends)]
    return obs, ts


def _frame(obs, ts, i):
    return SkeletonFrame(positions=obs, tracking_state=ts, stamp_ns=i * 33_333_333,
                         reliability=(ts == TRACKED).astype(np.float32))


_FEW = ('HandLeft', 'HandRight', 'FootLeft', 'FootRight', 'ElbowLeft', 'ElbowRight',
        'KneeLeft', 'KneeRight')   # Table III (d): no segment has two tracked ends


def _yaw_err(out, a):
    from skeleton_core.geometry import facing_yaw
    return abs(np.degrees(np.angle(np.exp(1j * (facing_yaw(out) - a)))))


def _turned(X, deg, height):
    a = np.radians(deg)
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    return a, (X @ rot.T) * (height / 1.75) + [2.5, 0.3, 0.0]


def test_height_and_heading_from_the_database_when_no_segment_is_observed(small_db):
    # a 1.50 m user (the standard body is 1.75 m) turned by 25 degrees, with only hands, feet,
    # elbows and knees tracked and the other joints reported at the origin: no length, no
    # height and no heading can be measured. The heading search and the scale-invariant
    # database fit find both; the height then sets the standard-body lengths of the output
    from skeleton_core.model import JOINT_INDEX, SEGMENT_CHILDREN, SEGMENT_PARENTS
    ends = [JOINT_INDEX[n] for n in _FEW]
    X = np.asarray(small_db.positions, float)
    a, p = _turned(X[40], 25.0, 1.50)
    obs, ts = _ends_only(p, np.zeros((NUM_JOINTS, 3)), ends)

    def run_few(**kw):
        r = Reconstructor(small_db, method='C', **kw)
        for i in range(40):
            out = r.process(_frame(obs, ts, i)).positions
        return r, out
    r, out = run_few()
    assert abs(r.reliability.height - 1.50) < 0.02 and _yaw_err(out, a) < 2.0
    assert len(r.body_fit.height_fits) == 30 and r.body_fit.height_done        # then kept
    L = np.linalg.norm(out[list(SEGMENT_CHILDREN)] - out[list(SEGMENT_PARENTS)], axis=1)
    assert np.allclose(L, standard_body(r.reliability.height).segment_lengths, atol=1e-6)
    r0, out0 = run_few(height_frames=0, yaw_search=0, yaw_rate=0.0)   # off: standard, no heading
    assert r0.reliability.height == 1.75 and not r0.body_fit.height_fits and _yaw_err(out0, a) > 20.0
    assert parent_relative_error(out[None], p[None]) < 0.5 * parent_relative_error(out0[None],
                                                                                   p[None])
    # once a frame has every joint tracked, the sensor's height is used, not the prior
    tall = _turned(X[40], 25.0, 1.80)[1]
    r.process(SkeletonFrame(positions=tall,
                            tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                            stamp_ns=10 ** 10))
    assert r.reliability.height_measured and abs(r.reliability.height - 1.80) < 0.02


def test_heading_follows_the_database_while_the_torso_is_unreliable(small_db):
    # the torso NOT_TRACKED and reported where it was before the user turned by 25 degrees:
    # its hip and shoulder lines give a wrong heading, which yaw_rate 0 keeps; the neighbour
    # fit turns it towards the tracked joints' (a local fit: part of the way here, where the
    # random database offers other postures that fit the 8 joints at the kept heading)
    from skeleton_core.model import JOINT_INDEX
    ends = [JOINT_INDEX[n] for n in _FEW]
    X = np.asarray(small_db.positions, float)
    a, p = _turned(X[40], 25.0, 1.50)
    obs, ts = _ends_only(p, _turned(X[40], 0.0, 1.50)[1], ends)
    errs = {}
    for rate in (0.5, 0.0):
        r = Reconstructor(small_db, method='C', yaw_rate=rate, yaw_search=0)
        for i in range(40):
            out = r.process(_frame(obs, ts, i)).positions
        errs[rate] = _yaw_err(out, a)
    assert errs[0.0] > 20.0 and errs[0.5] < errs[0.0] - 5.0
    with pytest.raises(ValueError):
        Reconstructor(small_db, method='C', yaw_rate=1.5)


def test_database_heading_fit_recovers_a_rotation_without_preferring_the_current_one(small_db):
    # hands and feet of a database posture turned by 30 degrees about the vertical (and, with
    # the root unreliable, moved): the rotation-invariant fit over the whole database finds the
    # posture and the rotation exactly, from any starting heading of the query; the joints not
    # tracked (placed far off) do not count
    from skeleton_core.model import JOINT_INDEX
    r = Reconstructor(small_db, method='C', yaw_neighbours=1)
    X = np.asarray(small_db.positions, float)
    ends = [JOINT_INDEX[n] for n in ('HandLeft', 'HandRight', 'FootLeft', 'FootRight')]
    w = np.zeros(NUM_JOINTS)
    w[ends] = 1.0
    for deg in (30.0, -75.0, 170.0):
        a, q = _turned(X[123], deg, 1.75)
        q[w == 0] = 50.0
        q[0] = np.nan
        theta = r.body_fit.database_yaw(q, w, centre=True)
        assert abs(np.degrees(np.angle(np.exp(1j * (theta + a))))) < 1e-6   # q is off by +a
        q0 = q - [2.5, 0.3, 0.0]                                      # root at the origin
        assert abs(np.degrees(np.angle(np.exp(1j * (r.body_fit.database_yaw(q0, w, centre=False) + a))))) < 1e-6
    # a smaller user (height not known yet): the scale-invariant fit still finds the rotation
    a, q = _turned(X[123], 30.0, 1.50)
    assert abs(np.degrees(np.angle(np.exp(1j * (r.body_fit.database_yaw(q, w, True, scaled=True) + a))))) < 1e-6
    # the uncentred fit is not translation invariant: a moved query matches worse
    a, q = _turned(X[123], 30.0, 1.75)
    theta = r.body_fit.database_yaw(q, w, centre=False)
    assert abs(np.degrees(np.angle(np.exp(1j * (theta + a))))) > 1e-3
    w1 = np.zeros(NUM_JOINTS)
    w1[ends[0]] = 1.0
    assert r.body_fit.database_yaw(q, w1, centre=True) is None                 # one joint: no rotation
    with pytest.raises(ValueError):
        Reconstructor(small_db, method='C', yaw_neighbours=0)


def test_users_on_one_database_share_its_arrays_with_the_same_results(case):
    """The KNN / PCA arrays derived from a database are computed once and shared by every user's
    optimizer (and completion): a second user on the same database gets what a user on a fresh
    copy of the database gets."""
    from pose_reconstruction.posture_space import as_database_arrays
    db, _, obs, ts = case
    arr = as_database_arrays(db)
    a = Reconstructor(arr, method='C')
    b = Reconstructor(arr, method='C')
    assert a.core.search._XA is b.core.search._XA and not a.core.search._XA.flags.writeable
    assert (Reconstructor(arr, method='A').core.components
            is Reconstructor(arr, method='A').core.components)
    fresh, _ = run(as_database_arrays(db.positions.copy()), obs[:20], ts[:20])
    shared, _ = run(arr, obs[:20], ts[:20])
    np.testing.assert_array_equal(shared, fresh)


def test_query_heading_matches_facing_yaw():
    from pose_reconstruction.posture_space import heading_yaw
    from skeleton_core.geometry import facing_yaw
    rng = np.random.default_rng(4)
    for _ in range(2000):
        p = rng.normal(size=(NUM_JOINTS, 3))
        w = rng.choice([0.0, 1e-4, 0.3, 1.0], NUM_JOINTS)
        assert heading_yaw(p, w.tolist()) == facing_yaw(p, np.maximum(w, 1e-3))


def test_anchored_filled_segments_keep_the_speed_term():
    # Table III style: only the hands and feet tracked, the rest NOT_TRACKED and frozen. Every
    # segment is then filled by the database; filtering them all with smooth_filled_scale times
    # the whole One Euro cutoff made the body trail the tracked hands and feet. With
    # smooth_anchored_speed (default) a segment with a tracked joint below it keeps the speed
    # term: the output follows the unsmoothed reconstruction more closely when the arms move.
    from skeleton_eval.clips import toy_clip
    from skeleton_core.geometry import normalize
    from skeleton_core.model import (FOOT_LEFT, FOOT_RIGHT, HAND_RIGHT, NOT_TRACKED,
                                     SEGMENT_CHILDREN, SEGMENT_PARENTS)
    clip = toy_clip(4.0)
    pos = np.asarray(clip.positions, float)
    db = normalize(pos)[0]
    keep = [HAND_LEFT, HAND_RIGHT, FOOT_LEFT, FOOT_RIGHT]
    hidden = np.setdiff1d(np.arange(NUM_JOINTS), keep)
    rng = np.random.default_rng(2)
    frames = []
    for t in range(len(pos)):
        p = pos[t] + rng.normal(0, 0.003, (NUM_JOINTS, 3))
        p[hidden] = pos[0][hidden]
        ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
        ts[hidden] = NOT_TRACKED
        frames.append(SkeletonFrame(positions=p, tracking_state=ts, stamp_ns=t * 33_333_333))

    def segs(**kw):
        r = Reconstructor(db, method='C', samples=20, **kw)
        out = np.array([r.process(f.copy()).positions for f in frames])
        return out[:, list(SEGMENT_CHILDREN)] - out[:, list(SEGMENT_PARENTS)]

    raw = segs(smooth_min_cutoff=0.0)  # no output filter at all: nothing to lag behind
    new, old = segs(), segs(smooth_anchored_speed=False)
    lag_new = np.linalg.norm(new - raw, axis=-1)[10:].mean()
    lag_old = np.linalg.norm(old - raw, axis=-1)[10:].mean()
    assert lag_new < 0.9 * lag_old    # 0.88 at the defaults (beta 3; 0.82 at beta 5)
    # outside the few-reliable-joints regime the filled segments are smoothed as before: a
    # reliable torso with one forearm hidden, or the torso hidden with one forearm tracked
    ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
    ts[[WRIST_RIGHT, HAND_RIGHT]] = NOT_TRACKED
    ts2 = np.full(NUM_JOINTS, NOT_TRACKED, np.uint8)
    ts2[keep + [ELBOW_RIGHT, WRIST_RIGHT]] = TRACKED
    for states in (ts, ts2):
        occl = [SkeletonFrame(positions=pos[t] + rng.normal(0, 0.01, (NUM_JOINTS, 3)),
                              tracking_state=states, stamp_ns=t * 33_333_333) for t in range(60)]
        a = Reconstructor(db, method='C', samples=20)
        b = Reconstructor(db, method='C', samples=20, smooth_anchored_speed=False)
        for f in occl:
            assert np.array_equal(a.process(f.copy()).positions, b.process(f.copy()).positions)
    with pytest.raises(ValueError):
        Reconstructor(db, method='C', smooth_anchored_speed='yes')


def test_large_database_screened_knn_equals_the_exact_search():
    """From SCREEN_FROM postures on, Eq. 9 is screened in single precision and the best
    candidates re-ranked in double: the same neighbours and distances as the exact double
    search, with and without the translation-invariant variant."""
    from pose_reconstruction.search import SCREEN_FROM, DatabaseSearch
    db = random_database(SCREEN_FROM + 500, seed=11)
    opt = DatabaseSearch(db, k=30, knn='brute', kdtree_dims=12, kdtree_candidates=4)
    assert opt._screen is not None
    exact = DatabaseSearch(db, k=30, knn='brute', kdtree_dims=12, kdtree_candidates=4)
    exact._screen = None
    rng = np.random.default_rng(2)
    for i in range(20):
        q = np.asarray(db.positions[rng.integers(len(db.positions))], float)
        q = q + rng.normal(0.0, 0.03, q.shape) + (0.4 if i % 2 else 0.0)
        w = rng.uniform(0.0, 1.0, NUM_JOINTS)
        for translate in (False, True):
            a, b = opt.knn_search(q, w, translate), exact.knn_search(q, w, translate)
            assert list(a[0]) == list(b[0])
            for x, y in zip(a[1:], b[1:]):
                np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-9)


def test_energy_kernel_numba_and_numpy_agree(small_db):
    """Eq. 15 of a batch of samples from the energy matrix product: the numba kernel gives the
    numpy formulation's energies (and both the sum of energy_terms)."""
    pytest.importorskip('numba')
    from pose_reconstruction import kernels
    opt = NaturalPostureOptimizer(small_db, k=30)
    q = np.asarray(small_db.positions[7], float) + 0.02
    w = np.linspace(0.2, 1.0, NUM_JOINTS)
    idx, _ = opt.search.knn_search(q, w)
    S = opt._setup(opt._X.take(idx, axis=0), q, w, q + 0.01)
    rng = np.random.default_rng(1)
    Z = rng.normal(0.0, 0.2, (64, S['d']))
    ZT = np.vstack([Z.T, np.ones(64)])
    P = S['WT'] @ ZT
    args = (P, ZT, S['d'], S['const'], opt.L, opt.w_kinematics, opt.w_style)
    a, b = kernels._energy_numba(*args), kernels._energy_numpy(*args)
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    terms = opt.energy_terms(Z, S)
    ref = (opt.w_control * terms['control'] + opt.w_style * terms['style']
           + opt.w_kinematics * terms['kinematics'] + opt.w_continuity * terms['continuity'])
    np.testing.assert_allclose(a, ref, rtol=1e-9, atol=1e-9)
