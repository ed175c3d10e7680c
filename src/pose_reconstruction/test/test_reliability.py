"""Reliability measure (Shum et al. 2013, Eq. 1-8) on hand-computed cases."""
import numpy as np
import pytest

from pose_reconstruction.reliability import (INCIDENCE, ReliabilityEstimator, behaviour_term,
                                             gaussian_weights, kinematics_term,
                                             reference_pose_match, tracking_term)
from skeleton_core.model import (ANKLE_LEFT, ANKLE_RIGHT, ELBOW_LEFT, ELBOW_RIGHT, FOOT_LEFT,
                                 FOOT_RIGHT, HAND_LEFT, HAND_RIGHT, HIP_CENTER, HIP_LEFT,
                                 HIP_RIGHT, INFERRED, KNEE_LEFT, KNEE_RIGHT, NOT_TRACKED,
                                 NUM_JOINTS, SEGMENT_CHILDREN, SEGMENT_OF_JOINT, SEGMENT_PARENTS,
                                 SHOULDER_LEFT, SHOULDER_RIGHT, TRACKED, WRIST_LEFT, WRIST_RIGHT,
                                 segment_lengths, standard_body)

FLOOR, ROOF = np.radians(90.0), np.radians(135.0)


def rest():
    return standard_body().rest_positions()


def test_behaviour_vibrating_joint_goes_to_zero():
    # a joint jumping back and forth by 5 cm: every angle is 180 deg > roof -> R_b = 0
    base = rest()
    hist = np.repeat(base[None], 5, axis=0)
    hist[::2, HAND_RIGHT, 0] += 0.05
    rb, theta = behaviour_term(hist, 0.03, 3, FLOOR, ROOF)
    assert np.allclose(np.degrees(theta[:, HAND_RIGHT]), 180.0)
    assert rb[HAND_RIGHT] == pytest.approx(0.0)
    # steady joints: displacements below d_min -> angle 0 -> fully reliable
    assert np.all(rb[np.arange(NUM_JOINTS) != HAND_RIGHT] == 1.0)


def test_behaviour_hand_computed_partial_value():
    # three displacements of 10 cm: +x, +y (90 deg), -x... angles 90, 90 -> one 112.5-deg case:
    p = np.zeros((5, NUM_JOINTS, 3))
    moves = [(0.1, 0, 0), (0.1 * np.cos(np.radians(120)), 0.1 * np.sin(np.radians(120)), 0),
             (0.1, 0, 0), (0.1, 0, 0)]
    for t, m in enumerate(moves):
        p[t + 1, 0] = p[t, 0] + m
    rb, theta = behaviour_term(p, 0.03, 3, FLOOR, ROOF)
    # angles: 120, 120, 0 deg -> mean 80 deg < floor -> 1.0
    assert np.degrees(theta[:, 0]) == pytest.approx([120.0, 120.0, 0.0], abs=1e-6)
    assert rb[0] == pytest.approx(1.0)
    # f_b = 2 -> mean of the last two angles (120, 0)/2 = 60 -> 1.0; with floor 30, roof 90:
    rb2, _ = behaviour_term(p, 0.03, 2, np.radians(30), np.radians(90))
    assert rb2[0] == pytest.approx(1.0 - (60 - 30) / (90 - 30))
    # slow motion below d_min never counts (Eq. 3)
    rb3, theta3 = behaviour_term(p * 0.2, 0.03, 3, FLOOR, ROOF)
    assert np.all(theta3 == 0.0) and rb3[0] == 1.0


def test_kinematics_stretched_segment_lowers_both_end_joints():
    p = rest()
    ref = segment_lengths(p)
    q = p.copy()
    q[WRIST_LEFT:WRIST_LEFT + 2] += (0.0, 0.5 * ref[SEGMENT_OF_JOINT[WRIST_LEFT]], 0.0)  # +50 %
    rk = kinematics_term(q, ref)
    # the elbow touches 2 segments (upper arm, forearm): 1 - (0 + 0.5) / 2
    assert rk[ELBOW_LEFT] == pytest.approx(0.75)
    # the wrist touches forearm (+50 %) and hand (unchanged): 1 - 0.5 / 2
    assert rk[WRIST_LEFT] == pytest.approx(0.75)
    assert rk[SHOULDER_LEFT] == pytest.approx(1.0)
    # ratio capped at 1 (Eq. 5): a 3x segment gives d = 1
    q2 = p.copy()
    q2[WRIST_LEFT:WRIST_LEFT + 2] += (0.0, 2.0 * ref[SEGMENT_OF_JOINT[WRIST_LEFT]], 0.0)
    assert kinematics_term(q2, ref)[ELBOW_LEFT] == pytest.approx(0.5)
    # the hip centre touches three segments
    assert INCIDENCE[HIP_CENTER].sum() == 3


def test_tracking_state_term():
    ts = np.array([TRACKED, INFERRED, NOT_TRACKED] * 6 + [TRACKED, TRACKED], np.uint8)
    rt = tracking_term(ts)
    assert list(rt[:3]) == [1.0, 0.0, 0.0]
    assert list(tracking_term(ts, inferred=0.5)[:3]) == [1.0, 0.5, 0.0]


def test_gaussian_weighted_minimum():
    w = gaussian_weights(6, 2.0)
    assert w.sum() == pytest.approx(1.0) and np.all(np.diff(w) > 0)  # most recent largest
    p = rest()
    ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
    for plausibility in (False, True):
        # the paper's Eq. 8 (plausibility stage off); with it, a joint tracked again is not held
        # down by its INFERRED frame (ReliabilityEstimator._reacquired), losing it is the same
        est = ReliabilityEstimator(sigma_frames=2.0, plausibility=plausibility)
        states = []
        for f in range(6):
            t = ts.copy()
            if f == 3:
                t[ELBOW_LEFT] = INFERRED  # min(R_b, R_k, R_t) = 0 in that frame only
            r = est.update(p, t)
            states.append(r[ELBOW_LEFT])
        # Eq. 8 by hand: sum of the weights of the frames whose minimum is 1 (all but frame 3;
        # w is oldest first, so frame f has weight w[f])
        expected = 1.0 if plausibility else 1.0 - w[3]
        assert states[-1] == pytest.approx(expected)
        assert states[3] == pytest.approx(1.0 - gaussian_weights(4, 2.0)[3])
        assert r[SHOULDER_LEFT] == pytest.approx(1.0)
    # the minimum of the three terms is used: a stretched, tracked segment lowers reliability
    est2 = ReliabilityEstimator(reference_lengths=segment_lengths(p))
    q = p.copy()
    q[HAND_RIGHT] += (0.0, -0.2, 0.0)
    r2 = est2.update(q, ts)
    rb, rk, rt = est2.last_terms
    assert r2[HAND_RIGHT] == pytest.approx(min(rb[HAND_RIGHT], rk[HAND_RIGHT], rt[HAND_RIGHT]))
    assert r2[HAND_RIGHT] < 0.5


def test_reference_lengths_captured_from_tpose_and_scaled_default():
    # the paper's default lengths and Eq. 1-8 alone (no plausibility term)
    est = ReliabilityEstimator(reference_mode='standard', plausibility=False)
    short = standard_body(1.5)
    # before any reference pose: the standard body scaled to the estimated height
    p = short.rest_positions()
    lowered = p.copy()
    # arms slightly raised forward: not a reference pose
    for j, k in ((ELBOW_LEFT, 1), (WRIST_LEFT, 2)):
        lowered[j] = p[SHOULDER_LEFT] + (0.15 * k, 0.0, 0.1 * k)
    ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
    assert reference_pose_match(lowered, 25.0) is None
    est.update(lowered, ts)
    assert est.reference_source == 'standard'
    assert est.height == pytest.approx(1.5, abs=0.02)
    assert np.allclose(est.reference_lengths, standard_body(est.height).segment_lengths)
    # a T-pose with every joint tracked: reference lengths become the user's own
    assert reference_pose_match(p, 25.0) == 'tpose'
    est.update(p, ts)
    assert est.reference_source == 'tpose'
    assert np.allclose(est.reference_lengths, short.segment_lengths)
    # not captured when a joint is inferred
    est3 = ReliabilityEstimator()
    t2 = ts.copy()
    t2[HAND_RIGHT] = INFERRED
    est3.update(p, t2)
    assert est3.reference_source == 'standard'


def test_observed_reference_lengths_follow_a_different_skeleton_layout():
    # a sensor whose spine segment is 14 cm longer than the standard body's (real Kinect vs the
    # CMU-derived body): with the standard reference the hip centre's R_k stays low, with the
    # observed reference (default) it is 1, and a sudden 50 % stretch still lowers R_k
    from skeleton_core.model import HIP_CENTER, SHOULDER_CENTER, SPINE, subtree
    p = standard_body(1.7).rest_positions()
    p[HIP_CENTER, 2] -= 0.14
    for leg in (12, 16):  # the hips hang from the hip centre
        p[subtree(leg)] -= (0.0, 0.0, 0.14)
    lowered = p.copy()
    lowered[ELBOW_LEFT] = p[SHOULDER_LEFT] + (0.15, 0.0, 0.1)
    lowered[WRIST_LEFT] = p[SHOULDER_LEFT] + (0.3, 0.0, 0.2)
    ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
    std = ReliabilityEstimator(reference_mode='standard')
    obs = ReliabilityEstimator()
    for _ in range(12):
        rs = std.update(lowered, ts)
        ro = obs.update(lowered, ts)
    assert std.last_terms[1][HIP_CENTER] < 0.75
    assert obs.last_terms[1][HIP_CENTER] == pytest.approx(1.0)
    assert rs[HIP_CENTER] < ro[HIP_CENTER]
    assert obs.reference_source == 'standard'  # no reference posture captured
    assert np.allclose(obs.reference_lengths, segment_lengths(lowered))
    q = lowered.copy()
    q[subtree(SHOULDER_CENTER)] += (0.0, 0.0, 0.5 * (p[SHOULDER_CENTER, 2] - p[SPINE, 2]))
    obs.update(q, ts)
    assert obs.last_terms[1][SHOULDER_CENTER] < 0.9
    with pytest.raises(ValueError):
        ReliabilityEstimator(reference_mode='bogus')


def test_invalid_parameters_refused():
    with pytest.raises(ValueError):
        ReliabilityEstimator(theta_floor_deg=140.0, theta_roof_deg=135.0)
    with pytest.raises(ValueError):
        ReliabilityEstimator(f_total=0)


def test_streamed_update_equals_the_equations_on_a_random_stream():
    # the estimator keeps one new angle per frame and precomputed segment lengths; it must give
    # exactly Eq. 1-8 as the reference functions compute them on the whole history
    rng = np.random.default_rng(3)
    T = 40
    base = rest() + np.array([2.5, 0.0, -0.8])
    pos = base + np.cumsum(rng.normal(0, 0.02, (T, NUM_JOINTS, 3)), axis=0)
    pos[::3, WRIST_LEFT] += 0.06  # vibration
    states = rng.choice([TRACKED, TRACKED, TRACKED, INFERRED, NOT_TRACKED], (T, NUM_JOINTS))
    states[:10] = TRACKED
    est = ReliabilityEstimator(reference_mode='standard', plausibility=False)  # Eq. 1-8 alone
    minima = []
    for t in range(T):
        ts = states[t].astype(np.uint8)
        got = est.update(pos[t], ts)
        hist = pos[max(0, t - est.f_b - 1):t + 1]
        rb, _ = behaviour_term(hist, est.d_min, est.f_b, est.theta_floor, est.theta_roof)
        rk = kinematics_term(pos[t], est.reference_lengths)
        rt = tracking_term(ts)
        minima.append(np.minimum(np.minimum(rb, rk), rt))
        win = np.array(minima[-est.f_total:])
        ref = np.clip(gaussian_weights(len(win), est.sigma_frames) @ win, 0, 1)
        assert np.allclose(got, ref, atol=1e-12), t
        assert np.allclose(est.last_terms[0], rb, atol=1e-12)


def test_reference_capture_decision_matches_reference_pose_match():
    from pose_reconstruction.reliability import _pose_match_segments
    rng = np.random.default_rng(4)
    p0 = rest()
    tol = 25.0
    seen = set()
    for i in range(60):
        p = p0 + rng.normal(0, 0.04 * (i % 6), p0.shape)
        a = np.radians(rng.uniform(-180, 180))
        c, s = np.cos(a), np.sin(a)
        p = p @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]).T
        seg = p[list(SEGMENT_CHILDREN)] - p[list(SEGMENT_PARENTS)]
        got = _pose_match_segments(p, seg, np.linalg.norm(seg, axis=1), np.cos(np.radians(tol)))
        assert got == reference_pose_match(p, tol), i
        seen.add(got)
    assert 'tpose' in seen and None in seen


def test_height_prior_until_the_height_is_measured():
    # no frame with every joint tracked: the prior (e.g. the reconstructor's database fit) is
    # the height and scales the standard-body reference lengths; a measured height replaces it
    from skeleton_core.model import NOT_TRACKED, TRACKED, standard_body
    est = ReliabilityEstimator(reference_mode='standard')
    ts = np.full(20, TRACKED, np.uint8)
    ts[0] = NOT_TRACKED
    est.update(rest(), ts)
    assert est.height == 1.75 and not est.height_measured
    est.set_height_prior(1.55)
    assert est.height == 1.55
    assert np.allclose(est.reference_lengths, standard_body(1.55).segment_lengths)
    est.set_height_prior(5.0)                  # clipped to the estimator's range
    assert est.height == 2.3
    est.set_height_prior(None)
    assert est.height == 1.75
    est.set_height_prior(1.55)
    tall = standard_body(1.9).rest_positions()
    est.update(tall, np.full(20, TRACKED, np.uint8))
    assert est.height_measured and abs(est.height - 1.9) < 0.02


def test_tpose_of_a_skeleton_with_dropped_hip_joints_is_recognised():
    """Mocap skeletons (e.g. CMU) put the hip joints ~50 deg below the pelvis centre where the
    standard body has them level: the reference-posture test judges limbs and spine, not the
    girdles, so such a T-pose still gives the user's own reference lengths."""
    p = standard_body(1.7).rest_positions()
    for hip, knee, ankle, foot in ((HIP_LEFT, KNEE_LEFT, ANKLE_LEFT, FOOT_LEFT),
                                   (HIP_RIGHT, KNEE_RIGHT, ANKLE_RIGHT, FOOT_RIGHT)):
        v = p[hip] - p[HIP_CENTER]
        w = np.linalg.norm(v)
        drop = np.array([v[0], v[1], 0.0]) / np.linalg.norm(v[:2]) * w * np.cos(np.radians(50)) \
            - np.array([0.0, 0.0, w * np.sin(np.radians(50))])
        shift = p[HIP_CENTER] + drop - p[hip]
        p[[hip, knee, ankle, foot]] += shift   # the whole leg hangs from the lowered hip joint
    assert reference_pose_match(p, 25.0) == 'tpose'
    est = ReliabilityEstimator(reference_mode='standard')
    est.update(p, np.full(NUM_JOINTS, TRACKED, np.uint8))
    assert est.reference_source == 'tpose'
    seg = p[list(SEGMENT_CHILDREN)] - p[list(SEGMENT_PARENTS)]
    assert np.allclose(est.reference_lengths, np.linalg.norm(seg, axis=1))
    # the limbs still decide: the same skeleton with the arms down is 'standing', not 'tpose'
    arms = p.copy()
    for sh, chain in ((SHOULDER_LEFT, (ELBOW_LEFT, WRIST_LEFT, HAND_LEFT)),
                      (SHOULDER_RIGHT, (ELBOW_RIGHT, WRIST_RIGHT, HAND_RIGHT))):
        for j in chain:
            d = np.linalg.norm(p[j] - p[sh])
            arms[j] = p[sh] - np.array([0.0, 0.0, d])
    assert reference_pose_match(arms, 25.0) == 'standing'


def test_fast_medians_equal_numpy():
    """The running medians (observed reference lengths, height) give np.nanmedian's and
    np.median's values exactly."""
    from pose_reconstruction.reliability import _column_nanmedian, _median_of
    rng = np.random.default_rng(2)
    for rows in (1, 2, 5, 10, 37, 90):
        obs = rng.normal(1.0, 0.3, (rows, 19))
        obs[rng.random(obs.shape) < 0.4] = np.nan
        count = np.sum(np.isfinite(obs), axis=0)
        ok = count >= 1
        with np.errstate(all='ignore'):
            ref = np.nanmedian(obs[:, ok], axis=0)
        np.testing.assert_array_equal(_column_nanmedian(obs, count)[ok], ref)
        v = list(rng.normal(1.7, 0.1, rows))
        assert _median_of(v) == float(np.median(v))


def test_fast_column_median_equals_numpy():
    from pose_reconstruction.reliability import _column_median
    rng = np.random.default_rng(6)
    for rows in (1, 2, 3, 8, 15):
        a = rng.normal(0.3, 0.05, (rows, 19))
        np.testing.assert_array_equal(_column_median(a), np.median(a, axis=0))
        a[0, 4] = np.nan
        np.testing.assert_array_equal(_column_median(a), np.median(a, axis=0))


def test_plausibility_running_floor_quantile_is_np_quantile():
    """The floor's running quantile (sorted window, bisect) gives np.quantile's value at every
    frame, through the window's eviction and a NaN in it (np.quantile: NaN)."""
    from pose_reconstruction.plausibility import PlausibilityCheck
    pc = PlausibilityCheck(floor_window=7)
    rng = np.random.default_rng(3)
    vals = list(rng.normal(0.0, 0.05, 40).round(2))   # ties included
    vals[12] = float('nan')
    for z in vals:
        pc._floor_push(float(z))
        for q in (0.25, 0.5, 0.1, 0.9):
            got, want = pc._floor_quantile(q), float(np.quantile(pc._floor_z, q))
            assert (np.isnan(got) and np.isnan(want)) or got == want


@pytest.mark.parametrize('scenario', ['c', 'd'])
def test_compiled_step_agrees_with_numpy(scenario):
    """The compiled Eq. 1-8 / plausibility steps (reliability_kernels, numba) and the numpy twin
    give the same reliability, terms and state on a sensor-model stream with occlusions (c) and
    confident failures (d): jumps, snaps, floor (its window evicting), swapped limbs; heading,
    floor and swap flags included."""
    from skeleton_core import jit
    if not jit.enabled():
        pytest.skip('numba off: the numpy twin is the only path')
    from skeleton_eval.clips import toy_clip
    from skeleton_eval.sensor_model import SensorModel
    s = SensorModel(None, seed=2).corrupt(toy_clip(), scenario, seed=2)
    pos = s.positions.copy()
    pos[100:106] += (1.0, 0.0, 0.0)            # a whole-skeleton jump (another person)
    pos[150:160, HAND_LEFT] += (0.0, 0.0, 0.5)  # a snapped hand (latched segment)
    pos[200:210, FOOT_RIGHT, 2] -= 0.2          # a foot through the floor
    from pose_reconstruction.plausibility import unswap_permutation
    pos[240:250] = pos[240:250][:, unswap_permutation({'arms': True})]   # arms swapped L/R
    est = {}
    for compiled in (True, False):
        e = ReliabilityEstimator()
        e._jit = e.plausibility._jit = compiled
        est[compiled] = e
    outlier = latched = swaps = 0
    for p, ts in zip(pos, s.tracking_state):
        a, b = est[True].update(p, ts), est[False].update(p, ts)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
        for ta, tb in zip(est[True].last_terms, est[False].last_terms):
            np.testing.assert_allclose(ta, tb, rtol=0, atol=1e-12)
        assert est[True].plausibility.skeleton_outlier == est[False].plausibility.skeleton_outlier
        assert np.array_equal(est[True].plausibility._latch, est[False].plausibility._latch)
        pa, pb = est[True].plausibility, est[False].plausibility
        assert pa.swapped == pb.swapped
        assert (pa.heading is None) == (pb.heading is None)
        if pa.heading is not None:
            assert abs(pa.heading - pb.heading) < 1e-12
        assert (pa.floor is None) == (pb.floor is None)
        if pa.floor is not None:
            assert abs(pa.floor - pb.floor) < 1e-12
        swaps += int(pa.swapped['arms'] or pa.swapped['legs'])
        outlier += est[True].plausibility.skeleton_outlier
        latched += int((est[True].plausibility._latch > 0).any())
    assert outlier >= 3 and latched >= 3       # the stream exercises the jump and the latch
    assert swaps >= 3                          # ... and the left/right swap


@pytest.mark.parametrize('scenario', ['c', 'd'])
def test_reacquired_floor_gives_the_bytes_of_the_deque_of_frames(scenario):
    """The re-acquisition floor (ReliabilityEstimator._reacquired) with its Eq. 8 window kept as
    rows of one array, and compiled into the Eq. 1-8 step
    (reliability_kernels.eq18_reacquired_step): the same reliability, bit for bit, as the floor
    in numpy with the window kept as a deque of frames stacked every frame, over a stream longer
    than the window (its rows shifting) with joints lost and re-acquired (c) and confident
    failures (d); with numba off, the numpy floor alone."""
    import collections
    from skeleton_core import jit
    from skeleton_eval.clips import toy_clip
    from skeleton_eval.sensor_model import SensorModel

    class DequeWindow(ReliabilityEstimator):
        _k_reacquired = False     # the compiled Eq. 1-8 step, then the floor below

        raised = 0

        def reset(self):
            super().reset()
            self._dq = collections.deque(maxlen=self.f_total)

        def _reacquired(self, r, rp):
            if not self.plausibility.enabled or self.last_terms is None:
                return r
            rb, rk, rt = self.last_terms
            self._dq.append(np.minimum(rb, rk))
            now = self._gauss[len(self._dq)] @ np.asarray(self._dq)
            np.minimum(now, rt, out=now)
            out = np.maximum(r, now)
            if rp is not None:
                np.minimum(out, rp, out=out)
            np.clip(out, 0.0, 1.0, out=out)
            self.raised += int((out > r).any())    # the floor held a re-acquired joint up
            self.reliability = out
            return out

    s = SensorModel(None, seed=4).corrupt(toy_clip(), scenario, seed=4)
    assert (s.tracking_state != TRACKED).any(axis=1).sum() >= 10   # joints lost and found
    for compiled in ((True, False) if jit.enabled() else (False,)):
        a, b = ReliabilityEstimator(), DequeWindow()
        a._jit = a.plausibility._jit = b._jit = b.plausibility._jit = compiled
        for p, ts in zip(s.positions, s.tracking_state):
            ra, rb_ = a.update(p, ts), b.update(p, ts)
            assert ra.tobytes() == rb_.tobytes()
        assert a._bk_n[0] == a.f_total        # the window filled and shifted
        assert b.raised >= 5                   # ... and the floor mattered
