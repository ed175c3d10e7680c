"""The recorder's start: with ``wait_for_publishers`` (set by the launch file) it subscribes to the
graph's input only once the named output topics have a publisher it matched, so a replay (which
waits for the recorder's subscription before its first frame) never plays frames whose outputs the
recorder cannot receive yet (the replay through launch lost frame 0's outputs in CI); and it is
active only once its input subscriptions met the named input publishers (the driver's), so the
driver, which the launch files activate last, starts with the recorder listening."""
import threading
import time

import pytest

rclpy = pytest.importorskip('rclpy')

from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402

from kinect_bringup.recorder import MATCH_SETTLE_S, RecorderNode  # noqa: E402
from ros_helpers import Spinner, wait_until  # noqa: E402
from skeleton_core.rosnode import bring_up  # noqa: E402

pytestmark = pytest.mark.ros


def _bring_up_in_background(rec):
    done = threading.Event()
    errors = []

    def run():
        try:
            bring_up(rec)
        except Exception as e:   # noqa: BLE001 -- reported by the test
            errors.append(e)
        done.set()
    threading.Thread(target=run, daemon=True).start()
    return done, errors


def test_the_input_is_subscribed_after_the_outputs_have_publishers(rclpy_context, tmp_path):
    from skeleton_msgs.msg import SkeletonArray
    rec = RecorderNode(context=rclpy_context, parameter_overrides=[
        Parameter('output', value=str(tmp_path / 'out.mcap')),
        Parameter('topics', value=['/kinect/skeletons', '/posture/reconstructed']),
        Parameter('wait_for_publishers', value=['/posture/reconstructed'])])
    other = rclpy.create_node('kp_recorder_start_probe', context=rclpy_context)
    spin = Spinner(rclpy_context, rec, other)
    try:
        done, errors = _bring_up_in_background(rec)
        assert wait_until(lambda: other.count_subscribers('/posture/reconstructed') == 1, 10.0)
        time.sleep(1.0)   # 100 polls of the recorder's wait: still no output publisher
        assert other.count_subscribers('/kinect/skeletons') == 0
        assert not done.is_set() and rec.lifecycle_state != 'active'
        made = time.monotonic()
        other.create_publisher(SkeletonArray, '/posture/reconstructed', QoSProfile(depth=10))
        assert wait_until(lambda: other.count_subscribers('/kinect/skeletons') == 1, 10.0)
        assert done.wait(10.0) and not errors, errors
        # active only once the publisher's side of the match had MATCH_SETTLE_S to follow
        assert time.monotonic() - made >= MATCH_SETTLE_S
        assert rec.lifecycle_state == 'active'
    finally:
        spin.stop()
        rec.destroy_node()
        other.destroy_node()


def test_active_only_once_the_input_met_its_publisher(rclpy_context, tmp_path):
    """The driver's topics named in wait_for_publishers: subscribed after the outputs (as any
    input), and the recorder is active only once those subscriptions have met a publisher."""
    from skeleton_msgs.msg import SkeletonArray
    rec = RecorderNode(context=rclpy_context, parameter_overrides=[
        Parameter('output', value=str(tmp_path / 'out.mcap')),
        Parameter('topics', value=['/kinect/skeletons', '/posture/reconstructed']),
        Parameter('wait_for_publishers', value=['/kinect/skeletons', '/posture/reconstructed'])])
    other = rclpy.create_node('kp_recorder_start_probe3', context=rclpy_context)
    spin = Spinner(rclpy_context, rec, other)
    try:
        other.create_publisher(SkeletonArray, '/posture/reconstructed', QoSProfile(depth=10))
        done, errors = _bring_up_in_background(rec)
        # the input is subscribed once the output has its publisher ...
        assert wait_until(lambda: other.count_subscribers('/kinect/skeletons') == 1, 10.0)
        time.sleep(MATCH_SETTLE_S + 0.5)
        # ... but without the input's publisher the recorder is not active yet
        assert not done.is_set() and rec.lifecycle_state != 'active'
        other.create_publisher(SkeletonArray, '/kinect/skeletons', QoSProfile(depth=10))
        assert done.wait(10.0) and not errors, errors
        assert rec.lifecycle_state == 'active'
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
        assert other.count_subscribers('/kinect/skeletons') == 1 or \
            wait_until(lambda: other.count_subscribers('/kinect/skeletons') == 1, 10.0)
    finally:
        spin.stop()
        rec.destroy_node()
        other.destroy_node()


def test_a_latched_message_the_executor_was_never_woken_for_is_recorded(rclpy_context, tmp_path):
    """/tf_static sends its message once: when the executor is never woken for it (the middleware
    can lose that wake-up for a subscription made in the activation; here the executor never
    waits on the subscription at all), the recorder still takes it from the subscription."""
    from skeleton_core.tf import Transform
    from skeleton_core.tf_ros import StaticTfBroadcaster
    rec = RecorderNode(context=rclpy_context, parameter_overrides=[
        Parameter('output', value=str(tmp_path / 'out.mcap')),
        Parameter('topics', value=['/kinect/skeletons', '/tf_static'])])
    other = rclpy.create_node('kp_recorder_latched_probe', context=rclpy_context)
    spin = None
    bring_up(rec)
    sub = rec._latched_subs['/tf_static']
    rec._subscriptions.remove(sub)   # hidden from the executor: no wake-up ever reaches it
    try:
        spin = Spinner(rclpy_context, rec, other)
        StaticTfBroadcaster(other).send([('world', 'kinect_link', Transform())])
        assert wait_until(lambda: rec.counts['/tf_static'] == 1, 10.0), rec.counts
    finally:
        if spin is not None:
            spin.stop()
        rec._subscriptions.append(sub)   # destroyed with the node
        rec.destroy_node()
        other.destroy_node()
