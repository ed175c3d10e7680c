"""Frames without tf2: transforms and the static TF buffer (chains through a common ancestor,
inverse lookups, cycles refused, clear errors), the sensor-pose YAML and launch-argument poses,
and the static_tf node over real DDS (one latched message holding every frame, received by a
subscriber that joins late, tf2's QoS)."""
import math
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from skeleton_core.tf import (HeldUntilTf, TfBuffer, Transform, default_sensor_poses, load_transforms,
                              parse_pose, transforms_to_yaml)


def test_ypr_follows_tf2_and_a_positive_pitch_tilts_the_sensor_down():
    t = Transform.from_xyz_ypr(0, 0, 0.8, 0, 10, 0)
    forward = t.apply([1.0, 0, 0]) - t.translation
    assert forward[2] < 0                                   # x axis points down
    np.testing.assert_allclose(t.xyz_ypr(), [0, 0, 0.8, 0, 10, 0], atol=1e-9)
    r = Transform.from_xyz_ypr(1, 2, 3, 30, -20, 15)
    np.testing.assert_allclose(r.xyz_ypr(), [1, 2, 3, 30, -20, 15], atol=1e-9)
    # z-y'-x'': yaw 90 turns x to y
    np.testing.assert_allclose(Transform.from_xyz_ypr(0, 0, 0, 90).apply([1, 0, 0]), [0, 1, 0],
                               atol=1e-12)
    p = np.random.default_rng(0).normal(size=(5, 3))
    np.testing.assert_allclose(r.inverse().apply(r.apply(p)), p, atol=1e-12)
    np.testing.assert_allclose((r * r.inverse()).translation, 0, atol=1e-12)


def test_apply_quat_of_identity_orientations_is_the_product_exactly():
    """Identity orientations (a tracker without any) take a shortcut: the same values as the
    quaternion product, bit for bit; anything else still goes through the product."""
    from skeleton_core.geometry import quat_multiply
    rng = np.random.default_rng(4)
    for _ in range(50):
        t = Transform.from_xyz_ypr(*rng.normal(size=3), *rng.uniform(-170, 170, 3))
        for q in (np.tile([0.0, 0.0, 0.0, 1.0], (20, 1)), rng.normal(size=(20, 4)),
                  np.vstack([np.tile([0.0, 0.0, 0.0, 1.0], (19, 1)), [[0.0, 0.0, 1e-9, 1.0]]])):
            want = quat_multiply(np.broadcast_to(t.rotation, q.shape), q)
            assert np.array_equal(t.apply_quat(q), want)
    assert t.apply_quat(np.zeros((0, 4))).shape == (0, 4)


def test_buffer_looks_up_chains_through_the_common_ancestor():
    tf = TfBuffer()
    w1 = Transform.from_xyz_ypr(0, 0, 0.8, 0, 5, 0)
    w2 = Transform.from_xyz_ypr(2.5, 2.5, 1.0, -90, 0, 0)
    tf.set('world', 'kinect_1_link', w1)
    tf.set('world', 'kinect_2_link', w2)
    tf.set('kinect_2_link', 'camera_2', Transform.from_xyz_ypr(0.05, 0, 0))
    p2 = np.array([1.0, 0.2, -0.3])                          # a point the side sensor sees
    in_world = w2.apply(p2)
    np.testing.assert_allclose(tf.lookup('world', 'kinect_2_link').apply(p2), in_world)
    np.testing.assert_allclose(tf.lookup('kinect_1_link', 'kinect_2_link').apply(p2),
                               w1.inverse().apply(in_world), atol=1e-12)
    np.testing.assert_allclose(tf.lookup('kinect_2_link', 'world').apply(in_world), p2,
                               atol=1e-12)
    # two steps below the common ancestor
    np.testing.assert_allclose(tf.lookup('kinect_1_link', 'camera_2').apply([0, 0, 0]),
                               w1.inverse().apply(w2.apply([0.05, 0, 0])), atol=1e-12)
    assert tf.lookup('world', 'world').is_identity()


def test_buffer_errors_are_one_line_and_cycles_are_refused():
    tf = TfBuffer()
    tf.set('world', 'kinect_link', Transform())
    tf.set('map', 'odom', Transform())
    with pytest.raises(LookupError, match="'kinect_2_link' is not on TF"):
        tf.lookup('world', 'kinect_2_link')
    with pytest.raises(LookupError, match='not connected'):
        tf.lookup('world', 'odom')
    with pytest.raises(ValueError, match='cycle'):
        tf.set('kinect_link', 'world', Transform())
    v = tf.version
    tf.set('world', 'kinect_link', Transform())              # the same again: no change
    assert tf.version == v
    tf.set('world', 'kinect_link', Transform.from_xyz_ypr(0, 0, 1))   # replaced, as tf2
    assert tf.version == v + 1 and tf.lookup('world', 'kinect_link').translation[2] == 1
    with pytest.raises(ValueError):
        Transform((0, 0, math.nan))
    with pytest.raises(ValueError):
        Transform((0, 0, 0), (0, 0, 0, 0))


def test_sensor_pose_file_round_trip_and_errors(tmp_path):
    items = [('world', 'kinect_1_link', Transform.from_xyz_ypr(0, 0, 0.8)),
             ('world', 'kinect_2_link', Transform.from_xyz_ypr(2.5, 2.5, 0.9, -90, 3, 1))]
    f = tmp_path / 'extrinsics.yaml'
    f.write_text(transforms_to_yaml(items, {'kinect_2_link': {'time_offset_s': 0.25}}, 'hand'))
    back = load_transforms(f)
    assert [(p, c) for p, c, _ in back] == [(p, c) for p, c, _ in items]
    for (_, _, a), (_, _, b) in zip(items, back):
        d, ang = a.distance(b)
        assert d < 1e-6 and ang < 1e-5
    hand = tmp_path / 'hand.yaml'        # hand-measured: only what a person writes down
    hand.write_text('transforms:\n- child: kinect_link\n  xyz: [0, 0, 1.1]\n  ypr_deg: [0, 12, 0]\n')
    (p, c, t), = load_transforms(hand)
    assert (p, c) == ('world', 'kinect_link')
    np.testing.assert_allclose(t.xyz_ypr(), [0, 0, 1.1, 0, 12, 0], atol=1e-9)
    bad = tmp_path / 'bad.yaml'
    bad.write_text('transforms:\n- child: kinect_link\n  ypr_deg: [0, 1]\n')
    with pytest.raises(ValueError, match='bad.yaml, transform 1: ypr_deg needs 3 values'):
        load_transforms(bad)
    with pytest.raises(ValueError, match='not found'):
        load_transforms(tmp_path / 'missing.yaml')
    with pytest.raises(ValueError, match='x y z yaw pitch roll'):
        parse_pose('0 0 zero')
    np.testing.assert_allclose(parse_pose('1, 2, 3').translation, [1, 2, 3])


def test_default_poses_put_the_second_sensor_at_the_side_facing_the_play_space():
    one, two = default_sensor_poses(2)
    np.testing.assert_allclose(one.xyz_ypr(), [0, 0, 0.8, 0, 0, 0], atol=1e-9)
    centre = np.array([2.5, 0.0, 0.8])
    # the side sensor looks at the play space centre, at 90 degrees to the first
    look = two.apply([1.0, 0, 0]) - two.translation
    to_centre = (centre - two.translation) / np.linalg.norm(centre - two.translation)
    np.testing.assert_allclose(look, to_centre, atol=1e-9)
    assert abs(look @ np.array([1.0, 0, 0])) < 1e-9


# ------------------------------------------------------------------ over DDS
rclpy = pytest.importorskip('rclpy')


def _env():
    return dict(os.environ, ROS_DOMAIN_ID=os.environ['ROS_DOMAIN_ID'])


def test_static_tf_node_latches_every_frame_in_one_message(rclpy_context):
    """The node publishes both sensors and exits cleanly; a subscriber started after the
    publication still gets them (transient_local), in one TFMessage."""
    from tf2_msgs.msg import TFMessage
    from skeleton_core.tf_ros import STATIC_LISTENER_QOS, StaticTfListener
    proc = subprocess.Popen(
        [sys.executable, '-m', 'kinect_driver.static_tf_node', '--pose', '0 0 0.8 0 0 0',
         '--child', 'kinect_1_link', '--pose', '2.5 2.5 1.0 -90 0 0', '--child', 'kinect_2_link'],
        env=_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    node = rclpy.create_node('tf_probe', context=rclpy_context)
    try:
        time.sleep(2.0)             # published before anybody listens
        assert proc.poll() is None
        msgs = []
        node.create_subscription(TFMessage, '/tf_static', msgs.append, STATIC_LISTENER_QOS)
        listener = StaticTfListener(node)
        from rclpy.executors import SingleThreadedExecutor
        ex = SingleThreadedExecutor(context=rclpy_context)
        ex.add_node(node)
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and not listener.buffer.can_transform(
                'kinect_1_link', 'kinect_2_link'):
            ex.spin_once(timeout_sec=0.1)
        assert msgs and {t.child_frame_id for t in msgs[0].transforms} == {
            'kinect_1_link', 'kinect_2_link'}
        rel = listener.buffer.lookup('kinect_1_link', 'kinect_2_link')
        d, a = rel.distance(Transform.from_xyz_ypr(2.5, 2.5, 0.2, -90, 0, 0))
        assert d < 1e-9 and a < 1e-6
        info = node.get_publishers_info_by_topic('/tf_static')
        assert info, 'no publisher on /tf_static'
        qos = info[0].qos_profile
        from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
        assert qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
        assert qos.reliability == ReliabilityPolicy.RELIABLE
    finally:
        node.destroy_node()
        proc.terminate()
        out = proc.communicate(timeout=30)[0]   # (a loaded machine: shutdown is not what is tested)
    assert proc.returncode in (0, -15), out
    assert 'kinect_2_link: 2.5 2.5 1 -90 0 0' in out


def test_listener_lookup_takes_what_waits_unannounced_and_a_resend_keeps_every_frame(rclpy_context):
    """A broadcaster that sent its frames in two calls still holds both in its one latched message
    (depth 1 keeps only the last). A listener made after that, on a node no executor spins (a
    wake-up the middleware lost looks the same: the message waits on the subscription), finds
    both frames through its lookup, which takes the waiting message on a miss; a frame nobody
    publishes stays a LookupError naming the publishers met and the messages received."""
    from ros_helpers import wait_until
    from skeleton_core.tf_ros import StaticTfBroadcaster, StaticTfListener
    pub_node = rclpy.create_node('tf_resend_pub', context=rclpy_context)
    node = rclpy.create_node('tf_unspun_listener', context=rclpy_context)
    try:
        b = StaticTfBroadcaster(pub_node)
        b.send([('world', 'kinect_1_link', Transform.from_xyz_ypr(0, 0, 0.8))])
        b.send([('world', 'kinect_2_link', Transform.from_xyz_ypr(2.5, 2.5, 0.8, -90, 0, 0))])
        listener = StaticTfListener(node)

        def found():
            try:
                return listener.lookup('kinect_1_link', 'kinect_2_link')
            except LookupError:
                return None
        assert wait_until(found, 20)
        d, a = found().distance(Transform.from_xyz_ypr(2.5, 2.5, 0.0, -90, 0, 0))
        assert d < 1e-9 and a < 1e-6
        with pytest.raises(LookupError, match=r"kinect_3_link.*; /tf_static: 1 publisher\(s\) "
                                              r"matched, 1 message\(s\) received"):
            listener.lookup('world', 'kinect_3_link')
        assert listener.poll() == 0   # nothing more waits
    finally:
        node.destroy_node()
        pub_node.destroy_node()


@pytest.mark.parametrize('args, text', [
    (['--pose', '0 0 high'], 'x y z yaw pitch roll'),
    (['--file', '/nonexistent/extrinsics.yaml'], 'not found'),
    ([], 'nothing to publish'),
])
def test_static_tf_bad_arguments_are_one_line_and_exit_1(args, text):
    r = subprocess.run([sys.executable, '-m', 'kinect_driver.static_tf_node'] + args, env=_env(),
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and text in lines[0], r.stderr
    assert 'Traceback' not in r.stderr


def test_held_until_tf_keeps_the_newest_in_order_and_gives_back_what_it_lets_go():
    held = HeldUntilTf(limit=3)
    assert [held.hold(i) for i in range(5)] == [None, None, None, 0, 1]
    assert len(held) == 3
    assert held.take() == [2, 3, 4]
    assert len(held) == 0 and held.take() == []
    with pytest.raises(ValueError, match='limit'):
        HeldUntilTf(limit=0)
