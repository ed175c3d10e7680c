"""Azure Kinect / Orbbec Femto body tracking in: a bag as ``ros2 bag record /body_tracking_data
/imu`` writes it from the Azure Kinect ROS driver (bodies entering and leaving, a capture split by
body, one split by joints, a joint missing; tests/azure_fake.py) goes through ``process_bag`` with
no flag and opens in the replay source; the driver node with ``source:=azure_kinect`` turns a fake
driver's markers into skeletons over DDS."""
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import azure_fake as A
import domains  # noqa: E402  (tests/domains.py)

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('visualization_msgs.msg')

from skeleton_core import tracker as T  # noqa: E402
from skeleton_core.bagio import read_messages  # noqa: E402
from skeleton_core.cdr import frames_from_cdr  # noqa: E402
from skeleton_core.marker_cdr import MarkerArrayDecoder, installed_layout  # noqa: E402
from skeleton_eval.metrics import bone_length_std, jitter  # noqa: E402

HERE = Path(__file__).resolve().parent
DOMAIN = domains.claim(20 + os.getpid() % 40)
SETTLE = 15   # frames in which a new user's segment lengths are learned


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    path = tmp_path_factory.mktemp('azure') / 'body_tracking.mcap'
    A.write_bag(path)
    return path


def _per_user(path, topic):
    out = {}
    for m in read_messages(path, topics=[topic], decode=False):
        for f in frames_from_cdr(m.data)[2]:
            out.setdefault(f.user_id, {})[f.stamp_ns] = f.positions
    return out


def test_the_codec_reads_what_rclpy_writes():
    from rclpy.serialization import serialize_message
    bodies = A.captures()[40]
    msg = A.marker_array(bodies, 1_700_000_000_123_456_789, 'cam2_depth_camera_link')
    got = MarkerArrayDecoder()(serialize_message(msg))
    assert installed_layout() == 'iron'
    assert len(got) == 64 and got[33].id == msg.markers[33].id == 201
    assert got[5].frame_id == 'cam2_depth_camera_link' and got[5].lifetime_ns == 250_000_000
    assert got[5].stamp_ns == 1_700_000_000_123_456_789
    assert np.allclose(got[5].position, bodies[0][1][5])


def test_process_bag_takes_a_body_tracking_recording_as_it_is(bag, tmp_path):
    from kinect_bringup.process_bag import process
    warned = []
    out = tmp_path / 'processed.mcap'
    s = process(bag, out, method='C', progress=False, warn=warned.append, info=lambda t: None)
    expected = A.expected_user_frames()
    assert s['tracker'] == 'azure_kinect_bt' and s['users'] == 3 and s['user_arrivals'] == 3
    assert s['user_frames'] == sum(expected.values()) and not s['skipped_messages']
    assert T.from_bag(out) == 'azure_kinect_bt'
    raw, rec = _per_user(out, '/kinect/skeletons'), _per_user(out, '/posture/reconstructed')
    assert {u: len(v) for u, v in rec.items()} == expected      # every frame of every body
    assert {u: sorted(v) for u, v in rec.items()} == {u: sorted(v) for u, v in raw.items()}
    topics = {m.topic for m in read_messages(out, decode=False)}
    assert {'/body_tracking_data', '/imu'} <= topics           # what was recorded, kept
    figures = {}
    for u in expected:
        keys = sorted(rec[u])
        r = np.stack([raw[u][k] for k in keys])
        o = np.stack([rec[u][k] for k in keys])
        assert np.all(np.isfinite(o))
        # bone lengths steady per user, smoother than the tracker (printed: the figures of the
        # report; the rigid output for every tracker is the output stage's, not this input's)
        sr, so = bone_length_std(r)[1], bone_length_std(o)[1]
        settled = bone_length_std(o[SETTLE:])[1], bone_length_std(r[SETTLE:])[1]
        jr, jo = jitter(r)[1], jitter(o)[1]
        figures[u] = (sr, so, jr, jo, settled)
        print(f'user {u} ({len(keys)} frames): bone-length std raw {sr:.2f} cm -> {so:.2f} cm '
              f'({1 - so / sr:.0%} below; after the first {SETTLE} frames {settled[1]:.2f} -> '
              f'{settled[0]:.3f} cm), jitter raw {jr:.1f} -> {jo:.1f} m/s^2')
    for u, (sr, so, jr, jo, (s_out, s_raw)) in figures.items():
        # the user's lengths are learned in the first half second, then held; while they
        # converge the output has the expected final lengths (bone_lengths.py): over the whole
        # track >= 90 % below the tracker's from 2 s on, >= 85 % on the 1.3 s user (the
        # 15-sample estimate of a 1.7 cm length noise itself moves that much while it forms)
        assert so < (0.10 if expected[u] >= 60 else 0.15) * sr, (u, figures)
        assert s_out <= 0.1 * s_raw, (u, figures)
        assert jo < jr, (u, figures)


def test_the_replay_source_plays_a_body_tracking_recording(bag):
    from kinect_driver.sources.replay import ReplaySource
    src = ReplaySource(str(bag))
    src.open()
    assert src.tracker == 'azure_kinect_bt' and src.topic == '/body_tracking_data'
    assert src.frames == 145 and '/imu' in src.other_topics
    assert '/body_tracking_data' not in src.other_topics   # played as /kinect/skeletons
    users = {}
    for _, o in src._items:
        for f in o.frames:
            users[f.user_id] = users.get(f.user_id, 0) + 1
            assert f.frame_id == 'kinect_link'
    assert users == A.expected_user_frames()


def test_a_bag_of_two_cameras_replays_one_per_driver(tmp_path):
    from kinect_driver.sources.base import SourceError
    from kinect_driver.sources.replay import ReplaySource
    from skeleton_core.bagio import BagWriter
    path = tmp_path / 'two.mcap'
    caps = A.captures()[30:40]
    with BagWriter(str(path)) as bag:
        for i, bodies in enumerate(caps):
            for k in (1, 2):
                stamp = 10**18 + i * 33_333_333 + k
                bag.write(f'/kinect_{k}/body_tracking_data', A.marker_array(bodies[:k], stamp),
                          stamp, 'visualization_msgs/msg/MarkerArray')
    for k in (1, 2):
        src = ReplaySource(str(path), frame_id=f'kinect_{k}_link')
        src.open()
        assert src.topic == f'/kinect_{k}/body_tracking_data' and not src.other_topics
        assert {len(o.frames) for _, o in src._items} == {k}
    with pytest.raises(SourceError, match='replay_topic'):
        ReplaySource(str(path)).open()


def _env():
    return dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN))


def test_the_azure_kinect_source_over_dds():
    """The driver node subscribed to a fake Azure Kinect ROS driver: every body of every capture
    arrives on /kinect/skeletons with the tracker declared."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from skeleton_msgs.msg import SkeletonArray
    from std_msgs.msg import String
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN)
    node = rclpy.create_node('azure_probe', context=ctx)
    got, tracker = [], []
    node.create_subscription(SkeletonArray, '/kinect/skeletons', got.append, 300, raw=True)
    node.create_subscription(String, '/kinect/tracker', lambda m: tracker.append(m.data),
                             QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    driver = subprocess.Popen([sys.executable, '-m', 'kinect_driver.driver_node', '--ros-args',
                               '-p', 'source:=azure_kinect'], env=_env(),
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    fake = subprocess.Popen([sys.executable, str(HERE / 'fake_azure_driver.py'), '--wait-topic',
                             '/kinect/skeletons', '--wait', '1'], env=_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and fake.poll() is None:
            ex.spin_once(timeout_sec=0.05)
        end = time.monotonic() + 2
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
        assert fake.returncode == 0, fake.communicate()[0]
    finally:
        driver.terminate()
        out = driver.communicate(timeout=20)[0]
        if fake.poll() is None:
            fake.kill()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    users = {}
    stamps = []
    for data in got:
        stamp, frame_id, frames = frames_from_cdr(data)
        assert frame_id == 'kinect_link'
        stamps.append(stamp)
        for f in frames:
            users[f.user_id] = users.get(f.user_id, 0) + 1
            assert np.all(np.isfinite(f.positions))
    assert users == A.expected_user_frames(), (users, out)
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    assert tracker == ['azure_kinect_bt']
    assert 'source azure_kinect started' in out and 'Traceback' not in out


def test_reliability_without_tracking_states_comes_from_behaviour_and_lengths():
    """The markers carry no tracking state (every joint there is TRACKED): a joint the tracker
    shakes, or one placed at a wrong bone length, is still found unreliable (Eq. 1-6 and the
    plausibility checks), the steady ones stay reliable."""
    from pose_reconstruction.reliability import ReliabilityEstimator
    from skeleton_core.model import ELBOW_RIGHT, HAND_LEFT, KNEE_LEFT
    from skeleton_data import k4abt as K4
    t = A.truth()[1]
    stream = K4.MarkerStream(live=False)
    est = ReliabilityEstimator()
    cam = K4.camera_to_sensor()
    rel = []
    for i in range(5, 95):
        k = K4.k4abt_from_model(t[i])
        if i >= 60:   # the left hand shakes 8 cm back and forth every frame
            k[K4.K4ABT_INDEX['HAND_LEFT']] += [0.0, 0.08 * (-1) ** i, 0.0]
        if 70 <= i < 80:   # the left knee 20 cm up its thigh for a third of a second
            k[K4.K4ABT_INDEX['KNEE_LEFT']] += [0.0, 0.0, 0.2]
        bodies = [(1, k @ cam, np.ones(K4.NUM_K4ABT, bool))]
        for _, frames in stream.add(_markers(bodies, i), 10**9 + i * 33_333_333):
            f = frames[0]
            assert (f.tracking_state == 2).all()
            rel.append(est.update(f.positions, f.tracking_state))
    rel = np.array(rel)          # rel[n]: capture 5 + n
    late = rel[60:].mean(axis=0)
    assert late[HAND_LEFT] < 0.3 and late[ELBOW_RIGHT] > 0.9, late
    assert rel[66:75, KNEE_LEFT].mean() < 0.6 and rel[50:60, KNEE_LEFT].min() > 0.9, \
        rel[:, KNEE_LEFT]


def _markers(bodies, i, t0=10**9):
    from skeleton_core.marker_cdr import Marker
    stamp = t0 + i * 33_333_333
    return [Marker(stamp, 'depth_camera_link', '', b * 100 + j, 2, 0, tuple(p[j]), (0, 0, 0, 1),
                   250_000_000) for b, p, _ in bodies for j in range(32)]
