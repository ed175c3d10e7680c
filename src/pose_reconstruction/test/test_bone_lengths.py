"""One rigid skeleton per user: the bone-length estimator (bone_lengths.py) and the segment
output's exact lengths on every output posture."""
import warnings

import numpy as np
import pytest

from pose_reconstruction.bone_lengths import (BoneLengthEstimator, robust_mean,
                                              skeleton_bone_lengths)
from pose_reconstruction.segment_output import (_SEG_CHAIN, SEG_DIFF, SegmentOutput,
                                                SegmentOutputConfig)
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS, NUM_SEGMENTS, TRACKED, standard_body

FPS = 30.0
DT = 1.0 / FPS
TRUE = np.linspace(0.1, 0.45, NUM_SEGMENTS)


def _noisy(rng, n, L=TRUE, noise=0.01):
    return L[None] * (1.0 + noise * rng.normal(size=(n, NUM_SEGMENTS)) / L[None] * 0.3)


def _feed(est, frames, trusted=None):
    restarted = []
    for k, ln in enumerate(frames):
        t = np.ones(NUM_SEGMENTS, bool) if trusted is None else trusted[k]
        if est.observe(ln, t, DT):
            restarted.append(k)
        if est.frozen is None and est.complete():
            est.freeze(est.estimate)
    return restarted


def test_robust_mean_ignores_outliers_and_is_the_mean_without_them():
    x = np.array([0.30, 0.31, 0.29, 0.30, 0.31, 0.29, 0.60])
    assert robust_mean(x) == pytest.approx(0.30, abs=1e-9)
    y = np.array([0.30, 0.302, 0.298])
    assert robust_mean(y) == pytest.approx(y.mean())
    assert np.isnan(robust_mean(np.array([])))


def test_converges_within_the_first_second_on_noisy_input_then_frozen():
    rng = np.random.default_rng(0)
    est = BoneLengthEstimator(samples=15, settle_s=2.0)
    frames = TRUE[None] + 0.01 * rng.normal(size=(300, NUM_SEGMENTS))   # 1 cm noise
    _feed(est, frames[:15])
    assert est.frozen is not None   # 0.5 s of trusted frames
    assert np.abs(est.frozen - TRUE).max() < 0.012   # ~ 1 cm / sqrt(15), 4 sigma
    frozen = est.frozen.copy()
    assert _feed(est, frames[15:]) == []
    np.testing.assert_array_equal(est.frozen, frozen)


def test_untrusted_frames_and_outliers_do_not_move_the_estimate():
    rng = np.random.default_rng(1)
    frames = TRUE[None] + 0.002 * rng.normal(size=(60, NUM_SEGMENTS))
    trusted = np.ones((60, NUM_SEGMENTS), bool)
    # an occluded arm: wildly wrong lengths, not trusted
    frames[::2, 5:8] = 2.0
    trusted[::2, 5:8] = False
    # a glitch the reliability missed: 3 trusted frames 40 % off
    frames[3:6, 10] *= 1.4
    est = BoneLengthEstimator(samples=15, settle_s=0.0)
    _feed(est, frames, trusted)
    assert est.frozen is not None
    assert np.abs(est.frozen - TRUE).max() < 0.003


def test_a_segment_never_trusted_is_frozen_after_the_settle_time():
    est = BoneLengthEstimator(samples=15, settle_s=1.0)
    trusted = np.ones((60, NUM_SEGMENTS), bool)
    trusted[:, 4] = False
    _feed(est, np.tile(TRUE, (60, 1)), trusted)
    assert est.frozen is not None and np.isnan(est.frozen[4])   # the caller's fallback then
    assert est.counts[4] == 0
    est2 = BoneLengthEstimator(samples=15, settle_s=0.0)
    _feed(est2, np.tile(TRUE, (60, 1)), trusted)
    assert est2.frozen is None   # settle 0: waits for every segment


def test_another_person_under_the_same_id_is_estimated_again():
    rng = np.random.default_rng(2)
    a = TRUE[None] + 0.005 * rng.normal(size=(150, NUM_SEGMENTS))
    b = 0.8 * TRUE[None] + 0.005 * rng.normal(size=(150, NUM_SEGMENTS))   # a child
    est = BoneLengthEstimator(samples=15, change=0.12, change_s=1.0)
    assert _feed(est, a) == []
    restarted = _feed(est, b)
    assert len(restarted) == 1 and 15 <= restarted[0] <= 90   # after ~1 s of disagreement
    assert est.restarts == 1
    assert np.abs(est.frozen - 0.8 * TRUE).max() < 0.012   # 4 standard errors (tolerance 3 mm)


def test_a_short_disagreement_or_few_segments_do_not_restart():
    rng = np.random.default_rng(3)
    est = BoneLengthEstimator(samples=15, change=0.12, change_s=1.0)
    _feed(est, TRUE[None] + 0.003 * rng.normal(size=(30, NUM_SEGMENTS)))
    # 10 frames (1/3 s) of a skeleton 50 % off, then back; then many frames with only 4
    # trusted segments far off (an arm and a leg flailing)
    wrong = np.tile(1.5 * TRUE, (10, 1))
    back = np.tile(TRUE, (60, 1))
    few = np.tile(1.5 * TRUE, (90, 1))
    trusted = np.zeros((90, NUM_SEGMENTS), bool)
    trusted[:, :4] = True
    assert _feed(est, np.concatenate([wrong, back])) == []
    assert _feed(est, few, trusted) == []
    assert est.restarts == 0


def test_the_estimator_is_the_same_for_any_tracker_layout():
    """Nothing depends on which segments a tracker sees: a tracker without hands and feet
    (trusted nowhere there) converges on the rest and freezes after the settle time."""
    rng = np.random.default_rng(4)
    trusted = np.ones((90, NUM_SEGMENTS), bool)
    trusted[:, [6, 10, 14, 18]] = False
    est = BoneLengthEstimator(samples=15, settle_s=2.0)
    _feed(est, TRUE[None] + 0.003 * rng.normal(size=(90, NUM_SEGMENTS)), trusted)
    assert est.frozen is not None
    seen = trusted[0]
    assert np.abs(est.frozen[seen] - TRUE[seen]).max() < 0.004


def _output(L, lengths, trust, dirs=None, **kw):
    """The output positions (n, 20, 3) of a segment output fed observed lengths ``lengths``
    (n, 19), every joint TRACKED and reliable, directions swinging, default smoothing."""
    rng = np.random.default_rng(7)
    so = SegmentOutput(None, np.full(NUM_SEGMENTS, 0.3), lambda: True, 0.5, 'user',
                       SegmentOutputConfig(symmetric_lengths=False, **kw))
    root = np.array([0.0, 0.1, 2.4])
    base = rng.normal(size=(NUM_SEGMENTS, 3))
    out = []
    for k, ln in enumerate(lengths):
        t = k / FPS
        u = base + 0.4 * np.sin(2 * np.pi * 0.7 * t + np.arange(NUM_SEGMENTS))[:, None]
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        obs = root + _SEG_CHAIN @ (u * ln[:, None]) + 0.01 * rng.normal(size=(NUM_JOINTS, 3))
        sol = root + _SEG_CHAIN @ (np.roll(u, 1, axis=0) * 0.3)
        f = SkeletonFrame(positions=obs, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                          stamp_ns=int(k * 1e9 / FPS))
        out.append(so.output(f, sol, np.ones(NUM_JOINTS), trust))
    return so, np.array(out)


@pytest.mark.parametrize('trust', [0.0, 0.5, 1.0])
def test_every_output_posture_has_exactly_the_users_lengths(trust):
    rng = np.random.default_rng(5)
    # observed lengths changing slowly with the pose (8 %) and noisy: the output does not follow
    slow = TRUE[None] * (1.0 + 0.08 * np.sin(np.linspace(0, 6, 240))[:, None])
    so, out = _output(TRUE, slow + 0.005 * rng.normal(size=slow.shape), trust)
    L = np.linalg.norm(np.einsum('sj,njk->nsk', SEG_DIFF, out), axis=2)
    frozen = so.user_lengths
    assert frozen is not None
    # after the first length_frames frames: exact, through the smoothing, its prediction
    # correction and the position fit
    np.testing.assert_allclose(L[so.length_frames:], np.tile(frozen, (len(L) - so.length_frames, 1)),
                               rtol=1e-12, atol=1e-12)
    assert np.abs(frozen - TRUE).max() < 0.03


def test_a_profile_of_another_person_is_replaced_by_an_estimate():
    rng = np.random.default_rng(6)
    obs = np.tile(TRUE, (120, 1)) + 0.002 * rng.normal(size=(120, NUM_SEGMENTS))
    so = SegmentOutput(None, np.full(NUM_SEGMENTS, 0.3), lambda: True, 0.5, 'user',
                       SegmentOutputConfig(symmetric_lengths=False))
    so.profile_lengths = 1.3 * TRUE
    root = np.zeros(3)
    u = np.tile([0.0, 1.0, 0.0], (NUM_SEGMENTS, 1))
    for k, ln in enumerate(obs):
        p = root + _SEG_CHAIN @ (u * ln[:, None])
        f = SkeletonFrame(positions=p, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                          stamp_ns=int(k * 1e9 / FPS))
        so.output(f, p, np.ones(NUM_JOINTS), 1.0)
    assert so.estimator.restarts == 1
    assert np.abs(so.user_lengths - TRUE).max() < 0.005


def test_skeleton_bone_lengths_by_segment_name():
    p = standard_body(1.75).rest_positions()
    d = skeleton_bone_lengths(p)
    assert len(d) == NUM_SEGMENTS and 'HipCenter-Spine' in d
    np.testing.assert_allclose(list(d.values()), standard_body(1.75).segment_lengths, atol=1e-9)
    with pytest.raises(ValueError):
        skeleton_bone_lengths(np.zeros((3, 3)))


def test_segments_the_sensor_gets_wrong_are_not_another_person():
    """11 of the 19 trusted segments 30 % off for 5 s, 6 longer and 5 shorter (an occluder, a
    confident failure) are not a size change: no restart (the median of the absolute log ratios
    would have restarted)."""
    est = BoneLengthEstimator(samples=15, change=0.12, change_s=3.0)
    _feed(est, np.tile(TRUE, (30, 1)))
    wrong = np.tile(TRUE, (150, 1))
    wrong[:, :6] *= 1.3
    wrong[:, 6:11] *= 0.7
    assert np.median(np.abs(np.log(wrong[0] / TRUE))) > 0.12
    assert _feed(est, wrong) == [] and est.restarts == 0
    # while the whole skeleton 30 % larger for 5 s is
    assert len(_feed(est, np.tile(1.3 * TRUE, (150, 1)))) == 1


@pytest.mark.parametrize('method', ['B', 'C'])
def test_methods_b_and_c_output_one_rigid_skeleton(method):
    """On a noisy, occluded stream: after the lengths are frozen, every output posture of B and
    C has exactly them (smoothing, prediction correction, position fit, filled segments)."""
    from pose_reconstruction.reconstructor import Reconstructor
    from pose_reconstruction.synthetic import scenario
    db, _, obs, ts = scenario(frames=90)
    r = Reconstructor(db, method=method)
    frozen_at, L = None, []
    for k in range(len(obs)):
        o = r.process(SkeletonFrame(positions=obs[k], tracking_state=ts[k], user_id=1,
                                    stamp_ns=k * 33_333_333))
        L.append(np.linalg.norm(SEG_DIFF @ o.positions, axis=1))
        if frozen_at is None and r.bone_lengths is not None:
            frozen_at = k
    assert frozen_at is not None and frozen_at <= 61   # at the latest 2 s after the first
    L = np.array(L[frozen_at:])
    np.testing.assert_allclose(L, np.tile(r.bone_lengths, (len(L), 1)), rtol=1e-12, atol=1e-12)
    assert r.bone_length_restarts == 0


def test_a_steady_sensor_converges_in_min_samples_a_noisy_one_averages_more():
    rng = np.random.default_rng(8)
    steady = TRUE[None] + 0.002 * rng.normal(size=(30, NUM_SEGMENTS))   # 2 mm
    noisy = TRUE[None] + 0.02 * rng.normal(size=(30, NUM_SEGMENTS))    # 2 cm
    for frames, want in ((steady, 3), (noisy, 15)):
        est = BoneLengthEstimator(samples=15, settle_s=0.0, min_samples=3, tolerance=0.003)
        k = 0
        while est.frozen is None:
            _feed(est, frames[k:k + 1])
            k += 1
        assert k == want
    # the standard error of the noisy estimate is the tolerance's order, not 2 cm / sqrt(3)
    assert np.abs(est.frozen - TRUE).max() < 0.02


def test_median_is_numpys_median():
    from pose_reconstruction.bone_lengths import median
    rng = np.random.default_rng(3)
    for n in range(0, 26):
        for _ in range(20):
            x = rng.normal(size=n) * rng.uniform(1e-3, 10.0)
            if n > 2 and rng.uniform() < 0.2:
                x[rng.integers(n)] = np.nan
            if n > 3 and rng.uniform() < 0.2:
                x[1] = x[2]
            with np.errstate(all='ignore'), warnings.catch_warnings():
                warnings.simplefilter('ignore')
                want = float(np.median(x))
            got = median(x)
            assert (np.isnan(want) and np.isnan(got)) or got == want
    assert median(np.array([1.0, 3.0])) == 2.0 and median(np.array([5.0, 1.0, 2.0])) == 2.0


def test_sample_std_is_numpys():
    from pose_reconstruction.bone_lengths import sample_std
    rng = np.random.default_rng(5)
    for n in list(range(2, 60)) + [100, 129, 300]:
        buf = rng.normal(0.3, 0.01, (n + 3, 4)) * rng.uniform(0.1, 10.0)
        x = buf[:n, 2]   # a strided column, as the estimator's samples
        assert sample_std(x) == float(np.std(x, ddof=1))
