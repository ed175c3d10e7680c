"""launch_pytest: ``ros2 launch kinect_bringup pipeline.launch.py source:=azure_kinect`` against a
fake Azure Kinect ROS driver (tests/fake_azure_driver.py: the driver's ``/body_tracking_data``
markers of three bodies entering and leaving): every capture of every body is reconstructed.

Its own module: launch_pytest runs one launch service at a time."""
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

import launch  # noqa: E402
from launch_support import include, launch_pytest  # noqa: E402
from launch.actions import ExecuteProcess  # noqa: E402

import azure_fake as A  # noqa: E402
from skeleton_core import tracker as T  # noqa: E402

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]

HERE = Path(__file__).resolve().parent
OUTPUT = Path(tempfile.mkdtemp(prefix='kp_launch_azure_live_')) / 'live.mcap'


@launch_pytest.fixture(scope='module')
def azure_live():
    return launch.LaunchDescription([
        include('pipeline.launch.py', source='azure_kinect', record=str(OUTPUT),
                physics='false', viz='false'),
        # the Azure Kinect ROS driver: starts once the reconstruction and the recorder read
        ExecuteProcess(cmd=[sys.executable, str(HERE / 'fake_azure_driver.py'), '--wait-topic',
                            '/kinect/skeletons', '--wait', '2', '--timeout', '120'],
                       output='screen'),
        launch_pytest.actions.ReadyToTest(),
    ])


@pytest.mark.launch(fixture=azure_live)
def test_the_pipeline_with_an_azure_kinect_reconstructs_every_body():
    expected = A.expected_user_frames()
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and \
            A.user_frames(A.users_of(OUTPUT, '/posture/reconstructed')) != expected:
        time.sleep(1.0)
    time.sleep(1.0)
    raw = A.users_of(OUTPUT, '/kinect/skeletons')
    rec = A.users_of(OUTPUT, '/posture/reconstructed')
    assert A.user_frames(raw) == expected, A.user_frames(raw)
    assert A.user_frames(rec) == expected, A.user_frames(rec)
    assert {u: sorted(v) for u, v in rec.items()} == {u: sorted(v) for u, v in raw.items()}
    assert all(np.all(np.isfinite(p)) for v in rec.values() for p in v.values())
    assert T.from_bag(OUTPUT) == 'azure_kinect_bt'
