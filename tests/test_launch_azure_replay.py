"""launch_pytest: a recording of the Azure Kinect ROS driver (``ros2 bag record
/body_tracking_data /imu``; tests/azure_fake.py: three bodies entering and leaving, captures split
over messages, a joint missing) replays through ``ros2 launch kinect_bringup pipeline.launch.py
source:=replay replay_file:=BAG`` with nothing else set: every frame of every body is
reconstructed, and the recording of the run declares the tracker ``azure_kinect_bt``.

Its own module: launch_pytest runs one launch service at a time."""
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

import launch  # noqa: E402
from launch_support import include, launch_pytest  # noqa: E402

import azure_fake as A  # noqa: E402
from skeleton_core import tracker as T  # noqa: E402

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]

WORK = Path(tempfile.mkdtemp(prefix='kp_launch_azure_replay_'))
INPUT, OUTPUT = WORK / 'body_tracking.mcap', WORK / 'replayed.mcap'


@launch_pytest.fixture(scope='module')
def azure_replay():
    A.write_bag(INPUT)
    return launch.LaunchDescription([
        include('pipeline.launch.py', source='replay', replay_file=str(INPUT),
                record=str(OUTPUT), physics='false',
                viz='false'),
        launch_pytest.actions.ReadyToTest(),
    ])


@pytest.mark.launch(fixture=azure_replay)
def test_an_azure_kinect_recording_replays_through_the_pipeline():
    expected = A.expected_user_frames()
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and \
            A.user_frames(A.users_of(OUTPUT, '/posture/reconstructed')) != expected:
        time.sleep(1.0)
    time.sleep(1.0)
    raw = A.users_of(OUTPUT, '/kinect/skeletons')
    rec = A.users_of(OUTPUT, '/posture/reconstructed')
    assert A.user_frames(raw) == expected, A.user_frames(raw)
    assert A.user_frames(rec) == expected, A.user_frames(rec)     # every frame of every body
    assert all(np.all(np.isfinite(p)) for v in rec.values() for p in v.values())
    assert T.from_bag(OUTPUT) == 'azure_kinect_bt'
