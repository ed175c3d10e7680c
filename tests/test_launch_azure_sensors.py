"""launch_pytest: two Azure Kinects, ``ros2 launch kinect_bringup pipeline.launch.py sensors:=2
source:=azure_kinect`` against two fake Azure Kinect ROS drivers started in the namespaces
``/kinect_1`` and ``/kinect_2`` (tf_prefix ``kinect_k_``), each seeing the same people from its
own pose: each driver takes its camera's ``/kinect_k/body_tracking_data``, the fusion puts one
skeleton per person in ``world``, and the reconstruction rebuilds them.

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

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]

HERE = Path(__file__).resolve().parent
OUTPUT = Path(tempfile.mkdtemp(prefix='kp_launch_azure_sensors_')) / 'two.mcap'
POSES = ('0 0 0.8 0 0 0', '2.5 2.5 0.8 -90 0 0')   # front + side


def fake_driver(k):
    return ExecuteProcess(
        cmd=[sys.executable, str(HERE / 'fake_azure_driver.py'), '--pose', POSES[k - 1],
             '--tf-prefix', f'kinect_{k}_', '--wait-topic', 'skeletons', '--wait', '1',
             '--timeout', '120', '--ros-args', '-r', f'__ns:=/kinect_{k}'],
        output='screen')


@launch_pytest.fixture(scope='module')
def two_azure():
    return launch.LaunchDescription([
        include('pipeline.launch.py', sensors='2', source='azure_kinect',
                sensor_pose='; '.join(POSES), record=str(OUTPUT),
                physics='false', viz='false'),
        fake_driver(1), fake_driver(2),
        launch_pytest.actions.ReadyToTest(),
    ])


@pytest.mark.launch(fixture=two_azure)
def test_two_azure_kinects_are_fused_and_reconstructed():
    # the fakes play 150 captures each (5 s) once the graph is there
    # (until the last person has come and the fused stream has stopped growing for 3 s: on a
    # loaded machine a fake or a node may stall for seconds mid-way)
    deadline = time.monotonic() + 240
    last, still = -1, 0
    while time.monotonic() < deadline and still < 3:
        users = A.user_frames(A.users_of(OUTPUT, '/kinect/skeletons'))
        n = sum(users.values())
        still = still + 1 if n == last and len(users) >= 3 else 0
        last = n
        time.sleep(1.0)
    fused = A.users_of(OUTPUT, '/kinect/skeletons')
    rec = A.users_of(OUTPUT, '/posture/reconstructed')
    print('fused', A.user_frames(fused), 'reconstructed', A.user_frames(rec))
    # every person of both cameras' views, fused into one skeleton each in world: the three
    # people, never more than two at once (the cameras start a moment apart: a person seen by
    # one camera alone is a person too)
    assert len(fused) >= 3, A.user_frames(fused)
    per_stamp = {}
    for u, v in fused.items():
        for t in v:
            per_stamp[t] = per_stamp.get(t, 0) + 1
    assert max(per_stamp.values()) == 2
    n = sum(A.user_frames(fused).values())
    done = sum(A.expected_user_frames().values())
    assert 0.9 * done <= n <= 1.5 * done, (n, done)
    # in world: the floor at z = 0 (the cameras are 0.8 m up), the feet on it
    feet = [p[j, 2] for v in fused.values() for p in v.values() for j in (15, 19)]
    assert -0.1 < np.median(feet) < 0.15, np.median(feet)
    # reconstructed live, on a machine shared with the rest of the graph (two fake drivers, two
    # drivers, the fusion, the recorder): most frames (a frame the reconstruction is too late for
    # is dropped, as live); every replayed or processed frame is the other tests'
    assert sum(A.user_frames(rec).values()) >= 0.6 * n, (A.user_frames(rec), n)
    assert all(np.all(np.isfinite(p)) for v in rec.values() for p in v.values())
