"""Skeleton/SkeletonArray published by one process and received by another over real DDS."""
import os
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

from skeleton_msgs.msg import Skeleton, SkeletonArray  # noqa: E402

from skeleton_core.conversions import frames_from_array_msg  # noqa: E402

PUBLISHER = textwrap.dedent('''
    import sys, time, numpy as np, rclpy
    from skeleton_msgs.msg import SkeletonArray
    from skeleton_core.conversions import SkeletonFrame, frames_to_array_msg
    from skeleton_core.model import standard_body
    rclpy.init()
    node = rclpy.create_node('roundtrip_publisher')
    pub = node.create_publisher(SkeletonArray, '/test/skeletons', 10)
    frames = []
    for uid in (3, 7):
        rng = np.random.default_rng(uid)
        q = rng.normal(size=(20, 4)); q /= np.linalg.norm(q, axis=1, keepdims=True)
        frames.append(SkeletonFrame(positions=standard_body().rest_positions() + uid,
                                    tracking_state=(np.arange(20) % 3).astype(np.uint8),
                                    reliability=np.linspace(0, 1, 20).astype(np.float32),
                                    orientations=q, user_id=uid, stamp_ns=1234567890123 + uid,
                                    frame_id='kinect_link'))
    msg = frames_to_array_msg(frames, 1234567890123, 'kinect_link')
    deadline = time.time() + 20
    while time.time() < deadline:
        pub.publish(msg)
        rclpy.spin_once(node, timeout_sec=0.1)
    node.destroy_node(); rclpy.shutdown()
''')


def test_skeleton_array_crosses_dds_between_processes(rclpy_context):
    proc = subprocess.Popen([sys.executable, '-c', PUBLISHER], env=dict(os.environ),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        node = rclpy.create_node('roundtrip_subscriber', context=rclpy_context)
        got = []
        node.create_subscription(SkeletonArray, '/test/skeletons', got.append, 10)
        from rclpy.executors import SingleThreadedExecutor
        ex = SingleThreadedExecutor(context=rclpy_context)
        ex.add_node(node)
        deadline = time.time() + 15
        while not got and time.time() < deadline and proc.poll() is None:
            ex.spin_once(timeout_sec=0.1)
        assert got, 'no SkeletonArray received over DDS: ' + (
            proc.stdout.read().decode() if proc.poll() is not None else 'publisher still running')
        msg = got[0]
        assert msg.header.frame_id == 'kinect_link'
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1234, 567890123)
        frames = frames_from_array_msg(msg)
        assert [f.user_id for f in frames] == [3, 7]
        from skeleton_core.model import standard_body
        for f in frames:
            assert np.allclose(f.positions, standard_body().rest_positions() + f.user_id)
            assert list(f.tracking_state) == [j % 3 for j in range(20)]
            assert np.allclose(f.reliability, np.linspace(0, 1, 20))
            assert f.stamp_ns == 1234567890123 + f.user_id
            rng = np.random.default_rng(f.user_id)
            q = rng.normal(size=(20, 4))
            assert np.allclose(f.orientations, q / np.linalg.norm(q, axis=1, keepdims=True))
        assert Skeleton.NUM_JOINTS == 20 and Skeleton.TRACKED == 2 and Skeleton.JOINT_FOOT_RIGHT == 19
        ex.shutdown()
        node.destroy_node()
    finally:
        proc.terminate()
        proc.wait(timeout=10)
