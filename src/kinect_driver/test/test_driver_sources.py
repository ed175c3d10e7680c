"""kinect_driver sources without ROS: NiTE mapping, CSV format, replay timing, synthetic users,
and the live source's errors against the real OpenNI2 library."""
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from kinect_driver.csv_format import CsvFormatError, read_csv, write_csv
from kinect_driver.sources.base import SourceError
from kinect_driver.sources.openni_live import (camera_mm_to_rep103, confidence_to_state,
                                               find_openni2_library, nite_to_frame)
from kinect_driver.sources.replay import ReplaySource
from kinect_driver.sources.synthetic import SyntheticSource
from kinect_driver.tf_names import tf_frames
from skeleton_core.conversions import SkeletonFrame, validate_arrays
from skeleton_core import model
from skeleton_core.model import (FOOT_LEFT, HAND_RIGHT, HEAD, HIP_CENTER, INFERRED,
                                 NITE_TO_KINECT, NOT_TRACKED, TRACKED, standard_body)


# ---------------------------------------------------------------------------------- NiTE mapping
def _nite_points_from_body(rest):
    """A standing user 2 m in front of the camera, as NiTE would report it (camera mm)."""
    # body in REP-103 sensor frame: rest pose facing the sensor (rotate 180 deg about z), 2 m away
    body = rest * np.array([-1.0, -1.0, 1.0]) + np.array([2.0, 0.0, -0.9])
    nite = body[list(NITE_TO_KINECT)]
    # REP-103 (x fwd, y left, z up) -> camera (x right, y up, z fwd), mm
    return np.stack([-nite[:, 1], nite[:, 2], nite[:, 0]], axis=1) * 1000.0, body


def test_camera_axes_to_rep103():
    # 1 m to the camera's right, 0.5 m up, 3 m ahead
    assert np.allclose(camera_mm_to_rep103([1000.0, 500.0, 3000.0]), [3.0, -1.0, 0.5])


def test_confidence_thresholds():
    st = confidence_to_state([0.0, 0.2, 0.5, 1.0])
    assert st.tolist() == [NOT_TRACKED, INFERRED, TRACKED, TRACKED]
    assert confidence_to_state([0.5, 0.8], tracked=0.9, inferred=0.5).tolist() == [NOT_TRACKED,
                                                                                   INFERRED]


def test_nite_to_frame_maps_joints_and_fills_missing_plausibly():
    rest = standard_body().rest_positions()
    pts, body = _nite_points_from_body(rest)
    conf = np.ones(15)
    conf[0] = 0.0   # head lost
    conf[6] = 0.5   # left "hand" (wrist) at 0.5 -> TRACKED
    f = nite_to_frame(pts, conf, user_id=4, stamp_ns=99, frame_id='kinect_link')
    validate_arrays(f.positions, f.tracking_state)
    assert f.user_id == 4 and f.stamp_ns == 99 and f.frame_id == 'kinect_link'
    for k, j in enumerate(NITE_TO_KINECT):
        assert np.allclose(f.positions[j], body[j]), model.JOINT_NAMES[j]
    assert f.tracking_state[HEAD] == NOT_TRACKED
    assert f.tracking_state[NITE_TO_KINECT[6]] == TRACKED
    # missing joints: HipCenter between the hips, INFERRED; hands/feet NOT_TRACKED at the
    # standard-body offsets (the test body IS the standard body, so they land on its joints)
    assert f.tracking_state[HIP_CENTER] == INFERRED
    assert np.allclose(f.positions[HIP_CENTER], body[HIP_CENTER], atol=1e-9)
    for j in model.NITE_MISSING:
        if j != HIP_CENTER:
            assert f.tracking_state[j] == NOT_TRACKED
            assert np.allclose(f.positions[j], body[j], atol=1e-6), model.JOINT_NAMES[j]
    names = [n for n, _ in tf_frames(f)]
    assert 'neck_4' in names and 'torso_4' in names and 'head_4' not in names
    assert len(names) == 14


def test_nite_to_frame_degenerate_input_stays_valid():
    f = nite_to_frame(np.zeros((15, 3)), np.zeros(15), 1, 0, 'k')
    validate_arrays(f.positions, f.tracking_state)
    assert (f.tracking_state == NOT_TRACKED).all()
    assert np.allclose(f.positions[[HAND_RIGHT, FOOT_LEFT]], 0.0)


# ---------------------------------------------------------------------------------- live errors
_LIVE = textwrap.dedent('''
    import sys
    from kinect_driver.sources.openni_live import LiveSource
    from kinect_driver.sources.base import SourceError
    kw = eval(sys.argv[1])
    try:
        LiveSource(**kw).open()
    except SourceError as e:
        print(e)
        sys.exit(3)
    print('opened')
''')


def _live(**kw):
    # a fresh process each time: the OpenNI2 library is initialized once per process
    r = subprocess.run([sys.executable, '-c', _LIVE, repr(kw)], capture_output=True, text=True,
                       timeout=60)
    return r.returncode, r.stdout.strip(), r.stderr


needs_openni = pytest.mark.skipif(
    find_openni2_library() is None,
    reason='libopenni2-0 not installed (scripts/setup.sh installs it when run as root)')


@needs_openni
def test_live_without_sensor_reports_no_device():
    pytest.importorskip('openni', reason='openni bindings not installed (requirements-py.txt)')
    rc, out, err = _live(nite2_path='/opt/NiTE2/Redist')
    assert rc == 3, (out, err)
    assert out.startswith('no device:') and '\n' not in out


@needs_openni
def test_live_names_missing_nite2_path():
    pytest.importorskip('openni')
    # OpenNI2's built-in dummy device stands in for a sensor, so the NiTE2 step is reached
    rc, out, err = _live(device_uri='Dummy', nite2_path='/nowhere/NiTE-2.2/Redist')
    assert rc == 3, (out, err)
    assert '/nowhere/NiTE-2.2/Redist' in out and 'NiTE2 not found' in out
    rc, out, _ = _live(device_uri='Dummy', nite2_path='')
    assert rc == 3 and 'nite2_path' in out


def test_live_missing_openni2_library_and_recording():
    pytest.importorskip('openni')
    rc, out, _ = _live(openni2_path='/nowhere/openni2', nite2_path='/x')
    assert rc == 3 and out == ('OpenNI2 library not found in /nowhere/openni2 '
                               '(install it: sudo apt-get install libopenni2-0)')
    if find_openni2_library() is not None:
        rc, out, _ = _live(device_uri='/nowhere/take1.oni', nite2_path='/x')
        assert rc == 3 and 'cannot read OpenNI recording /nowhere/take1.oni' in out


# ---------------------------------------------------------------------------------- CSV
def _frames(stamp, users=(1, 2)):
    rng = np.random.default_rng(stamp)
    return [SkeletonFrame(positions=standard_body().rest_positions() + rng.normal(0, .1, (20, 3)),
                          tracking_state=rng.integers(0, 3, 20).astype(np.uint8), user_id=u,
                          stamp_ns=stamp) for u in users]


def test_csv_round_trip(tmp_path):
    data = [(1000 + k * 33_333_333, _frames(k)) for k in range(4)]
    assert write_csv(tmp_path / 's.csv', data) == 8
    back = read_csv(tmp_path / 's.csv', frame_id='kinect_link')
    assert [s for s, _ in back] == [s for s, _ in data]
    for (_, a), (_, b) in zip(data, back):
        for fa, fb in zip(a, b):
            assert fa.user_id == fb.user_id and fb.frame_id == 'kinect_link'
            assert np.allclose(fa.positions, fb.positions, atol=1e-6)
            assert np.array_equal(fa.tracking_state, fb.tracking_state)


def test_csv_minimal_columns_and_errors(tmp_path):
    rows = ['# a comment', 'stamp_ns,user_id,joint,x,y,z']
    rows += [f'5,1,{j},{j * 0.1},0,1' for j in range(20)]
    (tmp_path / 'ok.csv').write_text('\n'.join(rows) + '\n')
    (stamp, [f]), = read_csv(tmp_path / 'ok.csv')
    assert stamp == 5 and (f.tracking_state == TRACKED).all() and f.positions[3, 0] == 3 * 0.1
    (tmp_path / 'short.csv').write_text('\n'.join(rows[:-1]) + '\n')
    with pytest.raises(CsvFormatError, match=r'short.csv:3: stamp 5 user 1 lacks joints \[.FootRight.\]'):
        read_csv(tmp_path / 'short.csv')
    (tmp_path / 'bad.csv').write_text('\n'.join(rows[:5] + ['5,1,Nose,0,0,0']) + '\n')
    with pytest.raises(CsvFormatError, match="bad.csv:6: unknown joint 'Nose'"):
        read_csv(tmp_path / 'bad.csv')
    (tmp_path / 'hdr.csv').write_text('t,u,j\n')
    with pytest.raises(CsvFormatError, match='hdr.csv:1: header lacks'):
        read_csv(tmp_path / 'hdr.csv')


# ---------------------------------------------------------------------------------- replay
def test_replay_csv_timing_rate_and_loop(tmp_path):
    period = 33_333_333
    write_csv(tmp_path / 'r.csv', [(k * period, _frames(k, (3,))) for k in range(10)])
    src = ReplaySource(str(tmp_path / 'r.csv'), rate=2.0, loop=True)
    src.open()
    assert src.period_s == pytest.approx(period / 2e9)
    t0 = 10 ** 12
    got = []
    for tick in range(25):  # 25 ticks at the source period = 2.5 laps at rate 2
        got += [o.stamp_ns for o in src.poll(t0 + int(tick * period / 2))]
    assert got[:10] == [k * period for k in range(10)]
    assert got[10:20] == got[:10] and len(got) == 25  # one per tick, looping
    once = ReplaySource(str(tmp_path / 'r.csv'))
    once.open()
    n = sum(len(once.poll(t0 + tick * period)) for tick in range(30))
    assert n == 10 and once.finished


def test_replay_errors_are_one_line(tmp_path):
    (tmp_path / 'junk.mcap').write_bytes(b'not a bag at all')
    for path, text in ((tmp_path / 'junk.mcap', 'junk.mcap: not an MCAP file'),
                       (tmp_path / 'none.mcap', 'none.mcap: no such file'),
                       (tmp_path / 'x.db3', 'x.db3')):
        if path.suffix == '.db3':
            path.write_bytes(b'SQLite format 3\x00')
        with pytest.raises(SourceError, match=text) as e:
            ReplaySource(str(path)).open()
        assert '\n' not in str(e.value)
    with pytest.raises(SourceError, match='replay_file'):
        ReplaySource('').open()


# ---------------------------------------------------------------------------------- synthetic
def test_synthetic_users_side_by_side_with_truth():
    src = SyntheticSource(scenario='a', seed=3, num_users=4)
    src.open()
    period = 33_333_333
    outs = [src.poll(10 ** 12 + k * period)[0] for k in range(30)]
    o = outs[-1]
    assert [f.user_id for f in o.frames] == [1, 2, 3, 4] == [f.user_id for f in o.truth]
    for f in o.frames + o.truth:
        validate_arrays(f.positions, f.tracking_state)
        assert f.frame_id == 'kinect_link' and f.stamp_ns == o.stamp_ns
    lateral = [np.mean([out.truth[k].positions[HIP_CENTER, 1] for out in outs]) for k in range(4)]
    assert np.all(np.diff(lateral) > 0.5)   # users spread along y, ~0.8 m apart
    with pytest.raises(SourceError, match='num_users'):
        SyntheticSource(num_users=7)


def test_synthetic_source_declares_the_tracker_of_its_sensor_model():
    """The Kinect model declares ``sensor_model``; the Azure Kinect body tracking's variant
    declares ``azure_kinect_bt`` and, like that tracker's ROS message, has no joint states."""
    from pathlib import Path
    root = Path(__file__).resolve().parents[3]
    kin = SyntheticSource(scenario='b', seed=4)
    kin.open()
    az = SyntheticSource(scenario='b', seed=4,
                         sensor_params=str(root / 'config' / 'sensor_model_azure_kinect_bt.yaml'))
    az.open()
    assert (kin.tracker, az.tracker) == ('sensor_model', 'azure_kinect_bt')
    states = {name: np.array([src.poll(10 ** 12 + k * 33_333_333)[0].frames[0].tracking_state
                              for k in range(300)]) for name, src in (('kin', kin), ('az', az))}
    assert (states['az'] == TRACKED).all() and (states['kin'] != TRACKED).any()


def test_synthetic_is_reproducible_per_seed():
    a, b, c = (SyntheticSource(seed=s, num_users=2) for s in (5, 5, 6))
    for s in (a, b, c):
        s.open()
    pa, pb, pc = ([s.poll(k * 10 ** 8)[0].frames[1].positions for k in range(5)][-1]
                  for s in (a, b, c))
    assert np.array_equal(pa, pb) and not np.array_equal(pa, pc)


def test_synthetic_frames_prepared_ahead_are_the_same_frames():
    """prepare() (called by the node after publishing) simulates the next frame early: the
    stream and its stamps are unchanged, whether or not it was called."""
    a, b = (SyntheticSource(seed=2, num_users=2) for _ in range(2))
    for s in (a, b):
        s.open()
    period = 33_333_333
    for k in range(40):
        oa, ob = a.poll(k * period), b.poll(k * period)
        assert [o.stamp_ns for o in oa] == [o.stamp_ns for o in ob] == [k * period]
        for fa, fb in zip(oa[0].frames + oa[0].truth, ob[0].frames + ob[0].truth):
            assert np.array_equal(fa.positions, fb.positions)
            assert np.array_equal(fa.tracking_state, fb.tracking_state)
        if k % 3:  # b prepares ahead most of the time, not always
            b.prepare()
            b.prepare()  # idempotent until the prepared frame is taken
    b.open()   # reopening starts the stream again without a stale prepared frame
    b.prepare()
    c = SyntheticSource(seed=2, num_users=2)
    c.open()
    assert np.array_equal(b.poll(40 * period)[0].frames[0].positions,
                          c.poll(0)[0].frames[0].positions)


def test_synthetic_schedule_is_drift_free_and_catches_up():
    src = SyntheticSource(num_users=1, rate_hz=30.0)
    src.open()
    p = 33_333_333
    t0 = 5 * 10 ** 12
    stamps = []
    # jittery polls: one frame each, stamps on the fixed grid, never after the poll time
    for k, jitter in enumerate([0, 9e6, 2e6, 15e6, 0, 11e6]):
        now = t0 + k * p + int(jitter)
        out = src.poll(now)
        assert len(out) == 1 and out[0].stamp_ns <= now
        stamps.append(out[0].stamp_ns)
    assert np.all(np.diff(stamps) == p)
    # a poll 5 periods late returns the 5 overdue frames, still on the grid
    late = src.poll(t0 + 10 * p)
    assert [o.stamp_ns for o in late] == [stamps[-1] + i * p for i in range(1, 6)]
    # far behind: the backlog is skipped, not replayed
    assert len(src.poll(t0 + 1000 * p)) == 1 and src.skipped > 900


def test_synthetic_schedule_follows_the_timer_when_the_first_poll_was_late():
    """A late first poll must not make every later frame wait a period (or be stamped before it
    leaves): the schedule moves back onto the timer's grid, one frame per poll."""
    src = SyntheticSource(num_users=1, rate_hz=30.0)
    src.open()
    p = 33_333_333
    t0 = 7 * 10 ** 12
    polls = [t0 + 12_000_000] + [t0 + k * p + 300_000 for k in range(1, 8)]
    outs = [src.poll(now) for now in polls]
    assert [len(o) for o in outs] == [1] * len(polls)
    stamps = [o[0].stamp_ns for o in outs]
    assert all(s <= now for s, now in zip(stamps, polls))
    # after the re-anchoring the frames are stamped when they leave, on a drift-free grid
    assert [now - s for s, now in zip(stamps[1:], polls[1:])] == [0] * (len(polls) - 1)
    assert np.all(np.diff(stamps[1:]) == p)


def test_live_reader_survives_unplug_and_reconnects():
    """The reader thread's recovery logic, with the device I/O replaced by a fake."""
    import threading
    import time
    from kinect_driver.sources.base import SourceOutput
    from kinect_driver.sources.openni_live import LiveSource

    class FakeLive(LiveSource):
        def __init__(self):
            super().__init__(retry_s=0.05, log=self.logs.append)
            self.connects = 0
            self.reads = 0
            self.done = threading.Event()

        logs = []

        def connect(self):
            self.connects += 1
            if self.connects == 2:   # first reconnection attempt: still unplugged
                from kinect_driver.sources.base import SourceError
                raise SourceError('no device: no OpenNI2 depth sensor connected', retryable=True)
            self.connected = True

        def disconnect(self):
            self.connected = False

        def read_once(self):
            self.reads += 1
            if self.reads == 3:
                raise RuntimeError('USB transfer failed')
            if self.reads >= 8:   # enough: idle until closed (the queue keeps the last 10)
                self.done.set()
                self._stop.wait(1.0)
                return []
            time.sleep(0.005)
            self._queue.append(SourceOutput(stamp_ns=self.reads))
            return []

    src = FakeLive()
    src.open()
    assert src.done.wait(5.0)
    src.close()
    assert src.connects == 3 and src.reconnects == 1
    assert any('device disconnected' in m and 'USB transfer failed' in m for m in src.logs)
    assert any(m.startswith('no device') and 'retrying' in m for m in src.logs)
    assert 'device reconnected' in src.logs
    assert [o.stamp_ns for o in src.poll(0)][:2] == [1, 2]


def test_live_read_once_with_nite_structures():
    """read_once on real NiTE2 binding structures (the tracker itself is faked: no NiTE here)."""
    nite = pytest.importorskip('openni.nite2', reason='openni bindings not installed')
    from openni import _nite2 as c_api
    from kinect_driver.sources.openni_live import LiveSource

    pts, body = _nite_points_from_body(standard_body().rest_positions())

    def user(uid, state, skeleton_state):
        ud = c_api.NiteUserData()
        ud.id = uid
        ud.state = state
        ud.skeleton.state = skeleton_state
        for k in range(15):
            j = ud.skeleton.joints[k]
            j.position.x, j.position.y, j.position.z = pts[k]
            j.positionConfidence = 1.0 if k else 0.0
        return nite.UserData(ud)

    class Frame:
        def __init__(self, users):
            self.users = users

        def close(self):
            pass

    class Tracker:
        started = []

        def read_frame(self):
            return Frame([
                user(1, c_api.NiteUserState.NITE_USER_STATE_NEW,
                     c_api.NiteSkeletonState.NITE_SKELETON_NONE),
                user(2, c_api.NiteUserState.NITE_USER_STATE_VISIBLE,
                     c_api.NiteSkeletonState.NITE_SKELETON_TRACKED),
                user(5, c_api.NiteUserState.NITE_USER_STATE_VISIBLE,
                     c_api.NiteSkeletonState.NITE_SKELETON_TRACKED)])

        def start_skeleton_tracking(self, uid):
            self.started.append(int(uid))

    src = LiveSource(max_users=1, frame_id='cam', clock_ns=lambda: 42)
    src._tracker = Tracker()
    frames = src.read_once()
    assert Tracker.started == [1]                     # a new user gets skeleton tracking
    assert [f.user_id for f in frames] == [2]         # tracked users only, at most max_users
    f = frames[0]
    assert f.stamp_ns == 42 and f.frame_id == 'cam'
    for j in NITE_TO_KINECT[1:]:
        assert np.allclose(f.positions[j], body[j], atol=1e-6)
    assert f.tracking_state[HEAD] == NOT_TRACKED and f.tracking_state[NITE_TO_KINECT[1]] == TRACKED
    out, = src.poll(0)
    assert out.frames == frames and out.stamp_ns == 42
