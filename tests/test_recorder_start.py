"""The recorder's start: with ``wait_for_publishers`` (set by the launch file) it subscribes to the
graph's input only once the named output topics have a publisher it matched, so a replay (which
waits for the recorder's subscription before its first frame) never plays frames whose outputs the
recorder cannot receive yet (the replay through launch lost frame 0's outputs in CI)."""
import time

import pytest

rclpy = pytest.importorskip('rclpy')

from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402

from kinect_bringup.recorder import MATCH_SETTLE_S, RecorderNode  # noqa: E402
from ros_helpers import Spinner, wait_until  # noqa: E402
from skeleton_core.rosnode import bring_up  # noqa: E402

pytestmark = pytest.mark.ros


def test_the_input_is_subscribed_after_the_outputs_have_publishers(rclpy_context, tmp_path):
    from skeleton_msgs.msg import SkeletonArray
    rec = RecorderNode(context=rclpy_context, parameter_overrides=[
        Parameter('output', value=str(tmp_path / 'out.mcap')),
        Parameter('topics', value=['/kinect/skeletons', '/posture/reconstructed']),
        Parameter('wait_for_publishers', value=['/posture/reconstructed'])])
    other = rclpy.create_node('kp_recorder_start_probe', context=rclpy_context)
    spin = Spinner(rclpy_context, rec, other)
    try:
        bring_up(rec)
        assert wait_until(lambda: other.count_subscribers('/posture/reconstructed') == 1, 10.0)
        time.sleep(1.0)   # 20 polls of the recorder's wait: still no output publisher
        assert other.count_subscribers('/kinect/skeletons') == 0
        made = time.monotonic()
        other.create_publisher(SkeletonArray, '/posture/reconstructed', QoSProfile(depth=10))
        assert wait_until(lambda: other.count_subscribers('/kinect/skeletons') == 1, 10.0)
        # and not before the publisher's side of the match had MATCH_SETTLE_S to follow
        assert time.monotonic() - made >= MATCH_SETTLE_S
    finally:
        spin.stop()
        rec.destroy_node()
        other.destroy_node()


def test_without_outputs_to_wait_for_the_input_is_subscribed_on_activate(rclpy_context, tmp_path):
    rec = RecorderNode(context=rclpy_context, parameter_overrides=[
        Parameter('output', value=str(tmp_path / 'out.mcap')),
        Parameter('topics', value=['/kinect/skeletons', '/posture/reconstructed'])])
    other = rclpy.create_node('kp_recorder_start_probe2', context=rclpy_context)
    spin = Spinner(rclpy_context, rec, other)
    try:
        bring_up(rec)
        assert wait_until(lambda: other.count_subscribers('/kinect/skeletons') == 1, 10.0)
    finally:
        spin.stop()
        rec.destroy_node()
        other.destroy_node()
