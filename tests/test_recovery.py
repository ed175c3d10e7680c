"""Crash-safe recording: a cut or unfinished MCAP is read up to its last complete message
with one warning line, recover() rewrites it into a complete bag, and a recorder process killed
with SIGKILL leaves a file holding all but the last flush period of what it received."""
from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest

pytest.importorskip('mcap_ros2')
from skeleton_core import bagio  # noqa: E402
from skeleton_core.bagio import (BagError, BagWriter, bag_topics, finished,  # noqa: E402
                                 read_messages, recover, truncation)

STRING = 'std_msgs/msg/String'


def _cdr_string(text: str) -> bytes:
    b = text.encode() + b'\0'
    return b'\x00\x01\x00\x00' + len(b).to_bytes(4, 'little') + b


def _write(path, n=240, chunk_size=1500, compression='zstd'):
    with BagWriter(path, chunk_size=chunk_size, flush_period_s=0, compression=compression) as bag:
        for k in range(n):
            bag.write_raw('/a' if k % 3 else '/b', _cdr_string(f'message {k:04d}'), 1000 + k, STRING)
    return path.read_bytes()


@pytest.mark.parametrize('compression', ['zstd', 'none'])
def test_a_bag_cut_at_any_byte_reads_its_complete_messages(tmp_path, compression):
    data = _write(tmp_path / 'full.mcap', compression=compression)
    assert truncation(tmp_path / 'full.mcap') is None
    cut = tmp_path / 'cut.mcap'
    previous = 0
    header_end = 8 + 9 + int.from_bytes(data[9:17], 'little')
    offsets = sorted(set(range(8, len(data), 37)) | {len(data) - 1, len(data) - 9})
    for at in offsets:
        cut.write_bytes(data[:at])
        if at < header_end:   # not even the header record: nothing to read, one clear error
            with pytest.raises(BagError, match='cut.mcap: corrupt or cut before its first'):
                list(read_messages(cut))
            continue
        warnings = []
        msgs = list(read_messages(cut, warn=warnings.append))
        t = truncation(cut)
        # what is read is a prefix of the recording in log-time order, nothing invented
        assert [m.stamp_ns for m in msgs] == list(range(1000, 1000 + len(msgs))), at
        assert [m.msg.data for m in msgs] == [f'message {k:04d}' for k in range(len(msgs))]
        assert len(msgs) == t.messages and t.offset <= at and len(msgs) >= previous
        previous = len(msgs)
        assert len(warnings) == 1 and warnings[0] == (
            f'cut.mcap is truncated at byte {t.offset}: read {t.messages} messages, the rest is '
            f'lost' + (f' ({at - t.offset} bytes)' if at > t.offset else ''))
        bagio._WARNED.clear()
    assert previous == 240   # a cut inside the summary section loses no message
    # a cut at the middle loses only the chunk being cut (1500-byte chunks: < 60 messages)
    cut.write_bytes(data[:len(data) // 2])
    assert truncation(cut).messages > 60


def test_recover_rewrites_a_cut_bag_into_a_complete_indexed_one(tmp_path):
    from mcap.reader import make_reader
    data = _write(tmp_path / 'full.mcap')
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:int(len(data) * 0.7)])
    n, t = recover(cut, tmp_path / 'fixed.mcap', warn=lambda s: None)
    assert t is not None and n == t.messages > 0
    fixed = tmp_path / 'fixed.mcap'
    assert truncation(fixed) is None and finished(fixed) and not finished(cut)
    with open(fixed, 'rb') as f:
        summary = make_reader(f).get_summary()
    assert summary.statistics.message_count == n and summary.chunk_indexes
    got = list(read_messages(fixed, warn=lambda s: pytest.fail(f'warned on a recovered bag: {s}')))
    want = list(read_messages(cut, warn=lambda s: None))
    assert [(m.topic, m.stamp_ns, m.data) for m in got] == [(m.topic, m.stamp_ns, m.data)
                                                            for m in want]
    assert sum(c for _, c in bag_topics(fixed).values()) == n
    with pytest.raises(BagError, match='another file'):
        recover(fixed, fixed)


def test_recover_bag_command(tmp_path):
    data = _write(tmp_path / 'full.mcap')
    (tmp_path / 'cut.mcap').write_bytes(data[:len(data) // 2])
    from kinect_bringup import recover_bag
    assert recover_bag.main([str(tmp_path / 'cut.mcap')]) == 0
    out = tmp_path / 'cut_recovered.mcap'
    assert truncation(out) is None and bag_topics(out)['/a'][1] > 0
    assert recover_bag.main([str(tmp_path / 'missing.mcap'), str(tmp_path / 'x.mcap')]) == 1


def test_an_open_writer_leaves_a_readable_file_every_flush_period(tmp_path):
    path = tmp_path / 'live.mcap'
    bag = BagWriter(path, flush_period_s=0.05)
    try:
        # the header is on disk at once: an empty recording is a bag with no message
        assert list(read_messages(path, warn=lambda s: None)) == []
        for k in range(5):
            bag.write_raw('/a', _cdr_string(f'{k}'), k, STRING)
        time.sleep(0.06)
        assert bag.poll()   # a timer's call: the pending messages go to the file
        assert [m.msg.data for m in read_messages(path, warn=lambda s: None)] == \
            ['0', '1', '2', '3', '4']
        bagio._WARNED.clear()
        bag.write_raw('/a', _cdr_string('5'), 5, STRING)
        assert not bag.poll()   # not due yet: still in memory
        assert len(list(read_messages(path, warn=lambda s: None))) == 5
    finally:
        bag.close()
    assert truncation(path) is None and len(list(read_messages(path))) == 6


def test_unreadable_files_still_name_the_file(tmp_path):
    p = tmp_path / 'garbage.mcap'
    p.write_bytes(b'PK\x03\x04 a zip archive')
    with pytest.raises(BagError, match='garbage.mcap: not an MCAP file'):
        list(read_messages(p))
    for start in (b'', b'\x89MCA'):   # a recorder's file before its header reached the disk
        p.write_bytes(start)
        with pytest.raises(BagError, match=f'garbage.mcap: it ends before its MCAP header '
                                           f'[(]{len(start)} bytes'):
            truncation(p)
    p.write_bytes(b'\x89MCAP0\r\ngarbage')
    with pytest.raises(BagError, match='garbage.mcap: corrupt or cut before its first record'):
        bag_topics(p)


@pytest.mark.ros
def test_a_recorder_killed_with_sigkill_keeps_what_it_received(tmp_path):
    """A real recorder process (synthetic driver -> recorder over DDS) killed with SIGKILL after
    10 s of recording: the bag gives back >= 95 % of the frames it received before the kill."""
    pytest.importorskip('rclpy')
    pytest.importorskip('skeleton_msgs.msg')
    from kinect_bringup.processes import Graph
    bag = tmp_path / 'killed.mcap'
    g = Graph('processes', nodes=['driver', 'recorder'], log_dir=tmp_path / 'logs',
              overrides={'recorder': {'output': str(bag), 'topics': ['/kinect/skeletons']},
                         'driver': {'num_users': 1}})
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            try:   # the file exists from the recorder's start, its header a moment later
                cut = truncation(bag) if bag.exists() else None
                if cut is not None and cut.messages > 0:
                    break
            except BagError:
                pass
            time.sleep(0.2)
        else:
            pytest.fail('the recorder wrote nothing in 90 s:\n'
                        + (tmp_path / 'logs' / 'recorder.log').read_text()[-2000:])
        time.sleep(10.0)
        killed_ns = time.time_ns()
        g.kill('recorder')
        assert g.procs['recorder'].returncode == -signal.SIGKILL
    finally:
        g.stop()
    warnings = []
    msgs = list(read_messages(bag, warn=warnings.append))
    assert len(warnings) == 1 and 'killed.mcap is truncated at byte' in warnings[0]
    # frames received before the kill: those in the file plus the ones since its last message
    # (the file's own receive rate), i.e. what a recorder that never lost anything would hold
    t = np.array([m.stamp_ns for m in msgs], dtype=np.int64)
    rate = (len(t) - 1) / ((t[-1] - t[0]) * 1e-9)
    lost = max(0.0, (killed_ns - t[-1]) * 1e-9 * rate)
    kept = len(t) / (len(t) + lost)
    print(f'SIGKILL after {(killed_ns - t[0]) * 1e-9:.1f} s of recording: {len(t)} frames kept, '
          f'~{lost:.1f} lost ({kept:.1%} kept)')
    assert (killed_ns - t[0]) * 1e-9 >= 9.5 and kept >= 0.95
    n, _ = recover(bag, tmp_path / 'fixed.mcap', warn=lambda s: None)
    assert n == len(msgs) and truncation(tmp_path / 'fixed.mcap') is None
    # a recorder started again on the same output (a respawn) keeps the killed one's bag
    g2 = Graph('processes', nodes=['recorder'], log_dir=tmp_path / 'logs2',
               overrides={'recorder': {'output': str(bag), 'topics': ['/kinect/skeletons']}})
    try:
        kept = []
        deadline = time.monotonic() + 60
        while not kept and time.monotonic() < deadline:
            kept = list(tmp_path.glob('killed.unfinished-*.mcap'))
            time.sleep(0.2)
    finally:
        g2.stop()
    assert len(kept) == 1 and truncation(kept[0]).messages == len(msgs)


def _skeleton_bag(path, n=150):
    pytest.importorskip('skeleton_msgs.msg')
    from skeleton_core.cdr import SKELETON_ARRAY, frames_to_cdr
    from skeleton_core.conversions import SkeletonFrame
    from skeleton_core.model import standard_body
    body = standard_body().rest_positions() + [2.5, 0.0, -0.8]
    with BagWriter(path, chunk_size=8000, flush_period_s=0) as bag:
        for k in range(n):
            stamp = 1_700_000_000_000_000_000 + k * 33_333_333
            f = SkeletonFrame(positions=body + 0.01 * np.sin(k), user_id=1, stamp_ns=stamp,
                              tracking_state=np.full(20, 2, np.uint8), frame_id='kinect_link')
            data = frames_to_cdr([f], stamp, 'kinect_link')
            bag.write_raw('/kinect/skeletons', data, stamp, SKELETON_ARRAY)
            bag.write_raw('/kinect/ground_truth', data, stamp, SKELETON_ARRAY)
    return path.read_bytes()


def test_replay_source_and_process_bag_read_a_cut_bag(tmp_path):
    """The replay source and process_bag take a cut recording: every complete frame, one
    warning, instead of refusing the file."""
    from kinect_driver.sources.replay import ReplaySource
    data = _skeleton_bag(tmp_path / 'full.mcap')
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:int(len(data) * 0.6)])
    complete = sum(1 for m in read_messages(cut, warn=lambda s: None)
                   if m.topic == '/kinect/skeletons')
    assert 0 < complete < 150
    warned = []
    src = ReplaySource(str(cut), warn=warned.append)
    src.open()
    out, now = [], 0
    while not src.finished:
        out += src.poll(now)
        now += 10 ** 8
    assert sum(1 for o in out if not o.topic) == complete == src.count
    assert {o.topic for o in out if o.topic} == {'/kinect/ground_truth'}
    assert len(warned) == 1 and 'cut.mcap is truncated at byte' in warned[0]
    from kinect_bringup.process_bag import process
    s = process(cut, tmp_path / 'out.mcap', 'A', progress=False)
    assert s['frames'] == complete and s['accuracy']['A']['frames'] == complete


def test_fsync_runs_beside_the_writer_and_stops_on_close(tmp_path, monkeypatch):
    synced = []
    real = os.fsync
    monkeypatch.setattr(os, 'fsync', lambda fd: (synced.append(fd), real(fd)))
    bag = BagWriter(tmp_path / 's.mcap', flush_period_s=0.01, fsync=True)
    for k in range(3):
        bag.write_raw('/a', _cdr_string(str(k)), k, STRING)
        time.sleep(0.02)
        bag.poll()
    thread = bag._sync_thread
    bag.close()
    assert synced and not thread.is_alive()
    assert len(list(read_messages(tmp_path / 's.mcap'))) == 3
