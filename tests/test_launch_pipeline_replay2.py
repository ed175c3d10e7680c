"""launch_pytest: ``pipeline.launch.py sensors:=2 source:=replay replay_file:="a.mcap; b.mcap"``
with its drivers: two bags of one person seen from the front and from the side (the sensor
model's views, each bag in its sensor's frame ``kinect_k_link``) replay in ``/kinect_1`` and
``/kinect_2``; every node becomes active and the fused skeletons (in ``world``) are reconstructed.

Its own module: launch_pytest runs one launch service at a time."""
import tempfile
from pathlib import Path

import pytest

import launch  # noqa: E402
from launch_support import include, launch_pytest  # noqa: E402

from skeleton_core.bagio import BagWriter  # noqa: E402
from skeleton_core.cdr import SKELETON_ARRAY, frames_to_cdr  # noqa: E402
from skeleton_core.conversions import SkeletonFrame  # noqa: E402
from skeleton_core.tf import default_sensor_poses  # noqa: E402
from skeleton_eval.clips import toy_clip  # noqa: E402
from skeleton_eval.sensor_model import SensorModel  # noqa: E402

from ros_helpers import Probe  # noqa: E402

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]
SKELETONS = 'skeleton_msgs/msg/SkeletonArray'
TOPICS = {'/kinect_1/skeletons': SKELETONS, '/kinect_2/skeletons': SKELETONS,
          '/kinect/skeletons': SKELETONS, '/posture/reconstructed': SKELETONS}
NODES = ('/kinect_1/driver', '/kinect_2/driver', '/fusion', '/reconstruction')
WORK = Path(tempfile.mkdtemp(prefix='kp_launch_replay2_'))
BAGS = [WORK / 'kinect_1.mcap', WORK / 'kinect_2.mcap']
SECONDS = 150   # longer than the graph takes to come up on a loaded machine: no loop needed


def _write_bags():
    """The same person seen by the launch's default two sensors (front + side), one bag each."""
    first, second = default_sensor_poses(2)
    views = [None, first.inverse() * second]
    model = SensorModel(seed=5)
    clip = toy_clip(seconds=SECONDS)
    for k, (path, view) in enumerate(zip(BAGS, views)):
        kw = {} if view is None else {'view': view}
        s = model.corrupt(clip, 'a', seed=5, **kw)
        frame = f'kinect_{k + 1}_link'
        with BagWriter(path) as bag:
            for i in range(len(s)):
                stamp = int(s.stamps_ns[i]) + 1_700_000_000_000_000_000
                f = SkeletonFrame(positions=s.positions[i], tracking_state=s.tracking_state[i],
                                  user_id=1, stamp_ns=stamp, frame_id=frame)
                bag.write_raw('/kinect/skeletons', frames_to_cdr([f], stamp, frame), stamp,
                              SKELETON_ARRAY)


@launch_pytest.fixture
def two_bag_pipeline():
    _write_bags()
    return launch.LaunchDescription([
        include('pipeline.launch.py', sensors='2', source='replay',
                replay_file='; '.join(str(b) for b in BAGS),
                physics='false', viz='false'),
        launch_pytest.actions.ReadyToTest(),
    ])


@pytest.mark.launch(fixture=two_bag_pipeline)
def test_sensors_2_replays_two_bags_fused_and_reconstructed():
    from lifecycle_msgs.srv import GetState
    probe = Probe(TOPICS, name='pipeline_replay2_probe', keep=200)
    try:
        assert probe.wait_for(TOPICS, count=20, timeout=120), probe.counts()
        states = {n: probe._call(GetState, f'{n}/get_state', GetState.Request(),
                                 30).current_state.label for n in NODES}
        assert set(states.values()) == {'active'}, states
        for k in (1, 2):   # each driver replays its own bag, in its sensor's frame
            msgs = probe.messages_of(f'/kinect_{k}/skeletons')
            assert {m.header.frame_id for m in msgs} == {f'kinect_{k}_link'}
        for topic in ('/kinect/skeletons', '/posture/reconstructed'):
            msgs = probe.messages_of(topic)
            assert {m.header.frame_id for m in msgs} == {'world'}, topic
            assert all(len(m.skeletons) == 1 for m in msgs[-10:]), topic
        fused = probe.messages_of('/kinect/skeletons')
        feet = [s.positions[j].z for m in fused[-10:] for s in m.skeletons for j in (15, 19)]
        assert min(feet) > -0.2 and max(feet) < 0.4, feet
    finally:
        probe.close()
