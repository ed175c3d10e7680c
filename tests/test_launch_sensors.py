"""launch_pytest: driver.launch.py sensors:=2 starts two drivers in their namespaces (/kinect_1,
/kinect_2: skeletons in frames kinect_1_link / kinect_2_link) and one static_tf publishing both
sensor frames in one latched /tf_static message; the two drivers see the same simulated person
from their own poses, so the calibration recovers the second sensor's pose from what they
published over DDS.

Its own module: launch_pytest runs one launch service at a time."""
import time

import numpy as np
import pytest

import launch  # noqa: E402
from launch_support import include, launch_pytest  # noqa: E402
import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402

from skeleton_core.cdr import frames_from_cdr  # noqa: E402
from skeleton_core.tf import TfBuffer, Transform  # noqa: E402
from skeleton_core.tf_ros import StaticTfListener  # noqa: E402
from skeleton_eval.extrinsics import tracks_from_frames  # noqa: E402

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]
POSES = '0 0 0.8 0 0 0; 2.5 2.5 1.0 -90 0 0'   # front + side, the side sensor 0.2 m higher


@launch_pytest.fixture
def two_sensors():
    return launch.LaunchDescription([
        include('driver.launch.py', sensors='2', sensor_pose=POSES, scenario='clean',
                num_users='1'),
        launch_pytest.actions.ReadyToTest(),
    ])


@pytest.mark.launch(fixture=two_sensors)
def test_two_drivers_in_namespaces_with_their_frames_on_tf():
    from skeleton_msgs.msg import SkeletonArray
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node('sensors_probe', context=ctx)
    tf = TfBuffer()
    messages = []
    StaticTfListener(node, tf)
    # counts TFMessages as received (one message holding both frames)
    from tf2_msgs.msg import TFMessage
    from skeleton_core.tf_ros import STATIC_LISTENER_QOS
    node.create_subscription(TFMessage, '/tf_static', messages.append, STATIC_LISTENER_QOS)
    got = {1: [], 2: [], 'plain': []}
    for k in (1, 2):
        node.create_subscription(SkeletonArray, f'/kinect_{k}/skeletons',
                                 lambda d, k=k: got[k].append(d), 100, raw=True)
    node.create_subscription(SkeletonArray, '/kinect/skeletons',
                             lambda d: got['plain'].append(d), 10, raw=True)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline and (len(got[1]) < 200 or len(got[2]) < 200
                                               or not tf.can_transform('world', 'kinect_2_link')):
            ex.spin_once(timeout_sec=0.1)
        assert len(got[1]) >= 200 and len(got[2]) >= 200, {k: len(v) for k, v in got.items()}
        assert not got['plain'], 'a namespaced driver published on /kinect/skeletons'
        # both frames in one latched message, as tf2's static broadcaster sends them
        assert any({t.child_frame_id for t in m.transforms} == {'kinect_1_link', 'kinect_2_link'}
                   for m in messages)
        side = tf.lookup('world', 'kinect_2_link')
        d, a = side.distance(Transform.from_xyz_ypr(2.5, 2.5, 1.0, -90, 0, 0))
        assert d < 1e-6 and a < 1e-4
        # the relative pose of the two sensors, as the launch file composed it
        rel = tf.lookup('kinect_1_link', 'kinect_2_link')
        assert rel.distance(Transform.from_xyz_ypr(2.5, 2.5, 0.2, -90, 0, 0))[0] < 1e-6
        frames = {k: [] for k in (1, 2)}
        for k in (1, 2):
            for data in got[k]:
                _, frame_id, fs = frames_from_cdr(data)
                assert frame_id == f'kinect_{k}_link'
                frames[k] += fs
        # the same person seen from both places: the ground-truth-free check is that the side
        # sensor's skeleton, moved through TF, lands on the front sensor's (noise, offsets and
        # the drivers' start times apart: compare the mean body positions)
        a1 = tracks_from_frames(frames[1])[1]
        a2 = tracks_from_frames(frames[2])[1]
        c1 = np.nanmean(a1.positions[:, 0], axis=0)
        c2 = rel.apply(np.nanmean(a2.positions[:, 0], axis=0))
        assert np.linalg.norm(c1 - c2) < 0.15, (c1, c2)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
