"""viz node over real DDS: SkeletonArray in, MarkerArray out; run-time parameter changes."""
import os
import time
import uuid

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from skeleton_msgs.msg import SkeletonArray  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

from skeleton_core.conversions import SkeletonFrame, frames_to_array_msg  # noqa: E402
from skeleton_core.model import ELBOW_LEFT, NUM_JOINTS, NUM_SEGMENTS, standard_body  # noqa: E402
from viz.viz_node import VizNode  # noqa: E402
from skeleton_core.rosnode import bring_up  # noqa: E402
from ros_helpers import Spinner  # noqa: E402


def _array(uids, reliability=None):
    frames = []
    for uid in uids:
        r = (np.full(NUM_JOINTS, np.nan, np.float32) if reliability is None else reliability)
        frames.append(SkeletonFrame(positions=standard_body().rest_positions() + (2.5, 0, 0),
                                    tracking_state=np.full(NUM_JOINTS, 2, np.uint8),
                                    reliability=r, user_id=uid, stamp_ns=5_000_000_123,
                                    frame_id='kinect_link'))
    return frames_to_array_msg(frames, 5_000_000_123, 'kinect_link')


# Private topic names: other test runs on this machine may share the DDS domain.
P = f'/viztest_{os.getpid()}_{uuid.uuid4().hex[:6]}'
TOPICS = {'raw_topic': P + '/kinect/skeletons',
          'reliability_topic': P + '/kinect/skeletons_reliability',
          'reconstructed_topic': P + '/posture/reconstructed',
          'completed_topic': P + '/posture/completed',
          'character_topic': P + '/character/skeletons',
          'objects_topic': P + '/physics/objects', 'markers_topic': P + '/viz/markers'}


@pytest.fixture
def graph(rclpy_context):
    viz = bring_up(VizNode(context=rclpy_context, parameter_overrides=[
        Parameter('max_rate_hz', value=20.0), Parameter('stale_timeout_s', value=30.0)] + [
        Parameter(k, value=v) for k, v in TOPICS.items()]))
    peer = rclpy.create_node('viz_test_peer', context=rclpy_context)
    spinner = Spinner(rclpy_context, viz, peer)
    yield viz, peer
    spinner.stop()
    viz.destroy_node()
    peer.destroy_node()


def _wait_for(got, cond, pubs, timeout=10.0):
    deadline = time.time() + timeout
    while time.time() < deadline:
        for pub, msg in pubs:
            pub.publish(msg)
        for m in list(got):
            if cond(m):
                return m
        time.sleep(0.05)
    return None


def test_markers_cross_dds_and_hiding_a_layer_takes_effect(graph):
    viz, peer = graph
    got = []
    # a deep queue: the deletion below is one array among the 20 Hz stream, and a spin thread
    # starved on a loaded machine would otherwise find it pushed out of a depth-10 queue
    peer.create_subscription(MarkerArray, TOPICS['markers_topic'], got.append, 1000)
    raw = peer.create_publisher(SkeletonArray, TOPICS['raw_topic'], qos_profile_sensor_data)
    rel = peer.create_publisher(SkeletonArray, TOPICS['reliability_topic'],
                                qos_profile_sensor_data)
    char = peer.create_publisher(SkeletonArray, TOPICS['character_topic'], qos_profile_sensor_data)
    r = np.ones(NUM_JOINTS, np.float32)
    r[ELBOW_LEFT] = 0.0
    objects = peer.create_publisher(MarkerArray, TOPICS['objects_topic'], 10)
    box = Marker(ns='box', id=3, type=Marker.CUBE, action=Marker.ADD)
    box.header.frame_id = 'kinect_link'
    box.scale.x = box.scale.y = box.scale.z = 0.3
    box.color.a = 1.0
    pubs = [(raw, _array([1, 4])), (rel, _array([1], r)), (char, _array([1])),
            (objects, MarkerArray(markers=[box]))]

    want = {'raw/user_1', 'raw/user_4', 'reliability/user_1', 'character/user_1',
            'environment/box'}
    msg = _wait_for(got, lambda m: {x.ns for x in m.markers if x.action == Marker.ADD} == want,
                    pubs)
    assert msg is not None, \
        f'no MarkerArray with {want}; got {[{x.ns for x in m.markers} for m in got[-3:]]}'
    by_ns = {}
    for m in msg.markers:
        by_ns.setdefault(m.ns, []).append(m)
    assert sorted(m.type for m in by_ns['raw/user_1']) == [Marker.LINE_LIST, Marker.SPHERE_LIST]
    joints = next(m for m in by_ns['raw/user_1'] if m.type == Marker.SPHERE_LIST)
    assert len(joints.points) == NUM_JOINTS and len(joints.colors) == NUM_JOINTS
    assert [(m.type, m.id) for m in by_ns['reliability/user_1']] == [(Marker.CUBE, ELBOW_LEFT)]
    assert np.isclose(by_ns['reliability/user_1'][0].scale.y, 0.15, atol=1e-6)  # 0.15 * (1 - 0)
    assert len(by_ns['character/user_1']) == 3 * NUM_SEGMENTS
    assert all(m.header.frame_id == 'kinect_link' for m in msg.markers)
    assert all((m.header.stamp.sec, m.header.stamp.nanosec) == (5, 123) for m in msg.markers
               if not m.ns.startswith('environment'))
    fwd = next(x for x in msg.markers if x.ns == 'environment/box')  # forwarded object
    assert fwd.id == 3 and fwd.type == Marker.CUBE and fwd.lifetime.nanosec == 500_000_000

    # refused: out of range / a bad offset
    res = viz.set_parameters([Parameter('max_rate_hz', value=1000.0)])[0]
    assert not res.successful and 'max_rate_hz' in res.reason
    res = viz.set_parameters([Parameter('character_offset', value=[1.0, 0.0])])[0]
    assert not res.successful

    # hide the raw layer at run time: its markers are deleted, then no longer sent
    got.clear()  # before the change: the deletion may go out at once
    assert viz.set_parameters([Parameter('show_raw', value=False)])[0].successful
    # a hidden layer's topic is not subscribed any more (nothing computed for it upstream)
    deadline = time.time() + 10.0
    while raw.get_subscription_count() and time.time() < deadline:
        time.sleep(0.05)
    assert raw.get_subscription_count() == 0
    deleted = _wait_for(got, lambda m: any(x.action == Marker.DELETE and x.ns == 'raw/user_4'
                                           for x in m.markers), pubs)
    assert deleted is not None, 'hidden raw layer was not deleted'
    later = _wait_for(got, lambda m: got.index(m) > got.index(deleted) and
                      any(x.ns == 'character/user_1' for x in m.markers), pubs)
    assert later is not None
    assert not any(x.ns.startswith('raw/') for x in later.markers)

    # hiding the environment deletes the forwarded object
    assert viz.set_parameters([Parameter('show_objects', value=False)])[0].successful
    gone = _wait_for(got, lambda m: any(x.action == Marker.DELETE and x.ns == 'environment/box'
                                        and x.id == 3 for x in m.markers), pubs)
    assert gone is not None, 'hidden environment objects were not deleted'


def test_config_file_lists_every_parameter_and_loads(rclpy_context):
    from pathlib import Path

    import yaml

    from viz.viz_node import PARAMS
    cfg = Path(__file__).resolve().parents[1] / 'config' / 'viz.yaml'
    values = yaml.safe_load(cfg.read_text())['/**']['ros__parameters']
    assert set(values) == {s.name for s in PARAMS if s.public}
    node = bring_up(VizNode(context=rclpy_context, cli_args=['--ros-args', '--params-file', str(cfg)]))
    try:
        for name, v in values.items():
            got = node.params[name]
            assert (list(got) if isinstance(v, list) else got) == v, name
    finally:
        node.destroy_node()
