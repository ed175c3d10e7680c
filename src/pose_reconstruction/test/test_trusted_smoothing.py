"""smooth_trusted_scale of the segment output: a segment the output takes from the
sensor is smoothed less (its lag bent what the sensor gives right); what the database gives keeps
the full smoothing."""
import numpy as np

from pose_reconstruction.segment_output import (_SEG_CHAIN, SEG_DIFF, SegmentOutput,
                                                SegmentOutputConfig)
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS, NUM_SEGMENTS, TRACKED

FPS = 30.0


def _dirs(t, amp, phase):
    """(19, 3) unit directions swinging by ``amp`` rad at 0.7 Hz about per-segment axes."""
    a = amp * np.sin(2 * np.pi * 0.7 * t + phase)
    return np.stack([np.sin(a), -np.cos(a), np.zeros_like(a)], axis=1)


def _run(scale, trust, obs_weight=None):
    """Mean angle (deg) between the output's and the observed segment directions over the last
    2 s of a 4 s swing, and the output positions."""
    L = np.linspace(0.1, 0.45, NUM_SEGMENTS)
    phase = np.linspace(0, np.pi, NUM_SEGMENTS)
    kw = {} if obs_weight is None else dict(direction_fusion=False, observation_weight=obs_weight)
    so = SegmentOutput(None, np.full(NUM_SEGMENTS, 0.3), lambda: True, 0.5, 'user',
                       SegmentOutputConfig(smooth_trusted_scale=scale, symmetric_lengths=False,
                                           position_fit=0.0, **kw))
    so.profile_lengths = L
    root = np.array([0.0, 0.1, 2.4])
    errs, outs = [], []
    for k in range(int(4 * FPS)):
        t = k / FPS
        u = _dirs(t, 0.5, phase)
        obs = root + _SEG_CHAIN @ (u * L[:, None])
        solution = root + _SEG_CHAIN @ (_dirs(t, 0.2, phase + 1.0) * L[:, None])
        f = SkeletonFrame(positions=obs, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                          stamp_ns=int(k * 1e9 / FPS))
        out = so.output(f, solution, np.ones(NUM_JOINTS), trust)
        d = SEG_DIFF @ out
        cos = np.sum(d * u, axis=1) / np.linalg.norm(d, axis=1)
        errs.append(np.degrees(np.arccos(np.clip(cos, -1, 1))).mean())
        outs.append(out)
    return float(np.mean(errs[int(2 * FPS):])), np.array(outs)


def test_a_segment_taken_from_the_sensor_lags_less():
    full, _ = _run(1.0, 1.0)
    light, _ = _run(2.0, 1.0)
    assert full > 1.0                # the smoothing's lag on a 0.7 Hz swing
    assert light < 0.5 * full        # (1.7 -> 0.6 deg at the default 2)


def test_what_the_database_gives_keeps_the_full_smoothing():
    # untrusted, the observation's weight 0: the output is the database's, smoothed as before
    _, a = _run(1.0, 0.0, obs_weight=0.0)
    _, b = _run(2.0, 0.0, obs_weight=0.0)
    assert np.allclose(a, b)
