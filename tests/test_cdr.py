"""The numpy CDR codec of SkeletonArray against rclpy's own serializer: same frames out of the
same bytes (valid, malformed and duplicate skeletons alike), bytes rclpy reads back."""
import numpy as np
import pytest

pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

from geometry_msgs.msg import Point, Quaternion  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from skeleton_msgs.msg import Skeleton, SkeletonArray  # noqa: E402

from skeleton_core.cdr import (CdrError, frames_from_cdr, frames_to_cdr,  # noqa: E402
                               restamp_cdr, stamp_offsets)
from skeleton_core.conversions import (SkeletonFrame, frames_from_array_msg,  # noqa: E402
                                       frames_to_array_msg)


def _frames(rng, n=3, orient=True):
    out = []
    for k in range(n):
        q = rng.normal(size=(20, 4)) if orient and k % 2 == 0 else None
        out.append(SkeletonFrame(positions=rng.normal(size=(20, 3)),
                                 tracking_state=rng.integers(0, 3, 20).astype(np.uint8),
                                 reliability=np.where(rng.random(20) < 0.2, np.nan,
                                                      rng.random(20)).astype(np.float32),
                                 orientations=q, user_id=k + 1, stamp_ns=1_700_000_000_123_456_789 + k,
                                 frame_id='kinect_link' if k else ''))
    return out


def _same(a, b):
    assert [f.user_id for f in a] == [f.user_id for f in b]
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.positions, y.positions)
        np.testing.assert_array_equal(x.tracking_state, y.tracking_state)
        np.testing.assert_array_equal(x.reliability, y.reliability)
        assert (x.orientations is None) == (y.orientations is None)
        if x.orientations is not None:
            np.testing.assert_allclose(x.orientations, y.orientations, rtol=0, atol=1e-15)
        assert (x.stamp_ns, x.frame_id) == (y.stamp_ns, y.frame_id)


@pytest.mark.parametrize('n', [0, 1, 4])
def test_decodes_what_rclpy_serialized_and_encodes_what_rclpy_reads(n):
    rng = np.random.default_rng(n)
    frames = _frames(rng, n)
    msg = frames_to_array_msg(frames, 42_000_000_007, 'world')
    stamp, frame_id, got = frames_from_cdr(serialize_message(msg))
    assert (stamp, frame_id) == (42_000_000_007, 'world')
    _same(got, frames_from_array_msg(msg))
    # and the other way round: our bytes give rclpy the same message
    back = deserialize_message(frames_to_cdr(frames, 42_000_000_007, 'world'), SkeletonArray)
    assert back.header == msg.header and len(back.skeletons) == n
    _same(frames_from_array_msg(back), frames_from_array_msg(msg))   # (NaN != NaN in ==)


def test_malformed_and_duplicate_skeletons_are_skipped_with_the_same_reasons():
    rng = np.random.default_rng(7)
    good = frames_to_array_msg(_frames(rng, 2), 5, 'k')
    bad_nan = Skeleton(user_id=7, positions=[Point(x=float('nan'))] * 20,
                       tracking_state=[2] * 20, reliability=[1.0] * 20)
    short = Skeleton(user_id=8, positions=[Point()] * 19, tracking_state=[2] * 19)
    state = Skeleton(user_id=9, positions=[Point()] * 20, tracking_state=[5] + [2] * 19)
    quat = Skeleton(user_id=10, positions=[Point()] * 20, tracking_state=[2] * 20,
                    orientations=[Quaternion()] * 3)
    dup = good.skeletons[0]
    msg = SkeletonArray(header=good.header,
                        skeletons=list(good.skeletons) + [bad_nan, short, state, quat, dup])
    e1, e2 = [], []
    _, _, got = frames_from_cdr(serialize_message(msg), e1)
    _same(got, frames_from_array_msg(msg, e2))
    assert [e.cause for e in e1] == [e.cause for e in e2] and len(e1) == 5


@pytest.mark.parametrize('cut', [0, 3, 10, 60, -1])
def test_truncated_buffers_raise_a_clear_error(cut):
    data = serialize_message(frames_to_array_msg(_frames(np.random.default_rng(1), 2), 1, 'k'))
    with pytest.raises(CdrError):
        frames_from_cdr(data[:cut] if cut >= 0 else data[:-7])


def test_validated_frames_are_written_as_they_are():
    """frames_to_cdr(validated=True) on validate_arrays' output (what the nodes publish) gives
    the bytes frames_to_cdr gives on the raw frames."""
    from skeleton_core.conversions import validate_arrays
    frames = _frames(np.random.default_rng(3), n=3)
    checked = [SkeletonFrame(*validate_arrays(f.positions, f.tracking_state, f.reliability,
                                              f.orientations),
                             user_id=f.user_id, stamp_ns=f.stamp_ns, frame_id=f.frame_id)
               for f in frames]
    assert (frames_to_cdr(checked, 5, 'kinect', validated=True)
            == frames_to_cdr(frames, 5, 'kinect'))


def test_restamp_rewrites_every_stamp_as_rclpy_reads_it():
    """A pre-serialized message restamped in place (the benchmark's remote drivers) is the message
    serialized with the new stamp, header and every skeleton alike: rclpy reads that stamp."""
    frames = _frames(np.random.default_rng(3), n=3)
    data = frames_to_cdr(frames, frames[0].stamp_ns, 'kinect_2_link')
    offsets = stamp_offsets(data)
    assert len(offsets) == 1 + len(frames)
    new = 1_800_000_001_000_000_007
    out = restamp_cdr(data, offsets, new)
    assert out == frames_to_cdr([f.copy(stamp_ns=new) for f in frames], new, 'kinect_2_link')
    msg = deserialize_message(out, SkeletonArray)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_800_000_001, 7)
    assert all((sk.header.stamp.sec, sk.header.stamp.nanosec) == (1_800_000_001, 7)
               for sk in msg.skeletons)
    _same([f.copy(stamp_ns=new) for f in frames_from_cdr(data)[2]], frames_from_cdr(out)[2])
    with pytest.raises(CdrError):
        stamp_offsets(data[:len(data) // 2])


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_skeletons_checked_together_decode_as_one_by_one(seed, monkeypatch):
    """A message whose skeletons are all valid is read in blocks and checked in one pass: the
    frames are bit for bit those of the field-by-field reader, checked together and one by one
    (frame_from_arrays), orientations (zero quaternions -> identity, normalised), missing and
    NaN reliabilities and duplicate ids alike."""
    import skeleton_core.cdr as cdr
    rng = np.random.default_rng(seed)
    frames = _frames(rng, 5)
    frames[3].reliability = np.array([], np.float32)     # no reliability: unknown
    msg = frames_to_array_msg(frames, 9, 'k')
    zero = Quaternion(x=0.0, y=0.0, z=0.0, w=0.0)        # a default-constructed C++ message's
    msg.skeletons[1].orientations = [zero] * 20
    msg.skeletons[2].orientations = [Quaternion(x=3.0, y=-40.0, z=0.5, w=1e3)] * 19 + [zero]
    msg.skeletons.append(msg.skeletons[0])               # a duplicate id
    full = serialize_message(msg)
    msg.skeletons[3].reliability = [float('nan')] * 20   # every skeleton complete
    for data in (full, serialize_message(msg)):
        blocks = cdr._decode_blocks(data)
        assert blocks is not None and blocks[3] is not None   # read in blocks, checked at once
        results = []
        for blocks_on, together_on in ((True, True), (False, True), (False, False)):
            monkeypatch.setattr(cdr, '_decode_blocks',
                                cdr.__dict__['_decode_blocks'] if blocks_on else lambda d: None)
            if not together_on:
                monkeypatch.setattr(cdr, '_checked_together', lambda p: None)
            errors = []
            got = frames_from_cdr(data, errors)[2]
            results.append(got)
            assert [e.cause for e in errors] == ['duplicate user id']
            monkeypatch.undo()
        ref = results[-1]
        assert len(ref) == 5
        for got in results[:-1]:
            assert len(got) == len(ref)
            for x, y in zip(got, ref):
                for a, b in ((x.positions, y.positions), (x.tracking_state, y.tracking_state),
                             (x.reliability, y.reliability), (x.orientations, y.orientations)):
                    assert a.dtype == b.dtype and a.shape == b.shape
                    assert a.tobytes() == b.tobytes()
                assert (x.user_id, x.stamp_ns, x.frame_id) == (y.user_id, y.stamp_ns, y.frame_id)


def test_one_invalid_skeleton_sends_the_message_one_by_one():
    """An out-of-range reliability in one skeleton: the message is decoded one by one, that
    skeleton dropped with its reason, the others kept."""
    frames = _frames(np.random.default_rng(4), 3)
    msg = frames_to_array_msg(frames, 9, 'k')
    msg.skeletons[1].reliability = [2.0] * 20
    errors = []
    got = frames_from_cdr(serialize_message(msg), errors)[2]
    assert [f.user_id for f in got] == [1, 3]
    assert [e.cause for e in errors] == ['reliability out of range']


def _outcome(fn, *args):
    """What a call gives: its value, or its exception's type and message."""
    try:
        return fn(*args)
    except Exception as e:  # noqa: BLE001 - compared, not handled
        return (type(e), str(e))


def _decoded(data, decode):
    errors = []
    out = _outcome(decode, data, errors)
    if isinstance(out[0], type):
        return out
    stamp, frame_id, frames = out
    return (stamp, frame_id, [(e.cause, str(e)) for e in errors],
            [(f.positions.tobytes(), f.positions.shape, f.tracking_state.tobytes(),
              f.tracking_state.dtype, f.reliability.tobytes(), f.reliability.dtype,
              None if f.orientations is None else f.orientations.tobytes(),
              type(f.user_id), f.user_id, type(f.stamp_ns), f.stamp_ns, f.frame_id)
             for f in frames])


def _random_frames(rng, n):
    """Skeletons as the nodes send them, some invalid (NaN, far, unknown state, reliability out
    of range, zero quaternion), some without orientations, frame ids of every length mod 8."""
    frames = _frames(rng, n, orient=bool(rng.integers(0, 2)))
    for f in frames:
        f.frame_id = 'kinect_2_link'[:int(rng.integers(0, 14))]
    if n and rng.random() < 0.4:
        f = frames[int(rng.integers(0, n))]
        what = int(rng.integers(0, 5))
        if what == 0:
            f.positions[3, 1] = np.nan
        elif what == 1:
            f.positions[3, 1] = 60.0
        elif what == 2:
            f.tracking_state[2] = 7
        elif what == 3:
            f.reliability[2] = 1.5
        elif f.orientations is not None:
            f.orientations[2] = 0.0
    if n and rng.random() < 0.2:
        frames.append(frames[0])   # a duplicate id
    return frames


def test_block_reader_and_writer_match_the_field_by_field_ones():
    """The usual message read in blocks and frames written in blocks give bit for bit what the
    field-by-field reader and writer give: the same bytes (or the same error) for random frames
    valid and not, the same frames and errors (or the same CdrError) for their bytes,
    truncated, with a random byte changed, and for the fuzz mutations of the robustness tests."""
    import skeleton_core.cdr as cdr
    from kinect_experiments import fuzz
    rng = np.random.default_rng(11)
    blocks_used = 0
    for case in range(150):
        frames = _random_frames(rng, int(rng.integers(0, 7)))
        for validated in (False, True):
            new = _outcome(cdr.frames_to_cdr, frames, 1_700_000_000_000_000_001 + case, 'world',
                           validated)
            old = _outcome(cdr._frames_to_cdr_general, frames, 1_700_000_000_000_000_001 + case,
                           'world', validated)
            assert new == old, (case, validated)
        data = cdr._frames_to_cdr_general(frames, 5, 'world', True)
        variants = [data] + [data[:int(c)] for c in rng.integers(0, len(data), 3)]
        for _ in range(3):
            b = bytearray(data)
            b[int(rng.integers(0, len(b)))] = int(rng.integers(0, 256))
            variants.append(bytes(b))
        for d in variants:
            blocks_used += cdr._decode_blocks(d) is not None
            assert _decoded(d, cdr.frames_from_cdr) == _decoded(d, cdr._frames_from_cdr_general)
    assert blocks_used > 300   # (most of them are the usual message)
    for name, mutate in fuzz.MUTATIONS.items():
        for users in ((1,), (1, 2), (1, 2, 3, 4, 5, 6)):
            msg = fuzz.valid_array(7, users, rng=np.random.default_rng(1))
            mutate(msg)
            d = serialize_message(msg)
            assert _decoded(d, cdr.frames_from_cdr) == _decoded(d, cdr._frames_from_cdr_general), name


def test_header_stamp_is_the_decoded_one():
    from skeleton_core.cdr import header_stamp_ns
    data = frames_to_cdr(_frames(np.random.default_rng(2), 2), 1_700_000_000_000_000_321, 'k')
    assert header_stamp_ns(data) == frames_from_cdr(data)[0] == 1_700_000_000_000_000_321
    with pytest.raises(CdrError):
        header_stamp_ns(data[:6])
