"""launch_pytest: the graph split across machines as a lab runs it, here two
launches on one machine, one DDS domain: ``driver.launch.py sensors:=2 sensor:=k`` for k = 1, 2
(the sensor PCs: one driver each, in /kinect_k, its frame on TF) and ``pipeline.launch.py sensors:=2
drivers:=false`` (the other PC: fusion, reconstruction). The two drivers' skeletons are fused
into one per person in ``world`` on /kinect/skeletons, and the reconstruction (unchanged) turns
them into /posture/reconstructed in ``world``.

Its own module: launch_pytest runs one launch service at a time."""
import time

import pytest

import launch  # noqa: E402
from launch_support import include, launch_pytest  # noqa: E402

from ros_helpers import Probe  # noqa: E402

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]
SKELETONS = 'skeleton_msgs/msg/SkeletonArray'
TOPICS = {'/kinect_1/skeletons': SKELETONS, '/kinect_2/skeletons': SKELETONS,
          '/kinect/skeletons': SKELETONS, '/posture/reconstructed': SKELETONS}


@launch_pytest.fixture
def split_graph():
    return launch.LaunchDescription([
        # the two sensor PCs, one driver each, with its frame on TF
        include('driver.launch.py', sensors=2, sensor=1, scenario='b', num_users=2),
        include('driver.launch.py', sensors=2, sensor=2, scenario='b', num_users=2),
        # the other PC: no drivers, no frames of its own (they come with the drivers)
        include('pipeline.launch.py', sensors=2, drivers='false', physics='false', viz='false'),
        launch_pytest.actions.ReadyToTest(),
    ])


@pytest.mark.launch(fixture=split_graph)
def test_two_sensors_fused_in_world_reach_the_reconstruction():
    # keep: every message of the test's seconds (none dropped from the front while it reads)
    probe = Probe(TOPICS, name='fusion_launch_probe', keep=5000)
    try:
        assert probe.wait_for(TOPICS, count=30, timeout=90), probe.counts()
        probe.reset()
        assert probe.wait_for(TOPICS, count=30, timeout=20), probe.counts()
        time.sleep(0.5)
        got = {topic: probe.messages_of(topic) for topic in TOPICS}   # one snapshot each

        def stamps_of(msgs):
            return [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in msgs]
        sensor1 = set(stamps_of(got['/kinect_1/skeletons']))
        for topic in ('/kinect/skeletons', '/posture/reconstructed'):
            msgs = got[topic]
            assert {m.header.frame_id for m in msgs} == {'world'}, topic
            # the two people once each (four views), stable ids
            assert {len(m.skeletons) for m in msgs[-10:]} == {2}, topic
            assert len({s.user_id for m in msgs[-10:] for s in m.skeletons}) == 2, topic
        fused = got['/kinect/skeletons']
        # one fused frame per capture of sensor 1, stamped with it (sensor 2's only while sensor 1
        # delivered nothing for 1/3 s: a loaded machine): increasing, not one per message of
        # either sensor (the probe itself may miss a message on a loaded machine: the bounds)
        stamps = stamps_of(fused)
        assert stamps == sorted(set(stamps))
        window = [s for s in stamps if min(sensor1) <= s <= max(sensor1)]
        ours = set(window) & sensor1
        assert len(ours) >= 0.6 * len(window), (len(ours), len(window), len(sensor1))
        assert len(window) <= 1.1 * len(sensor1) + 2, (len(window), len(sensor1))
        # in world: the floor at z = 0 (the sensors are 0.8 m up): the feet near it
        feet = [s.positions[j].z for m in fused[-10:] for s in m.skeletons for j in (15, 19)]
        assert min(feet) > -0.2 and max(feet) < 0.4, feet
    finally:
        probe.close()
