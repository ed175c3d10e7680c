"""Built-in motions: well-formed, on the standard body, on the floor, smooth, split differs."""
import numpy as np
import pytest

from skeleton_core.geometry import quat_rotate
from skeleton_data.mocap import FIVE_CLASSES, rest_directions
from skeleton_core.model import (ANKLE_LEFT, FOOT_LEFT, FOOT_RIGHT, HAND_LEFT, HAND_RIGHT, PARENTS,
                                 ROOT, segment_lengths, standard_body)
from skeleton_data.motions import builtin_clips, builtin_split


@pytest.fixture(scope='module')
def clips():
    return builtin_clips(seed=0)


def test_clip_shapes_classes_durations(clips):
    assert len(clips) >= 7
    names = {c.name for c in clips}
    assert len(names) == len(clips)
    assert {c.motion_class for c in clips} == set(FIVE_CLASSES)
    for c in clips:
        assert c.fps == 30.0 and 5.0 <= c.duration <= 10.0
        assert np.all(np.isfinite(c.positions)) and np.all(np.isfinite(c.orientations))


def test_bone_lengths_are_the_standard_body(clips):
    ref = standard_body().segment_lengths
    for c in clips:
        np.testing.assert_allclose(segment_lengths(c.positions), np.broadcast_to(ref, (len(c), 19)),
                                   atol=1e-9, err_msg=c.name)


def test_feet_on_floor_never_below(clips):
    for c in clips:
        z = c.positions[..., 2]
        assert z.min() > -1e-9, c.name
        feet = c.positions[:, [FOOT_LEFT, FOOT_RIGHT, ANKLE_LEFT], 2]
        # a foot (toe joint or heel) touches the floor in every frame
        assert np.all(feet.min(1) < 0.08), c.name


def test_orientations_exactly_consistent(clips):
    a = rest_directions()[1:]
    for c in clips:
        d = c.positions[:, 1:] - c.positions[:, list(PARENTS[1:])]
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        np.testing.assert_allclose(quat_rotate(c.orientations[:, 1:], a), d, atol=1e-9)


def test_smooth_and_human_speeds(clips):
    for c in clips:
        v = np.linalg.norm(np.diff(c.positions, axis=0), axis=-1) * c.fps
        assert v.max() < 8.0, c.name  # m/s; fast punches/swings stay below this
        acc = np.linalg.norm(np.diff(c.positions, 2, axis=0), axis=-1) * c.fps ** 2
        assert acc.max() < 200.0, c.name


def test_walk_moves_forward_without_skating(clips):
    walk = next(c for c in clips if c.motion_class == 'locomotion')
    p = walk.positions
    speed = np.linalg.norm(p[-1, ROOT, :2] - p[0, ROOT, :2]) / walk.duration
    assert 0.6 < speed < 1.8
    # a foot that stays on the floor does not slide
    for f in (FOOT_LEFT, FOOT_RIGHT):
        on = (p[1:, f, 2] < 1e-6) & (p[:-1, f, 2] < 1e-6)
        slide = np.linalg.norm(p[1:, f, :2] - p[:-1, f, :2], axis=-1)[on]
        assert on.any() and np.median(slide) < 1e-3


def test_punch_reaches_forward(clips):
    from skeleton_core.geometry import normalize
    punch = next(c for c in clips if c.name.startswith('builtin_punch'))
    n, _ = normalize(punch.positions)
    reach = np.maximum(n[:, HAND_LEFT, 0], n[:, HAND_RIGHT, 0])
    assert reach.max() > 0.55 and reach.min() < 0.45


def test_seeds_and_split():
    a = builtin_clips(seed=3)
    b = builtin_clips(seed=3)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.positions, y.positions)
    db, dev = builtin_split(seed=0)
    assert len(db) > len(dev) > 0
    assert not np.allclose(db[0].positions, dev[0].positions)
