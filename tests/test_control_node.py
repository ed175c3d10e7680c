"""control node over real DDS: a scripted imitation in, the composed pose out on /control/target
(frame and stamps kept), skeleton_msgs/Intention with the engaged feature and e1/e2, feature and
contact markers; parameters validated."""
import math

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

from rclpy.parameter import Parameter  # noqa: E402
from skeleton_msgs.msg import Intention, SkeletonArray  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from performance_control.control_node import ControlNode  # noqa: E402
from skeleton_core.rosnode import TransitionFailed, bring_up  # noqa: E402
from performance_control.examples import imitation  # noqa: E402
from performance_control.features import load_world  # noqa: E402
from ros_helpers import Spinner, wait_until  # noqa: E402
from skeleton_core.conversions import (SkeletonFrame, frames_from_array_msg,  # noqa: E402
                                       frames_to_array_msg)
from skeleton_core.model import NUM_JOINTS, standard_body  # noqa: E402


@pytest.fixture
def graph(rclpy_context):
    node = bring_up(ControlNode(context=rclpy_context, parameter_overrides=[
        Parameter('input_topic', value='/test_control/in'),
        Parameter('output_topic', value='/test_control/out'),
        Parameter('start_feature', value='monkey_bars')]))
    peer = rclpy.create_node('control_test_peer', context=rclpy_context)
    spinner = Spinner(rclpy_context, node, peer)
    yield node, peer
    spinner.stop()
    node.destroy_node()
    peer.destroy_node()


def test_node_controls_a_performance_over_dds(graph):
    node, peer = graph
    out, intent, marks = [], [], []
    peer.create_subscription(SkeletonArray, '/test_control/out', out.append, 100)
    peer.create_subscription(Intention, '/control/intention', intent.append, 100)
    peer.create_subscription(MarkerArray, '/control/markers', marks.append, 100)
    pub = peer.create_publisher(SkeletonArray, '/test_control/in', 10)
    assert wait_until(lambda: pub.get_subscription_count() > 0, 10)
    f = load_world('playground').features['monkey_bars']
    clip = imitation(f.example.generator, f.example.params, standard_body(1.7), 60)
    clip = clip + np.array([2.5, 0.0, -0.8])         # 2.5 m ahead of a sensor 0.8 m up
    stamps = []
    for i, p in enumerate(clip):
        st = 5_000_000_000 + i * 33_333_333
        stamps.append(st)
        fr = SkeletonFrame(positions=p, tracking_state=np.full(NUM_JOINTS, 2, np.uint8),
                           user_id=3, stamp_ns=st, frame_id='kinect_link')
        pub.publish(frames_to_array_msg([fr], st, 'kinect_link'))
        # lockstep, not a rate: this is about what the node computes, and a loaded machine must
        # not turn a slow callback into dropped input
        # (the first frame starts the user's controller: longer on a loaded machine)
        assert wait_until(lambda n=i: len(out) > n, 30 if i == 0 else 10), \
            f'no output for frame {i}'
    assert wait_until(lambda: out and frames_from_array_msg(out[-1])[0].stamp_ns == stamps[-1], 10)
    last = frames_from_array_msg(out[-1])[0]
    assert out[-1].header.frame_id == 'kinect_link' and last.user_id == 3
    # hanging from a bar: the hands at the bar (sensor frame: z - 0.8)
    bar_z = f.geoms[0].vec('from')[2]
    hands = last.positions[[7, 11]]
    assert np.all(np.abs(hands[:, 2] - (bar_z - 0.8)) < 0.08), hands
    assert wait_until(lambda: len(intent) >= len(clip), 5)   # one per output frame
    m = intent[-1]
    assert m.user_id == 3 and m.feature == 'monkey_bars'
    assert set(m.engaged_effectors) >= {'HandLeft', 'HandRight'}
    assert list(m.engaged_features)[:2] == ['monkey_bars', 'monkey_bars']
    assert math.isfinite(m.e1) and math.isfinite(m.e2) and 0.0 <= m.confidence <= 1.0
    assert any(x.imitating for x in intent[-20:])
    assert wait_until(lambda: any(mk.ns == 'control_features' for a in marks
                                  for mk in a.markers), 3)
    assert any(mk.ns == 'control_contacts' and mk.action == 0 for a in marks for mk in a.markers)


def test_parameters_are_validated_and_live(graph):
    node, _ = graph
    res = node.set_parameters([Parameter('e1_threshold', value=-1.0)])[0]
    assert not res.successful and 'range' in res.reason
    assert node.set_parameters([Parameter('e1_threshold', value=0.05)])[0].successful
    assert node.rp.e1_threshold == 0.05


def test_unknown_world_is_a_clear_start_up_error(rclpy_context):
    node = ControlNode(context=rclpy_context, parameter_overrides=[
        Parameter('world', value='atlantis')])   # the constructor reads no file
    try:
        with pytest.raises(TransitionFailed, match='no world'):
            bring_up(node)   # on_configure: one line, the node stays unconfigured
        assert node.lifecycle_state == 'unconfigured'
    finally:
        node.destroy_node()
