"""The driver node over real DDS: synthetic and replay sources publish well-formed skeletons at
30 +- 1 Hz for several users, a replayed bag reproduces the recorded bytes, and start-up errors are
one clear line with exit code 1."""
import os
import subprocess
import sys
import time

import numpy as np
import pytest

import domains  # noqa: E402  (tests/domains.py)

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from skeleton_msgs.msg import SkeletonArray  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402  (make setup builds tf2_msgs with the launch tooling)

from skeleton_core.bagio import BagWriter, read_messages  # noqa: E402
from skeleton_core.conversions import (SkeletonFrame, frames_from_array_msg,  # noqa: E402
                                       frames_to_array_msg, stamp_to_ns)
from skeleton_core.model import standard_body  # noqa: E402

from kinect_driver.sources.openni_live import find_openni2_library  # noqa: E402

NODE = [sys.executable, '-m', 'kinect_driver.driver_node']
# A domain of our own: scripts/env.sh exports ROS_DOMAIN_ID=42, so concurrent test runs of other
# shells would otherwise share one domain with us.
DOMAIN = domains.claim(60 + os.getpid() % 40)   # claimed: tests/domains.py


def _env():
    return dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN))


@pytest.fixture
def dds():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def _start(*params):
    args = NODE + ['--ros-args'] + [a for p in params for a in ('-p', p)]
    return subprocess.Popen(args, env=_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def _stop(proc):
    proc.terminate()
    try:
        out, _ = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return out


def _collect(ctx, topic, count, raw=False, proc=None, extra=None, seconds=30.0):
    """Receive ``count`` messages (at most ``seconds`` after the first one: a count, not a rate,
    so that a loaded machine only makes it slower); returns [(monotonic time, msg)].
    ``extra``: {topic: (type, list)} of further subscriptions filled with messages."""
    node = rclpy.create_node('driver_probe', context=ctx)
    got = []
    node.create_subscription(SkeletonArray, topic, lambda m: got.append((time.monotonic(), m)),
                             100, raw=raw)
    for t, (cls, sink) in (extra or {}).items():
        node.create_subscription(cls, t, sink.append, 100)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        deadline = time.monotonic() + 25
        while not got and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
            if proc is not None and proc.poll() is not None:
                break
        end = time.monotonic() + seconds
        while got and len(got) < count and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.02)
    finally:
        ex.shutdown()
        node.destroy_node()
    return got


def _rate(times, warmup=0.5):
    """Receive rate after a warm-up (a node that just started may deliver a short catch-up burst)."""
    times = [t for t in times if t >= times[0] + warmup]
    return (len(times) - 1) / (times[-1] - times[0])


def test_synthetic_three_users_at_30hz(dds):
    proc = _start('num_users:=3', 'scenario:=b', 'publish_tf:=true')
    truth, tf = [], []
    try:
        got = _collect(dds, '/kinect/skeletons', 90, proc=proc,
                       extra={'/kinect/ground_truth': (SkeletonArray, truth), '/tf': (TFMessage, tf)})
    finally:
        out = _stop(proc)
    assert len(got) > 60, out
    stamps = [stamp_to_ns(m.header.stamp) for _, m in got]
    assert np.all(np.diff(stamps) > 0)
    # capture stamps carry the drift-free timer schedule; receive times include transport jitter
    rate_stamps = (len(stamps) - 1) / ((stamps[-1] - stamps[0]) / 1e9)
    rate_recv = _rate([t for t, _ in got])
    print(f'synthetic 3 users: {rate_stamps:.2f} Hz by stamps, {rate_recv:.2f} Hz received '
          f'({len(got)} msgs; rates are benchmark figures, not asserted here)')
    # the schedule, not the machine's speed (a loaded machine may skip a tick): every stamp on
    # the 30 Hz grid, most of them one period apart -- but for a move back to the timer's grid
    # (0.5-1 period) when a late poll had anchored the schedule late (synthetic.py: a loaded
    # machine; a CI run saw one step of 0.79 period), at most twice
    periods = np.diff(stamps) / (1e9 / 30)
    on_grid = np.isclose(periods, np.round(periods), atol=0.1)
    moved_back = (periods > 0.5) & (periods < 1.0)
    assert np.all(on_grid | moved_back) and np.count_nonzero(~on_grid) <= 2, periods
    assert np.median(periods) == pytest.approx(1.0, abs=0.05)
    for _, m in got:
        errors = []
        frames = frames_from_array_msg(m, errors)
        assert not errors and [f.user_id for f in frames] == [1, 2, 3]
        assert m.header.frame_id == 'kinect_link'
        assert all(f.stamp_ns == stamp_to_ns(m.header.stamp) for f in frames)
    # ground truth: same users and stamps as the published skeletons, all joints TRACKED
    by_stamp = {stamp_to_ns(m.header.stamp): m for _, m in got}
    matched = [m for m in truth if stamp_to_ns(m.header.stamp) in by_stamp]
    assert len(matched) > 30
    for m in matched:
        frames = frames_from_array_msg(m)
        assert [f.user_id for f in frames] == [1, 2, 3]
        assert all((f.tracking_state == 2).all() for f in frames)
    # TF: openni2_tracker-style frames, child of the sensor frame, at the joint positions
    assert tf
    names = {t.child_frame_id for m in tf for t in m.transforms}
    assert {'torso_1', 'neck_2', 'left_knee_3'} <= names
    last = {t.child_frame_id: t for m in tf for t in m.transforms}
    assert last['torso_1'].header.frame_id == 'kinect_link'
    assert 1.0 < last['torso_1'].transform.translation.x < 5.0  # in front of the sensor


def _record_bag(path, n=90, users=(2, 5)):
    t0 = 1_700_000_000_000_000_000
    body = standard_body().rest_positions()
    with BagWriter(path) as bag:
        for k in range(n):
            stamp = t0 + k * 33_333_333
            frames = [SkeletonFrame(positions=body + [2.5, 0.8 * u, -0.8] + 0.01 * np.sin(k + u),
                                    tracking_state=np.full(20, 2, np.uint8),
                                    reliability=np.linspace(0, 1, 20).astype(np.float32),
                                    user_id=u, stamp_ns=stamp, frame_id='kinect_link')
                      for u in users]
            bag.write('/kinect/skeletons', frames_to_array_msg(frames, stamp, 'kinect_link'),
                      stamp + 2_000_000)
    return [m.data for m in read_messages(path)]


def test_replayed_bag_reproduces_recorded_bytes_at_30hz(dds, tmp_path):
    bag = tmp_path / 'take.mcap'
    recorded = _record_bag(bag)
    proc = _start('source:=replay', f'replay_file:={bag}', 'loop:=true')
    try:
        got = _collect(dds, '/kinect/skeletons', 120, raw=True, proc=proc)
    finally:
        out = _stop(proc)
    assert len(got) > 90, out
    index = {d: i for i, d in enumerate(recorded)}
    positions = [index.get(bytes(d)) for _, d in got]
    assert None not in positions, 'a replayed message differs from every recorded one'
    # in recorded order, wrapping at the end of the bag
    assert all((b - a) % len(recorded) == 1 for a, b in zip(positions, positions[1:]))
    assert set(positions) == set(range(len(recorded)))
    rate = _rate([t for t, _ in got])
    print(f'replay 2 users: {rate:.2f} Hz received ({len(got)} msgs; the rate is a benchmark '
          'figure, not asserted here)')


def test_replay_restamp_with_tf(dds, tmp_path):
    bag = tmp_path / 'take.mcap'
    _record_bag(bag, n=30, users=(7,))
    proc = _start('source:=replay', f'replay_file:={bag}', 'loop:=true', 'restamp:=true',
                  'publish_tf:=true', 'rate:=2.0')
    tf = []
    try:
        got = _collect(dds, '/kinect/skeletons', 25, proc=proc,
                       extra={'/tf': (TFMessage, tf)})
    finally:
        out = _stop(proc)
    assert len(got) > 20, out
    now = time.time_ns()
    body = standard_body().rest_positions()
    for _, m in got:
        f, = frames_from_array_msg(m)
        assert f.user_id == 7 and m.header.frame_id == 'kinect_link'
        assert abs(now - f.stamp_ns) < 60e9     # restamped with the current time (recorded: 2023)
        assert stamp_to_ns(m.header.stamp) == f.stamp_ns
        assert np.allclose(f.positions - (body + [2.5, 5.6, -0.8]), f.positions[0] - body[0]
                           - [2.5, 5.6, -0.8], atol=1e-9)
    assert {t.child_frame_id for m in tf for t in m.transforms} >= {'head_7', 'right_foot_7'}
    assert all(abs(now - stamp_to_ns(t.header.stamp)) < 60e9 for m in tf for t in m.transforms)


def _run_fail(*params):
    args = NODE + ['--ros-args'] + [a for p in params for a in ('-p', p)]
    r = subprocess.run(args, env=_env(), capture_output=True, text=True, timeout=60)
    text = (r.stdout + r.stderr).strip()
    assert r.returncode == 1, text
    assert 'Traceback' not in text
    errors = [ln for ln in text.splitlines() if ln.startswith('[ERROR]')]
    assert len(errors) == 1, text
    return errors[0]


def test_unknown_source_is_one_clear_error():
    line = _run_fail('source:=kinect2')
    assert "source='kinect2' is not one of ['synthetic', 'replay', 'live', 'azure_kinect']" in line


def test_unreadable_replay_file_is_one_clear_error(tmp_path):
    (tmp_path / 'broken.mcap').write_bytes(b'\x89MCAP0\r\ngarbage')
    line = _run_fail('source:=replay', f'replay_file:={tmp_path / "broken.mcap"}')
    assert 'broken.mcap' in line and 'cannot read bag' in line


@pytest.mark.skipif(find_openni2_library() is None,
                    reason='libopenni2-0 not installed (scripts/setup.sh installs it as root)')
def test_live_without_sensor_and_without_nite2(tmp_path):
    pytest.importorskip('openni', reason='openni bindings not installed')
    line = _run_fail('source:=live', 'nite2_path:=/opt/NiTE-Linux-x64-2.2/Redist')
    assert 'no device' in line
    line = _run_fail('source:=live', 'device_uri:=Dummy',
                     'nite2_path:=/opt/NiTE-Linux-x64-2.2/Redist')
    assert 'NiTE2 not found at /opt/NiTE-Linux-x64-2.2/Redist' in line


def test_live_retry_keeps_running_without_sensor():
    if find_openni2_library() is None:
        pytest.skip('libopenni2-0 not installed')
    pytest.importorskip('openni')
    proc = _start('source:=live', 'retry_s:=0.5', 'nite2_path:=/opt/NiTE2')
    seen = []   # until the node reports its first retry (start-up takes long on a loaded machine)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        line = proc.stdout.readline()
        seen.append(line)
        if 'retrying every' in line:
            break
    time.sleep(1.5)                   # and it keeps running, retrying
    alive = proc.poll() is None
    out = ''.join(seen) + _stop(proc)
    assert alive, out
    assert 'no device' in out and 'retrying every 0.5 s' in out and 'Traceback' not in out


def _array(stamp, users):
    body = standard_body().rest_positions()
    frames = [SkeletonFrame(positions=body + [2.5, 0.8 * u, -0.8], user_id=u, stamp_ns=stamp,
                            tracking_state=np.full(20, 2, np.uint8), frame_id='kinect_link')
              for u in users]
    return frames_to_array_msg(frames, stamp, 'kinect_link')


def test_replay_waits_for_its_subscribers_and_plays_the_other_topics(tmp_path, dds):
    """wait_for_subscribers=2: nothing is published while one subscriber is there; once the
    second comes, every recorded frame arrives, and so does the bag's ground truth (another
    topic), while a topic the graph produces itself (/posture/reconstructed) is not replayed."""
    from std_msgs.msg import String
    bag = tmp_path / 'gt.mcap'
    n = 45
    with BagWriter(bag) as w:
        for k in range(n):
            stamp = 5_000_000_000 + k * 33_333_333
            w.write('/kinect/skeletons', _array(stamp, (1,)), stamp)
            w.write('/kinect/ground_truth', _array(stamp, (1,)), stamp)
            w.write('/posture/reconstructed', _array(stamp, (1,)), stamp)
            if k % 10 == 0:
                w.write('/notes', String(data=f'note {k}'), stamp)
    proc = _start('source:=replay', f'replay_file:={bag}', 'wait_for_subscribers:=2')
    node = rclpy.create_node('replay_probe', context=dds)
    got = {'/kinect/skeletons': [], '/kinect/ground_truth': [], '/posture/reconstructed': [],
           '/notes': []}
    for topic in got:
        cls = String if topic == '/notes' else SkeletonArray
        node.create_subscription(cls, topic, got[topic].append, 200)
    ex = SingleThreadedExecutor(context=dds)
    ex.add_node(node)
    second = None
    try:
        end = time.monotonic() + 3.0          # one subscriber (this probe): the replay waits
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        assert not got['/kinect/skeletons'], 'played before its subscribers were there'
        second = rclpy.create_node('replay_probe2', context=dds)
        second.create_subscription(SkeletonArray, '/kinect/skeletons', lambda m: None, 10)
        ex.add_node(second)
        deadline = time.monotonic() + 30
        while len(got['/kinect/skeletons']) < n and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
    finally:
        ex.shutdown()
        out = _stop(proc)
    assert len(got['/kinect/skeletons']) == n, out
    assert len(got['/kinect/ground_truth']) == n, out
    assert [m.data for m in got['/notes']] == [f'note {k}' for k in range(0, n, 10)]
    assert not got['/posture/reconstructed']
    assert 'waiting for 2 subscriber(s)' in out and 'also replaying' in out
