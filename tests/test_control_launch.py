"""launch_pytest: pipeline.launch.py with control:=true world:=playground -- the control node sits
between the reconstruction and the physics (the physics tracks /control/target), checked over
real DDS."""
import os
import time

import launch
import launch_pytest  # make setup builds the launch tooling: these tests never skip
import pytest
from ament_index_python.packages import get_package_share_directory  # noqa: E402
from launch.actions import IncludeLaunchDescription  # noqa: E402
from launch.launch_description_sources import PythonLaunchDescriptionSource  # noqa: E402

from ros_helpers import Probe  # noqa: E402

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]

TOPICS = {'/posture/reconstructed': 'skeleton_msgs/msg/SkeletonArray',
          '/control/target': 'skeleton_msgs/msg/SkeletonArray',
          '/control/intention': 'skeleton_msgs/msg/Intention',
          '/control/markers': 'visualization_msgs/msg/MarkerArray',
          '/character/skeletons': 'skeleton_msgs/msg/SkeletonArray'}


@launch_pytest.fixture(scope='module')
def control_launch():
    share = get_package_share_directory('kinect_bringup')
    return launch.LaunchDescription([
        IncludeLaunchDescription(
            PythonLaunchDescriptionSource(os.path.join(share, 'launch', 'pipeline.launch.py')),
            launch_arguments={'control': 'true', 'world': 'playground', 'num_users': '1',
                              'viz': 'false'}.items()),
        launch_pytest.actions.ReadyToTest(),
    ])


@pytest.fixture(scope='module')
def probe():
    p = Probe(TOPICS, name='control_launch_probe')
    yield p
    p.close()


@pytest.mark.launch(fixture=control_launch)
def test_control_graph_flows_into_the_physics(probe):
    # (a fresh clone compiles the control and physics kernels on first use, both at once on
    # 2 cores: minutes, once; the numba cache serves every later start)
    assert probe.wait_for(TOPICS, count=5, timeout=300), f'not every topic flows: {probe.counts()}'
    phys = probe.get_parameters('/physics', ['input_topic', 'feature_world'])
    assert phys['input_topic'] == '/control/target'
    assert phys['feature_world'].endswith('worlds/playground.yaml')   # the same world file
    got = probe.get_parameters('/control', ['world', 'input_topic'])
    assert got == {'world': 'playground', 'input_topic': '/posture/reconstructed'}
    intent = probe.last('/control/intention')
    target = probe.last('/control/target')
    assert intent.user_id == target.skeletons[0].user_id
    assert {m.ns for m in probe.last('/control/markers').markers} & {'control_features',
                                                                    'control_contacts'}
    before = probe.counts()['/control/target']
    time.sleep(4.0)    # past the start-up (numba compile, first frames)
    rin, rout = probe.rate('/posture/reconstructed', 3.0), probe.rate('/control/target', 3.0)
    print(f'control keeps up: {rout:.1f} of {rin:.1f} Hz (benchmark figures, not asserted)')
    assert probe.counts()['/control/target'] - before >= 3, (rin, rout)   # still flowing
