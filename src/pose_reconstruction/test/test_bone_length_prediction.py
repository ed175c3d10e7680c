"""While a user's lengths converge: the expected final estimate (bone_lengths.py
``BoneLengthEstimator.predicted``), the sensor's noise remembered across users, and the length
prior judging the still-converging lengths as they will be (length_prior.py ``excess``)."""
import numpy as np
import pytest

from pose_reconstruction.bone_lengths import BoneLengthEstimator, SensorLengthNoise
from pose_reconstruction.length_prior import LengthPrior, LengthPriorConfig
from pose_reconstruction.segment_output import (_SEG_CHAIN, SEG_DIFF, SegmentOutput,
                                                SegmentOutputConfig)
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS, NUM_SEGMENTS, TRACKED, standard_body

DT = 1.0 / 30.0
BODY = standard_body().segment_lengths     # the model's proportions at 1.75 m
ALL = np.ones(NUM_SEGMENTS, bool)


def _errors(true, noise, proportions, trials=60, memory=None, seed=0):
    """Mean squared distance (m^2) of the running estimate and of the prediction to the final
    estimate, per frame of the first 14 (15 samples to converge at this noise)."""
    rng = np.random.default_rng(seed)
    est_e, pred_e = np.zeros(14), np.zeros(14)
    for _ in range(trials):
        e = BoneLengthEstimator(samples=15, settle_s=2.0)
        if memory is not None:
            e.noise_memory = memory
        x = true[None] + noise * rng.normal(size=(15, NUM_SEGMENTS))
        running = []
        for k in range(15):
            e.observe(x[k], ALL, DT)
            running.append((e.estimate, e.predicted(proportions)))
        final = e.estimate
        assert e.complete()
        for k in range(14):
            est_e[k] += np.mean((running[k][0] - final) ** 2) / trials
            pred_e[k] += np.mean((running[k][1] - final) ** 2) / trials
    return est_e, pred_e


def test_the_prediction_is_nearer_the_final_estimate_than_the_running_mean():
    """A noisy sensor (1.7 cm) and a user of the model's proportions at another size: from the
    second frame the prediction is much nearer the final estimate than the running mean."""
    est_e, pred_e = _errors(1.1 * BODY, 0.017, BODY)
    assert pred_e[0] == pytest.approx(est_e[0])          # the first frame: no noise known yet
    assert pred_e[1:].sum() < 0.5 * est_e[1:].sum()
    assert np.all(pred_e[1:] <= est_e[1:] * 1.05)


def test_the_sensor_noise_seen_on_an_earlier_user_predicts_the_first_frame():
    mem = SensorLengthNoise()
    mem.add(100 * 0.017 ** 2, 100)
    est_e, pred_e = _errors(BODY, 0.017, BODY, memory=mem)
    assert pred_e[0] < 0.5 * est_e[0]


def test_proportions_that_do_not_fit_the_user_hardly_move_it():
    """Segments 0.6-1.4 times the proportions (another layout): the spread found on the user is
    large, the prediction stays near the running mean (no worse than it)."""
    rng = np.random.default_rng(3)
    true = BODY * rng.uniform(0.6, 1.4, NUM_SEGMENTS)
    est_e, pred_e = _errors(true, 0.017, BODY)
    assert pred_e.sum() <= 1.05 * est_e.sum()


def test_of_several_proportions_the_most_likely_is_used():
    wrong = BODY[::-1].copy()
    a = _errors(BODY, 0.017, BODY, seed=5)[1]
    b = _errors(BODY, 0.017, np.stack([wrong, BODY]), seed=5)[1]
    np.testing.assert_allclose(a, b, rtol=1e-9)


def test_the_prediction_is_the_estimate_where_done_and_when_no_more_samples_can_come():
    rng = np.random.default_rng(1)
    x = BODY[None] * 1.1 + 0.002 * rng.normal(size=(3, NUM_SEGMENTS))   # steady: done in 3
    e = BoneLengthEstimator(samples=15, settle_s=2.0)
    for k in range(3):
        e.observe(x[k], ALL, DT)
    assert e.done.all()
    np.testing.assert_array_equal(e.predicted(BODY), e.estimate)
    assert not e.excess_variances().any()
    # a noisy segment at the settle time: nothing more can come, nothing predicted
    e = BoneLengthEstimator(samples=15, settle_s=0.2)
    for k in range(7):
        e.observe(BODY + 0.03 * rng.normal(size=NUM_SEGMENTS), ALL, DT)
    assert not e.done.all() and e._elapsed >= 0.2 - 1e-9
    np.testing.assert_allclose(e.predicted(BODY), e.estimate, rtol=0, atol=1e-15)
    assert not e.excess_variances().any()


def test_the_sensor_noise_is_remembered_when_a_user_is_frozen():
    mem = SensorLengthNoise()
    assert np.isnan(mem.variance)
    mem.add(1.0, 0)                        # nothing to learn from
    assert np.isnan(mem.variance)
    rng = np.random.default_rng(2)
    e = BoneLengthEstimator(samples=15, settle_s=2.0)
    e.noise_memory = mem
    for _ in range(15):
        e.observe(BODY + 0.02 * rng.normal(size=NUM_SEGMENTS), ALL, DT)
    assert e.complete()
    e.freeze(e.estimate)
    assert mem.dof == int((e.counts - 1).sum()) > 10 * NUM_SEGMENTS
    assert np.sqrt(mem.variance) == pytest.approx(0.02, rel=0.15)
    # a new user's first frame: that noise, before its own samples tell
    e2 = BoneLengthEstimator()
    e2.noise_memory = mem
    e2.observe(BODY, ALL, DT)
    np.testing.assert_allclose(e2.noise_variances(), mem.variance)
    assert not BoneLengthEstimator().noise_variances().any()


def _prior():
    cfg = LengthPriorConfig(length_offset_sigma=0.03, length_offset_online=True)
    return LengthPrior(cfg, BODY / 1.75, 0.05 * BODY / 1.75, symmetric=True)


def test_the_length_prior_judges_converging_lengths_as_they_will_be():
    """A glitch on one side in the first frames: without the excess variance the offset scale is
    the glitch's; with it, what the final lengths will show."""
    L = BODY * 1.05
    L[13] += 0.09       # KneeLeft-AnkleLeft 9 cm long in the first frames
    counts = np.full(NUM_SEGMENTS, 2)
    p = _prior()
    plain = p.fuse(L, counts)
    same = p.fuse(L, counts, np.zeros(NUM_SEGMENTS))
    np.testing.assert_array_equal(plain, same)      # final lengths: as before
    inflated = p.offset_sigma
    ex = np.full(NUM_SEGMENTS, 0.01 ** 2)
    ex[13] = 0.09 ** 2                               # that segment's samples vary by as much
    p.fuse(L, counts, ex)
    assert p.offset_sigma < 0.5 * inflated


def _track(so, lengths, seed=7):
    rng = np.random.default_rng(seed)
    root = np.array([0.0, 0.1, 2.4])
    base = rng.normal(size=(NUM_SEGMENTS, 3))
    out = []
    for k, ln in enumerate(lengths):
        u = base + 0.4 * np.sin(2 * np.pi * 0.7 * k * DT + np.arange(NUM_SEGMENTS))[:, None]
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        obs = root + _SEG_CHAIN @ (u * ln[:, None])
        f = SkeletonFrame(positions=obs, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                          stamp_ns=int(k * 1e9 * DT))
        out.append(so.output(f, obs, np.ones(NUM_JOINTS), 1.0))
    return np.linalg.norm(np.einsum('sj,njk->nsk', SEG_DIFF, np.array(out)), axis=2)


def test_a_short_track_moves_less_and_converges_to_the_same_lengths():
    """40 frames (1.3 s) of a noisy sensor's second user, the segment output with and
    without the prediction: the same frozen lengths, the output's bone-length std over the
    whole track well below."""
    rng = np.random.default_rng(11)
    obs = 1.05 * BODY[None] + 0.017 * rng.normal(size=(40, NUM_SEGMENTS))
    std = {}
    frozen = {}
    for name, props in (('plain', None), ('predicted', BODY)):
        so = SegmentOutput(None, BODY, lambda: True, 0.5, 'user', SegmentOutputConfig())
        so.proportions = props
        so.estimator.noise_memory = SensorLengthNoise()
        so.estimator.noise_memory.add(100 * 0.017 ** 2, 100)   # the sensor's first user
        L = _track(so, obs)
        std[name] = float(L.std(axis=0).mean())
        frozen[name] = so.user_lengths
    np.testing.assert_allclose(frozen['predicted'], frozen['plain'], rtol=0, atol=1e-12)
    assert std['predicted'] < 0.6 * std['plain'], std
