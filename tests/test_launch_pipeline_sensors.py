"""launch_pytest: ``pipeline.launch.py sensors:=2`` with its drivers, as a user starts it (the
synthetic source, no other argument): both drivers, the fusion, the reconstruction, the physics
and viz become active, and the two sensors' skeletons come out fused in ``world`` and
reconstructed. The pipeline's own one-sensor ``sensor_pose`` default used to reach the included
driver launch and stop it at once ("sensor_pose has 1 pose(s) for sensors:=2").

Its own module: launch_pytest runs one launch service at a time."""

import pytest

import launch  # noqa: E402
from launch_support import include, launch_pytest  # noqa: E402

from ros_helpers import Probe  # noqa: E402

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]
SKELETONS = 'skeleton_msgs/msg/SkeletonArray'
TOPICS = {'/kinect_1/skeletons': SKELETONS, '/kinect_2/skeletons': SKELETONS,
          '/kinect/skeletons': SKELETONS, '/posture/reconstructed': SKELETONS,
          '/character/skeletons': SKELETONS}
NODES = ('/kinect_1/driver', '/kinect_2/driver', '/fusion', '/reconstruction', '/physics', '/viz')


def node_states(probe, nodes):
    """The lifecycle state label of each node (its ``get_state`` service)."""
    from lifecycle_msgs.srv import GetState
    return {n: probe._call(GetState, f'{n}/get_state', GetState.Request(), 30).current_state.label
            for n in nodes}


@launch_pytest.fixture
def two_sensor_pipeline():
    return launch.LaunchDescription([
        include('pipeline.launch.py', sensors='2'),
        launch_pytest.actions.ReadyToTest(),
    ])


@pytest.mark.launch(fixture=two_sensor_pipeline)
def test_sensors_2_starts_every_node_and_fuses_both_drivers():
    probe = Probe(TOPICS, name='pipeline_sensors_probe', keep=200)
    try:
        assert probe.wait_for(TOPICS, count=20, timeout=120), probe.counts()
        states = node_states(probe, NODES)
        assert set(states.values()) == {'active'}, states
        for topic in ('/kinect_1/skeletons', '/kinect_2/skeletons'):
            frames = {m.header.frame_id for m in probe.messages_of(topic)}
            assert frames == {topic.split('/')[1] + '_link'}, (topic, frames)
        for topic in ('/kinect/skeletons', '/posture/reconstructed', '/character/skeletons'):
            msgs = probe.messages_of(topic)
            assert {m.header.frame_id for m in msgs} == {'world'}, topic
            assert all(len(m.skeletons) == 1 for m in msgs[-10:]), topic
        # in world: the floor at z = 0 (the sensors are 0.8 m up), the fused feet near it
        fused = probe.messages_of('/kinect/skeletons')
        feet = [s.positions[j].z for m in fused[-10:] for s in m.skeletons for j in (15, 19)]
        assert min(feet) > -0.2 and max(feet) < 0.4, feet
    finally:
        probe.close()
