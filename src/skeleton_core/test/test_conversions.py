"""Message <-> array conversions: round trip and rejection of malformed skeletons."""
import math

import numpy as np
import pytest

from skeleton_core import model as m
from skeleton_core.conversions import (SkeletonFormatError, SkeletonFrame, frames_from_array_msg,
                                       frames_to_array_msg, skeleton_from_msg, skeleton_to_msg,
                                       validate_arrays)

pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')


def make_frame(uid=1):
    rng = np.random.default_rng(uid)
    p = m.standard_body().rest_positions() + [2.5, 0.0, -0.8]
    q = rng.normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return SkeletonFrame(positions=p, tracking_state=rng.integers(0, 3, 20).astype(np.uint8),
                         reliability=rng.random(20).astype(np.float32), orientations=q,
                         user_id=uid, stamp_ns=1_700_000_000_123_456_789, frame_id='kinect_link')


def test_round_trip_keeps_every_field():
    f = make_frame()
    g = skeleton_from_msg(skeleton_to_msg(f))
    assert np.allclose(g.positions, f.positions)
    assert np.array_equal(g.tracking_state, f.tracking_state)
    assert np.allclose(g.reliability, f.reliability)
    assert np.allclose(g.orientations, f.orientations)
    assert (g.user_id, g.stamp_ns, g.frame_id) == (f.user_id, f.stamp_ns, f.frame_id)


def test_reliability_nan_until_computed():
    f = make_frame()
    f.reliability = np.full(20, np.nan, np.float32)
    msg = skeleton_to_msg(f)
    assert all(math.isnan(r) for r in msg.reliability)
    assert np.all(np.isnan(skeleton_from_msg(msg).reliability))


@pytest.mark.parametrize('mutate, cause', [
    (lambda msg: msg.positions.pop(), 'wrong length'),
    (lambda msg: setattr(msg.positions[3], 'x', float('nan')), 'non-finite position'),
    (lambda msg: setattr(msg.positions[3], 'z', float('inf')), 'non-finite position'),
    (lambda msg: setattr(msg.positions[0], 'y', 1e6), 'coordinate out of range'),
    (lambda msg: setattr(msg, 'tracking_state', [2] * 19), 'wrong length'),
    (lambda msg: setattr(msg, 'tracking_state', [7] * 20), 'unknown tracking state'),
    (lambda msg: setattr(msg, 'reliability', [0.5] * 21), 'wrong length'),
    (lambda msg: setattr(msg, 'reliability', [1.5] * 20), 'reliability out of range'),
    (lambda msg: msg.orientations.pop(), 'wrong length'),
])
def test_malformed_skeletons_rejected_with_clear_cause(mutate, cause):
    msg = skeleton_to_msg(make_frame())
    mutate(msg)
    with pytest.raises(SkeletonFormatError) as e:
        skeleton_from_msg(msg)
    assert e.value.cause == cause


def test_validate_arrays_rejects_wrong_shapes():
    with pytest.raises(SkeletonFormatError, match='positions must be'):
        validate_arrays(np.zeros((15, 3)))
    with pytest.raises(SkeletonFormatError):
        skeleton_to_msg(SkeletonFrame(positions=np.zeros((20, 2)), tracking_state=np.zeros(20)))


def test_array_message_skips_bad_and_duplicate_users():
    good, dup, bad = make_frame(1), make_frame(1), make_frame(2)
    msg = frames_to_array_msg([good, dup], 5, 'kinect_link')
    bad_msg = skeleton_to_msg(bad)
    bad_msg.positions[0].x = float('nan')
    msg.skeletons.append(bad_msg)
    errors = []
    frames = frames_from_array_msg(msg, errors)
    assert [f.user_id for f in frames] == [1]
    assert sorted(e.cause for e in errors) == ['duplicate user id', 'non-finite position']


def test_message_constants_match_the_skeleton_model():
    from skeleton_msgs.msg import Skeleton
    import re
    assert Skeleton.NUM_JOINTS == m.NUM_JOINTS
    for j, name in enumerate(m.JOINT_NAMES):
        const = 'JOINT_' + re.sub(r'(?<!^)(?=[A-Z])', '_', name).upper()
        assert getattr(Skeleton, const) == j, const
    assert (Skeleton.NOT_TRACKED, Skeleton.INFERRED, Skeleton.TRACKED) == (
        m.NOT_TRACKED, m.INFERRED, m.TRACKED)


def test_copy_owns_its_arrays_and_takes_changes_as_given():
    f = SkeletonFrame(positions=np.zeros((20, 3)), tracking_state=np.full(20, 2, np.uint8),
                      orientations=np.tile([0.0, 0.0, 0.0, 1.0], (20, 1)), user_id=4,
                      stamp_ns=7, frame_id='k')
    c = f.copy()
    for name in ('positions', 'tracking_state', 'reliability', 'orientations'):
        assert getattr(c, name) is not getattr(f, name)
        np.testing.assert_array_equal(getattr(c, name), getattr(f, name))
    assert (c.user_id, c.stamp_ns, c.frame_id) == (4, 7, 'k')
    p = np.ones((20, 3))
    c = f.copy(positions=p, orientations=None, stamp_ns=9)
    assert c.positions is p and c.orientations is None and c.stamp_ns == 9
    assert c.tracking_state is not f.tracking_state
    with pytest.raises(TypeError):
        f.copy(position=p)
