"""Recordings that rotate: a recording split by duration or size into pieces, each a
complete bag; replay and recover_bag take the folder (or the list of pieces) as one recording,
a cut last piece included. The split decisions come from the messages' log times, so a
30-minute recording is written in seconds."""
import numpy as np
import pytest
from rclpy.serialization import serialize_message

from skeleton_core.bag_split import (SplitBagWriter, SplitPolicy, bag_pieces, pieces_topics,
                                     read_pieces)
from skeleton_core.bagio import BagError, truncation

from kinect_experiments.fuzz import valid_array
from kinect_bringup.recover_bag import main as recover_main
from kinect_driver.sources.replay import ReplaySource

T0 = 1_700_000_000 * 10 ** 9
HZ = 10


def _frame(k):
    return serialize_message(valid_array(T0 + k * 10 ** 9 // HZ, (1,)))


def _record(path, seconds, **split):
    """``seconds`` of a 10 Hz recording (stamps = log times), pieces as the writer split them."""
    data = [_frame(k) for k in range(16)]
    with SplitBagWriter(path, flush_period_s=0, **split) as w:
        for k in range(int(seconds * HZ)):
            # header stamps differ every 16 frames only; the log times are what counts here
            w.write_raw('/kinect/skeletons', data[k % 16], T0 + k * 10 ** 9 // HZ)
    return w


def _replay(source, warn=None):
    src = ReplaySource(source, rate=20.0, warn=warn)
    src.open()
    played, now = [], 0
    while not src.finished and now < 10 ** 13:
        played += [o for o in src.poll(now) if not o.topic]
        now += 10 ** 7
    return src, played


def test_policy():
    p = SplitPolicy(split_duration_s=300)
    assert p.enabled and not SplitPolicy().enabled
    assert not p.full(0, 0, None, T0)                      # an empty piece is never full
    assert not p.full(5, 10 ** 9, T0, T0 + 299 * 10 ** 9)
    assert p.full(5, 0, T0, T0 + 300 * 10 ** 9)
    q = SplitPolicy(split_size_bytes=1000)
    assert q.full(1, 1000, T0, T0) and not q.full(1, 999, T0, T0)
    with pytest.raises(BagError):
        SplitPolicy(-1)


def test_thirty_minutes_split_every_five_minutes_is_six_pieces_replayed_as_one(tmp_path):
    w = _record(tmp_path / 'day.mcap', 30 * 60, split_duration_s=300)
    folder = tmp_path / 'day'
    pieces = bag_pieces(folder)
    assert pieces == w.pieces and [p.name for p in pieces] == [f'day_{i}.mcap' for i in range(6)]
    n = 30 * 60 * HZ
    for i, p in enumerate(pieces):
        assert truncation(p) is None, f'{p.name} is not a complete bag'
        stamps = [m.stamp_ns for m in read_pieces([p], decode=False)]
        assert len(stamps) == n // 6
        # each piece is exactly its 5 minutes of the recording
        assert stamps[0] == T0 + i * 300 * 10 ** 9 and stamps[-1] - stamps[0] < 300 * 10 ** 9
    assert pieces_topics(pieces)['/kinect/skeletons'][1] == n
    # the folder and the list of pieces replay as one recording: every frame once, in order
    warnings = []
    src, played = _replay(str(folder), warn=warnings.append)
    assert len(played) == n == src.count and not warnings
    raw = [m.data for m in read_pieces(pieces, decode=False)]
    assert [o.raw for o in played] == raw
    _, played2 = _replay(','.join(str(p) for p in pieces))
    assert [o.raw for o in played2] == raw
    # one lap of the replay is the whole recording (a loop starts after its last frame)
    assert src._lap_ns == n * 10 ** 9 // HZ


def test_split_by_size(tmp_path):
    w = _record(tmp_path / 'big.mcap', 600, split_size_bytes=1_000_000, chunk_size=32_768,
                compression='none')
    sizes = [p.stat().st_size for p in w.pieces]
    assert len(w.pieces) >= 3, sizes
    # every piece but the last reached the size, by at most about one chunk
    assert all(1_000_000 <= s < 1_000_000 + 2 * 32_768 for s in sizes[:-1]), sizes
    assert sum(1 for _ in read_pieces(w.pieces, decode=False)) == 600 * HZ


def test_no_limit_writes_one_file(tmp_path):
    w = _record(tmp_path / 'one.mcap', 10)
    assert w.pieces == [tmp_path / 'one.mcap'] and truncation(tmp_path / 'one.mcap') is None


def test_cut_last_piece_is_replayed_and_recovered(tmp_path, capsys):
    _record(tmp_path / 'cut.mcap', 600, split_duration_s=120)
    folder = tmp_path / 'cut'
    pieces = bag_pieces(folder)
    assert len(pieces) == 5
    last = pieces[-1]
    data = last.read_bytes()
    last.write_bytes(data[:int(len(data) * 0.6)])   # the recorder died while writing it
    complete = sum(1 for _ in read_pieces(pieces, decode=False, warn=lambda s: None))
    assert 4 * 120 * HZ < complete < 600 * HZ
    warnings = []
    _, played = _replay(str(folder), warn=warnings.append)
    assert len(played) == complete and len(warnings) == 1 and 'truncated' in warnings[0]
    assert recover_main([str(folder)]) == 0
    fixed = bag_pieces(tmp_path / 'cut_recovered')
    assert [p.name for p in fixed] == [p.name for p in pieces]
    assert all(truncation(p) is None for p in fixed)
    assert pieces_topics(fixed)['/kinect/skeletons'][1] == complete
    assert 'truncated at byte' in capsys.readouterr().out


def test_bad_sources(tmp_path):
    (tmp_path / 'empty').mkdir()
    with pytest.raises(BagError, match='no .mcap'):
        bag_pieces(tmp_path / 'empty')
    with pytest.raises(BagError, match='no such file'):
        bag_pieces([tmp_path / 'a.mcap', tmp_path / 'b.mcap'])
    assert np.all(np.diff([int(p.stem.split('_')[1]) for p in
                           _record(tmp_path / 'n.mcap', 130, split_duration_s=10).pieces]) == 1)


@pytest.mark.ros
def test_recorder_node_rotates_and_process_bag_takes_the_folder(tmp_path):
    """A real recorder (synthetic driver -> recorder over DDS) with split_duration_s 2: complete
    pieces of 2 s each, closed on Ctrl-C too; process_bag runs over the folder as one bag."""
    import time
    from kinect_bringup.process_bag import process
    from kinect_bringup.processes import Graph
    folder = tmp_path / 'rot'
    g = Graph('processes', nodes=['driver', 'recorder'], log_dir=tmp_path / 'logs',
              overrides={'recorder': {'output': str(tmp_path / 'rot.mcap'),
                                      'topics': ['/kinect/skeletons'], 'split_duration_s': 2.0},
                         'driver': {'num_users': 1}})
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and len(list(folder.glob('*.mcap'))) < 4:
            time.sleep(0.2)
    finally:
        codes = g.stop()
    log = (tmp_path / 'logs' / 'recorder.log').read_text()
    assert codes['recorder'] == 0, log[-2000:]
    pieces = bag_pieces(folder)
    assert len(pieces) >= 4, log[-2000:]
    assert all(truncation(p) is None for p in pieces), 'a piece was left unfinished'
    firsts = []
    for p in pieces:
        t = [m.stamp_ns for m in read_pieces([p], decode=False)]
        assert t and t[-1] - t[0] < 2 * 10 ** 9
        firsts.append(t[0])
    assert all(b - a >= 2 * 10 ** 9 for a, b in zip(firsts, firsts[1:]))
    assert 'finished piece rot_0.mcap' in log
    total = pieces_topics(pieces)['/kinect/skeletons'][1]
    s = process(folder, tmp_path / 'out.mcap', 'A', progress=False)
    assert s['frames'] == total
