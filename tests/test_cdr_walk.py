"""walk_cdr, the one walk of a serialized SkeletonArray's offsets that the block decoder and the
light scan share, against the field-by-field reader: the same offsets, counts, ids, stamps and
frame ids on random messages of any sequence lengths, and the same error (type and message) on
every truncation and on corrupted buffers (read little or big endian)."""
import numpy as np
import pytest

pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

from geometry_msgs.msg import Point, Quaternion  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from skeleton_msgs.msg import Skeleton, SkeletonArray  # noqa: E402

from skeleton_core import cdr  # noqa: E402
from skeleton_core.cdr import CdrError, walk_cdr  # noqa: E402

_ITEM = {'f8': 8, 'u1': 1, 'f4': 4}


def _reader_walk(data):
    """What walk_cdr returns, found with the field-by-field reader (cdr._Reader)."""
    r = cdr._Reader(data)
    stamp, frame_id = r.stamp_ns(), r.string()
    heads, at = [], ([], [], [], [])
    for _ in range(r.u32()):
        sk_stamp, sk_frame, uid = r.stamp_ns(), r.string(), r.u32()
        counts = []
        for i, (dtype, per) in enumerate((('f8', 3), ('f8', 4), ('u1', 1), ('f4', 1))):
            k = per * r.u32()
            if k:
                r._align(_ITEM[dtype])
            at[i].append(r.pos if k or i in (0, 2) else -1)
            r.array(dtype, k)
            counts.append(k)
        heads.append((uid, sk_stamp, sk_frame, *counts))
    return (r.end, stamp, frame_id, heads, *at)


def _random_message(rng):
    msg = SkeletonArray()
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(rng.integers(1 << 31)), int(rng.integers(10**9))
    msg.header.frame_id = 'k' * int(rng.integers(0, 9))
    for _ in range(int(rng.integers(0, 5))):
        sk = Skeleton()
        sk.header.stamp.sec, sk.header.stamp.nanosec = int(rng.integers(1 << 31)), int(rng.integers(10**9))
        sk.header.frame_id = 'f' * int(rng.integers(0, 9))
        sk.user_id = int(rng.integers(1 << 32))
        usual = rng.random() < 0.5

        def n(usual=usual):
            return 20 if usual else int(rng.integers(0, 23))
        sk.positions = [Point(x=float(v), y=1.0, z=2.0) for v in rng.normal(size=n())]
        sk.orientations = [Quaternion(w=float(v))
                           for v in rng.normal(size=rng.choice([0, n()]))]
        sk.tracking_state = [int(v) for v in rng.integers(0, 3, n())]
        sk.reliability = [float(v) for v in rng.random(rng.choice([0, n()]))]
        msg.skeletons.append(sk)
    return msg


def _outcome(f, data):
    try:
        f(data)
    except CdrError as e:
        return type(e), str(e)
    return None


@pytest.mark.parametrize('seed', range(8))
def test_offsets_are_the_field_by_field_readers_on_random_messages(seed):
    rng = np.random.default_rng(seed)
    for _ in range(25):
        data = serialize_message(_random_message(rng))
        end, stamp, frame_id, heads, pos_at, ori_at, ts_at, rel_at, usual = walk_cdr(data)
        assert (end, stamp, frame_id, heads, pos_at, ori_at, ts_at, rel_at) == _reader_walk(data)
        for other in (bytearray(data), memoryview(data)):   # any buffer, as the reader takes
            assert walk_cdr(other) == walk_cdr(data)
        assert usual == all(p == 60 and t == 20 and q in (0, 80) and r in (0, 20)
                            for _, _, _, p, q, t, r in heads)


def test_truncated_and_corrupted_buffers_raise_the_readers_error():
    rng = np.random.default_rng(3)
    raised = read = 0
    for _ in range(6):
        data = serialize_message(_random_message(rng))
        buffers = [data[:cut] for cut in range(len(data))]
        for _ in range(60):
            b = bytearray(data)
            for i in rng.integers(0, len(b), rng.integers(1, 4)):
                b[i] = rng.integers(256)
            if rng.random() < 0.3:
                b[1] = 0   # read big endian
            buffers.append(bytes(b))
        for b in buffers:
            want = _outcome(cdr._frames_from_cdr_general, b)
            assert _outcome(walk_cdr, b) == want
            if want is None:
                assert walk_cdr(b)[1:4] == _reader_walk(b)[1:4]
                read += 1
            else:
                raised += 1
    assert raised > 200 and read > 20   # (both kinds seen)
