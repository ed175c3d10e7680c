"""The segment output in two halves around its smoothing filter (SegmentOutput.output_rows,
output_positions), and several users' filters updated together between them (smooth_many):
each user gets the numbers its own output() gives."""
import numpy as np

from pose_reconstruction.segment_output import (SEG_DIFF, _SEG_CHAIN, SegmentOutput,
                                                SegmentOutputConfig, smooth_many)
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS, NUM_SEGMENTS, TRACKED

FPS = 30.0


def _users(n, **cfg):
    out = []
    for u in range(n):
        so = SegmentOutput(None, np.full(NUM_SEGMENTS, 0.3), lambda: True, 0.5, 'user',
                           SegmentOutputConfig(symmetric_lengths=False, **cfg))
        so.profile_lengths = np.linspace(0.1, 0.45, NUM_SEGMENTS) * (1.0 + 0.05 * u)
        out.append(so)
    return out


def _frame(u, k):
    """User ``u``'s frame ``k``: (frame, database solution, reliabilities, trust), each user
    swinging at its own phase, some of its joints unreliable, its own trust."""
    rng = np.random.default_rng(1000 * u + k)
    t = k / FPS
    a = 0.5 * np.sin(2 * np.pi * 0.7 * t + np.linspace(0, np.pi, NUM_SEGMENTS) + u)
    dirs = np.stack([np.sin(a), -np.cos(a), np.zeros_like(a)], axis=1)
    root = np.array([0.6 * u - 1.0, 0.1, 2.4])
    obs = root + _SEG_CHAIN @ (dirs * 0.3) + rng.normal(scale=0.01, size=(NUM_JOINTS, 3))
    solution = root + _SEG_CHAIN @ (np.roll(dirs, u, axis=0) * 0.3)
    w = np.ones(NUM_JOINTS)
    w[rng.choice(NUM_JOINTS, 3 + u, replace=False)] = rng.uniform(0.0, 0.4, 3 + u)
    f = SkeletonFrame(positions=obs, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                      stamp_ns=int(k * 1e9 / FPS) + 2_000_000 * u * (k % 2))
    return f, solution, w, 0.3 + 0.2 * u


def _same_state(a, b):
    fa, fb = a._seg_filter, b._seg_filter
    for name in ('x', 'raw', 'dx', 'fdx', 'fdd', 'fdd2'):
        assert np.array_equal(getattr(fa, name), getattr(fb, name)), name
    assert fa.t_ns == fb.t_ns


def test_users_smoothed_together_get_their_own_output():
    alone, together = _users(4), _users(4)
    for k in range(40):
        frames = [_frame(u, k) for u in range(4)]
        want = [so.output(*f) for so, f in zip(alone, frames)]
        steps = [so.output_rows(*f) for so, f in zip(together, frames)]
        got = [SegmentOutput.output_positions(s, r) for s, r in zip(steps, smooth_many(steps))]
        for a, b, sa, sb in zip(want, got, alone, together):
            assert np.array_equal(a, b)
            _same_state(sa, sb)
    # the users' outputs differ (a mix-up of their rows would show)
    assert not np.allclose(want[0] - want[0][0], want[1] - want[1][0], atol=1e-3)


def test_no_user_no_smoothing_and_a_broken_frame_are_their_own():
    """None stays None, a step without smoothing keeps its rows, a user whose filter raises
    gets the exception while the others get their numbers."""
    ok, ok_alone = _users(2), _users(2)
    off = _users(1, smooth_min_cutoff=0.0)[0]
    for k in range(3):
        frames = [_frame(u, k) for u in range(2)]
        want = [so.output(*f) for so, f in zip(ok_alone, frames)]
        steps = [so.output_rows(*f) for so, f in zip(ok, frames)]
        plain = off.output_rows(*frames[0])
        broken = _users(1)[0].output_rows(*frames[1])
        broken.rows = broken.rows[:5]   # not the filter's 20 rows
        got = smooth_many([None, steps[0], plain, broken, steps[1]])
        assert got[0] is None and got[2] is plain.rows
        assert isinstance(got[3], (ValueError, IndexError))
        assert np.array_equal(SegmentOutput.output_positions(steps[0], got[1]), want[0])
        assert np.array_equal(SegmentOutput.output_positions(steps[1], got[4]), want[1])
    out = SegmentOutput.output_positions(plain, got[2])
    assert np.array_equal(out, plain.rows[NUM_SEGMENTS] + _SEG_CHAIN @ plain.rows[:NUM_SEGMENTS])


def test_the_output_gives_every_segment_its_length_and_keeps_a_vanished_direction():
    so = _users(1)[0]
    step = so.output_rows(*_frame(0, 0))
    rows = step.smooth().copy()
    rows[:NUM_SEGMENTS] *= 1.7   # smoothed rows of other lengths: the output's are the user's
    rows[4] = 0.0                # a segment smoothed to nothing: its unsmoothed direction
    seg = SEG_DIFF @ SegmentOutput.output_positions(step, rows)
    assert np.allclose(np.linalg.norm(seg, axis=1), step.lengths)
    assert np.allclose(seg[4], step.directions[4] * step.lengths[4])
    keep = np.arange(NUM_SEGMENTS) != 4
    unit = rows[:NUM_SEGMENTS][keep] / np.linalg.norm(rows[:NUM_SEGMENTS][keep], axis=1)[:, None]
    assert np.allclose(seg[keep], unit * step.lengths[keep, None])
