"""scan_cdr, the light read of a serialized SkeletonArray (header stamp; per skeleton user id,
stamp and why it is not a frame), against frames_from_cdr on the same bytes: random valid
messages of 1-6 users with and without NaN, every fuzz mutation, and truncated or corrupted
buffers (rejected by both, or read the same by both)."""
import numpy as np
import pytest

pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

from rclpy.serialization import serialize_message  # noqa: E402

import skeleton_core.cdr_scan as cdr_scan  # noqa: E402
from skeleton_core.cdr import CdrError, frames_from_cdr, frames_to_cdr  # noqa: E402
from skeleton_core.cdr_scan import scan_cdr  # noqa: E402
from skeleton_core.conversions import SkeletonFrame, frames_to_array_msg  # noqa: E402
from kinect_experiments.fuzz import MUTATIONS, valid_array  # noqa: E402


def _agree(data: bytes) -> bool:
    """scan_cdr reads ``data`` as frames_from_cdr does (False: both reject it)."""
    errors = []
    try:
        stamp, _, frames = frames_from_cdr(data, errors)
    except CdrError:
        with pytest.raises(CdrError):
            scan_cdr(data)
        return False
    scan = scan_cdr(data)
    assert scan.stamp_ns == stamp
    assert ([(u, s) for u, s, cause in scan.skeletons if cause is None]
            == [(f.user_id, f.stamp_ns) for f in frames])
    assert [cause for *_, cause in scan.skeletons if cause] == [e.cause for e in errors]
    return True


def _random_frames(rng, users):
    out = []
    for k, uid in enumerate(rng.choice(np.arange(1, 50), users, replace=False)):
        p = rng.normal(0, 1.0, (20, 3)) + [2.5, 0.0, 0.0]
        out.append(SkeletonFrame(
            positions=p, tracking_state=rng.integers(0, 3, 20).astype(np.uint8),
            reliability=(rng.random(20).astype(np.float32) if k % 3 else np.array([], np.float32)),
            orientations=rng.normal(size=(20, 4)) if k % 2 else None, user_id=int(uid),
            stamp_ns=1_700_000_000_000_000_000 + int(rng.integers(1 << 40)),
            frame_id='kinect_link' if k % 2 else ''))
    return out


@pytest.mark.parametrize('seed', range(12))
def test_random_valid_messages_read_as_frames_from_cdr_reads_them(seed, monkeypatch):
    rng = np.random.default_rng(seed)
    users = 1 + seed % 6
    frames = _random_frames(rng, users)
    nan_users = {f.user_id for f in frames if rng.random() < 0.4} if seed % 2 else set()
    for f in frames:
        if f.user_id in nan_users:
            f.positions[rng.integers(20), rng.integers(3)] = np.nan
    msg = frames_to_array_msg([f for f in frames if f.user_id not in nan_users], 77, 'k')
    # (frames_to_array_msg refuses a NaN skeleton: put it in the message by hand)
    for f in frames:
        if f.user_id in nan_users:
            sk = frames_to_array_msg([f.copy(positions=np.zeros((20, 3)))], 77, 'k').skeletons[0]
            for pt, xyz in zip(sk.positions, f.positions):
                pt.x, pt.y, pt.z = map(float, xyz)
            msg.skeletons.append(sk)
    data = serialize_message(msg)
    assert _agree(data)
    scan = scan_cdr(data)
    assert {u for u, _, cause in scan.skeletons if cause == 'non-finite position'} == nan_users
    assert len(scan.skeletons) == users
    if not nan_users:   # the usual message is read without decoding it skeleton by skeleton
        monkeypatch.setattr(cdr_scan, '_causes', lambda *a: pytest.fail('checked one by one'))
        assert scan_cdr(data) == scan


def test_our_own_bytes_and_six_users_take_the_light_path(monkeypatch):
    frames = _random_frames(np.random.default_rng(5), 6)
    data = frames_to_cdr(frames, 123, 'kinect_link')
    assert _agree(data)
    monkeypatch.setattr(cdr_scan, '_causes', lambda *a: pytest.fail('checked one by one'))
    scan = scan_cdr(data)
    assert scan.stamp_ns == 123
    assert [(u, s) for u, s, _ in scan.skeletons] == [(f.user_id, f.stamp_ns) for f in frames]
    assert all(cause is None for *_, cause in scan.skeletons)


@pytest.mark.parametrize('kind', sorted(MUTATIONS))
@pytest.mark.parametrize('users', [(1,), (1, 2, 3)])
def test_every_fuzz_mutation_reads_as_frames_from_cdr_reads_it(kind, users):
    msg = valid_array(5_000_000_123, users, rng=np.random.default_rng(len(kind)))
    MUTATIONS[kind](msg)
    data = serialize_message(msg)
    assert _agree(data)
    scan = scan_cdr(data)
    if kind == 'empty SkeletonArray':
        assert scan.skeletons == []
    elif kind != 'duplicate user ids':   # the first skeleton is the broken one
        assert scan.skeletons[0][2] is not None
        assert [cause for *_, cause in scan.skeletons[1:]] == [None] * (len(users) - 1)
    else:
        assert [cause for *_, cause in scan.skeletons][-1] == 'duplicate user id'


def test_truncated_and_corrupted_buffers_are_rejected_or_read_alike():
    rng = np.random.default_rng(11)
    data = serialize_message(frames_to_array_msg(_random_frames(rng, 3), 9, 'kinect_link'))
    read = 0
    for cut in range(0, len(data), 7):
        read += _agree(data[:cut])
    for _ in range(400):
        b = bytearray(data)
        for i in rng.integers(0, len(b), rng.integers(1, 4)):
            b[i] = rng.integers(256)
        read += _agree(bytes(b))
    assert read > 100   # most single-byte damage lands in values: read, not rejected
    with pytest.raises(CdrError):
        scan_cdr(b'\x01\x00\x00\x00' + data[4:])
