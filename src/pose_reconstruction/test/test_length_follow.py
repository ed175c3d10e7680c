"""length_follow_cutoff of the segment output: where the sensor is trusted, the
constant lengths follow the slow, pose-dependent part of the observed lengths, not their
frame-to-frame noise; where it is not trusted they stay constant."""
import numpy as np

from pose_reconstruction.segment_output import (_SEG_CHAIN, SEG_DIFF, SegmentOutput,
                                                SegmentOutputConfig)
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS, NUM_SEGMENTS, TRACKED

FPS = 30.0


def _observed(n=300, slow=0.03, noise=0.005, seed=3):
    """Observed segment lengths (n, 19): constant lengths times a slow 0.3 Hz swing of
    ``slow`` (the pose-dependent part) plus white noise of ``noise`` m; and the slow part."""
    rng = np.random.default_rng(seed)
    L = np.linspace(0.1, 0.45, NUM_SEGMENTS)
    t = np.arange(n) / FPS
    phase = rng.uniform(0, 2 * np.pi, NUM_SEGMENTS)
    slow_len = L * (1.0 + slow * np.sin(2 * np.pi * 0.3 * t[:, None] + phase))
    return L, slow_len, slow_len + noise * rng.normal(size=slow_len.shape)


def _run(L, lengths, trust, scale='user', **kw):
    """The output's segment lengths (n, 19) for observed lengths ``lengths`` (fixed directions,
    every joint TRACKED and reliable, no smoothing: only the lengths are looked at)."""
    rng = np.random.default_rng(7)
    u = rng.normal(size=(NUM_SEGMENTS, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    so = SegmentOutput(None, np.full(NUM_SEGMENTS, 0.3), lambda: True, 0.5, scale,
                       SegmentOutputConfig(smooth_min_cutoff=0.0, symmetric_lengths=False, **kw))
    so.profile_lengths = L
    so._standard_lengths = L   # output_scale 'standard': the same lengths
    root = np.array([0.0, 0.1, 2.4])
    out = []
    for k, ln in enumerate(lengths):
        obs = root + _SEG_CHAIN @ (u * ln[:, None])
        f = SkeletonFrame(positions=obs, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                          stamp_ns=int(k * 1e9 / FPS))
        p = so.output(f, obs, np.ones(NUM_JOINTS), trust)
        out.append(np.linalg.norm(SEG_DIFF @ p, axis=1))
    return np.array(out)


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def test_trusted_lengths_follow_the_slow_part_not_the_noise():
    L, slow_len, observed = _observed()
    out = _run(L, observed, 1.0)
    half = slice(len(out) // 2, None)   # after the low-pass has settled
    # nearer the slow, pose-dependent lengths than constant lengths are
    assert _rms(out[half] - slow_len[half]) < 0.5 * _rms(L - slow_len[half])
    # and without the observation's frame-to-frame noise (the output's step is the slow part's)
    step = lambda x: _rms(np.diff(x, axis=0)) / np.sqrt(2)  # noqa: E731
    assert step(observed) > 0.004
    assert step(out) < 0.25 * step(observed)


def test_untrusted_off_or_standard_scale_lengths_are_constant():
    L, _, observed = _observed()
    for out in (_run(L, observed, 0.0), _run(L, observed, 1.0, length_follow_cutoff=0.0),
                _run(L, observed, 1.0, scale='standard')):
        assert np.allclose(out, L[None, :], atol=1e-9)


def test_a_length_far_off_is_followed_only_to_the_bound():
    L, _, _ = _observed()
    out = _run(L, np.tile(1.5 * L, (150, 1)), 1.0)
    assert np.allclose(out[-1], 1.15 * L, rtol=1e-3)
