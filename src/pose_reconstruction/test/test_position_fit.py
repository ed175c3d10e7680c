"""position_fit of the segment output: the constant-length skeleton placed nearest the observed joints."""
import numpy as np

from pose_reconstruction.segment_output import (_SEG_CHAIN, SEG_DIFF, SegmentOutput,
                                                SegmentOutputConfig)
from skeleton_core.model import HAND_LEFT, HAND_RIGHT, NUM_JOINTS, NUM_SEGMENTS


def _unit(rng, n):
    u = rng.normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _output(**kw):
    return SegmentOutput(None, np.full(NUM_SEGMENTS, 0.3), lambda: True, 0.5, 'user',
                         SegmentOutputConfig(**kw))


def _chain(vr):
    return vr[NUM_SEGMENTS] + _SEG_CHAIN @ vr[:NUM_SEGMENTS]


def test_fit_keeps_the_lengths_and_lands_nearer_the_observed_joints():
    rng = np.random.default_rng(3)
    L = rng.uniform(0.1, 0.4, NUM_SEGMENTS)
    u = _unit(rng, NUM_SEGMENTS)
    root = np.array([0.1, -0.2, 2.5])
    # the sensor's joints: the same directions, lengths 10 % off (a non-rigid skeleton)
    obs = root + _SEG_CHAIN @ (u * (L * rng.uniform(0.9, 1.1, NUM_SEGMENTS))[:, None])
    vr = np.vstack([u * L[:, None], root])
    chained = _chain(vr)
    so = _output()
    so._fit_positions(vr, obs, np.ones(NUM_JOINTS), L)
    fitted = _chain(vr)
    assert np.allclose(np.linalg.norm(SEG_DIFF @ fitted, axis=1), L, atol=1e-9)
    err = lambda p: np.linalg.norm(p - obs, axis=1).mean()  # noqa: E731
    assert err(fitted) < 0.6 * err(chained)


def test_fit_recovers_a_translated_skeleton_and_ignores_missing_joints():
    rng = np.random.default_rng(4)
    L = rng.uniform(0.1, 0.4, NUM_SEGMENTS)
    u = _unit(rng, NUM_SEGMENTS)
    root = np.array([0.0, 0.3, 2.0])
    obs = root + _SEG_CHAIN @ (u * L[:, None])
    vr = np.vstack([u * L[:, None], root + [0.05, 0.0, -0.03]])   # chained from a wrong root
    _output()._fit_positions(vr, obs, np.ones(NUM_JOINTS), L)
    assert np.allclose(_chain(vr), obs, atol=1e-9)
    # hands not observed (NaN) and not pulled: a finite skeleton with the lengths
    obs2 = obs.copy()
    obs2[[HAND_LEFT, HAND_RIGHT]] = np.nan
    pull = np.ones(NUM_JOINTS)
    pull[[HAND_LEFT, HAND_RIGHT]] = 0.0
    vr2 = np.vstack([u * L[:, None], root + [0.05, 0.0, -0.03]])
    _output()._fit_positions(vr2, obs2, pull, L)
    p = _chain(vr2)
    assert np.isfinite(p).all()
    assert np.allclose(np.linalg.norm(SEG_DIFF @ p, axis=1), L, atol=1e-9)
    assert np.abs(p - obs)[[0, 1, 2, 3]].max() < 0.01


def test_a_trusted_observed_direction_is_not_bent_by_the_fit():
    """Where the sensor is trusted and reliable, the output's segment directions are the
    sensor's; the fit places the constant-length skeleton (here: only its root can move), it does
    not turn short segments to restore lengths."""
    from skeleton_core.conversions import SkeletonFrame
    from skeleton_core.model import TRACKED
    rng = np.random.default_rng(4)
    L = rng.uniform(0.08, 0.4, NUM_SEGMENTS)
    u = _unit(rng, NUM_SEGMENTS)
    root = np.array([0.1, -0.2, 2.5])
    obs = root + _SEG_CHAIN @ (u * (L * rng.uniform(0.85, 1.15, NUM_SEGMENTS))[:, None])
    so = _output(smooth_min_cutoff=0.0, symmetric_lengths=False)
    so.profile_lengths = L
    solution = root + _SEG_CHAIN @ (_unit(rng, NUM_SEGMENTS) * L[:, None])  # the database's
    f = SkeletonFrame(positions=obs, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8))
    out = so.output(f, solution, np.ones(NUM_JOINTS), 1.0)
    d = SEG_DIFF @ out
    cos = np.sum(d * u, axis=1) / np.linalg.norm(d, axis=1)
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 1e-4
    assert np.allclose(np.linalg.norm(d, axis=1), L)
    # and it is placed nearer the observed joints than chained from the observed root
    chained = obs[0] + _SEG_CHAIN @ (u * L[:, None])
    err = lambda p: np.linalg.norm(p - obs, axis=1).mean()  # noqa: E731
    assert err(out) < err(chained)
