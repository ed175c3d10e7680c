"""skeleton_core.compat: the Python side of the ROS 2 distro differences, checked on the distro the
suite runs on (CI runs it on Jazzy and on Kilted)."""
import importlib.metadata
import inspect
import os

import pytest

from skeleton_core import compat

# the rclpy major version of each distro's pinned wheels (requirements-<distro>.txt)
RCLPY_MAJOR = {'jazzy': 7, 'kilted': 9}


def test_localhost_discovery_per_distro():
    assert compat.localhost_discovery_env('humble') == {
        'ROS_LOCALHOST_ONLY': '1', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    for distro in ('jazzy', 'kilted', 'rolling', ''):
        assert compat.localhost_discovery_env(distro) == {
            'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_LOCALHOST_ONLY': None}
    env = {'ROS_DISTRO': 'Jazzy', 'ROS_LOCALHOST_ONLY': '1'}
    compat.apply_localhost_discovery(env)
    assert env == {'ROS_DISTRO': 'Jazzy', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    env = {'ROS_DISTRO': 'humble'}
    compat.apply_localhost_discovery(env)
    assert env['ROS_LOCALHOST_ONLY'] == '1'


def test_the_suite_runs_on_the_distro_it_says():
    """ROS_DISTRO (scripts/env.sh) and the rclpy actually imported agree: `ROS_DISTRO=kilted make
    test` really tests Kilted's wheels, not the other venv's."""
    distro = compat.ros_distro()
    assert distro, 'ROS_DISTRO is unset: run the suite with make test (scripts/env.sh sets it)'
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    if os.environ.get('KINECT_POSTURE_ROS', '').startswith('wheels:'):
        major = int(importlib.metadata.version('ros-rclpy').split('.')[0])
        assert major == RCLPY_MAJOR[distro], (distro, major)


def test_events_executor_spins_a_node_on_this_distro():
    rclpy = pytest.importorskip('rclpy')
    from rclpy.node import Node
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=int(os.environ['ROS_DOMAIN_ID']))
    try:
        ex = compat.events_executor(context=ctx)
        node = Node('compat_probe', context=ctx)
        ticks = []
        node.create_timer(0.01, lambda: ticks.append(1))
        ex.add_node(node)
        for _ in range(50):
            ex.spin_once(timeout_sec=0.05)
            if ticks:
                break
        assert ticks
        ex.shutdown()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_the_rclpy_api_the_nodes_use_is_there():
    """The calls whose signatures differ across rclpy versions and that the nodes and tests rely on."""
    rclpy = pytest.importorskip('rclpy')
    from rclpy.node import Node
    from rclpy.utilities import remove_ros_args
    assert 'domain_id' in inspect.signature(rclpy.init).parameters
    assert 'raw' in inspect.signature(Node.create_subscription).parameters
    assert remove_ros_args(args=['x', '--help', '--ros-args', '-p', 'a:=1']) == ['x', '--help']
