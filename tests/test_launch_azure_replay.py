"""launch_pytest: a recording of the Azure Kinect ROS driver (``ros2 bag record
/body_tracking_data /imu``; tests/azure_fake.py: three bodies entering and leaving, captures split
over messages, a joint missing) replays through ``ros2 launch kinect_bringup pipeline.launch.py
source:=replay replay_file:=BAG`` with nothing else set: every frame of every body is
reconstructed, even when the reconstruction is held up mid-replay for longer than its live queue
holds (a loaded machine), and the recording of the run declares the tracker ``azure_kinect_bt``.

Its own module: launch_pytest runs one launch service at a time."""
import os
import signal
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


HELD_S = 1.5   # 45 frames of the recording: over four times the reconstruction's live queue (10)


def _child(name: str) -> int:
    """The pid of this process's child (the launch's) whose command line names ``name``: only
    this test's own graph, never another run's."""
    for d in os.listdir('/proc'):
        if not d.isdigit():
            continue
        try:
            with open(f'/proc/{d}/stat') as f:
                ppid = int(f.read().rsplit(')', 1)[1].split()[1])
            with open(f'/proc/{d}/cmdline', 'rb') as f:
                cmd = f.read().replace(b'\0', b' ').decode(errors='replace')
        except (OSError, ValueError, IndexError):
            continue
        if ppid == os.getpid() and f'/{name} ' in cmd:
            return int(d)
    raise AssertionError(f'no {name} process started by this test')


def _hold(pid: int, seconds: float) -> None:
    """The process stopped for ``seconds``, as a loaded machine can hold a node up."""
    os.kill(pid, signal.SIGSTOP)
    try:
        time.sleep(seconds)
    finally:
        os.kill(pid, signal.SIGCONT)


@pytest.mark.launch(fixture=azure_replay)
def test_an_azure_kinect_recording_replays_through_the_pipeline():
    expected = A.expected_user_frames()
    deadline = time.monotonic() + 180
    # once the replay plays (its first frames recorded), the reconstruction is held up: the
    # frames the replay sends meanwhile wait for it instead of being lost
    reconstruction = _child('reconstruction')
    while time.monotonic() < deadline and not A.users_of(OUTPUT, '/kinect/skeletons'):
        time.sleep(0.1)
    _hold(reconstruction, HELD_S)
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
