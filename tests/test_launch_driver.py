"""launch_pytest: a node killed mid-run is reported by launch (per-node launch file).

Its own module: launch_pytest runs one launch service at a time, so this function-scoped launch
must not share a module with the module-scoped pipeline launch."""
import os
import signal
import time

import launch
import launch_pytest  # make setup builds the launch tooling: these tests never skip
import pytest
from ament_index_python.packages import get_package_share_directory  # noqa: E402
from launch.actions import IncludeLaunchDescription, RegisterEventHandler  # noqa: E402
from launch.event_handlers import OnProcessExit  # noqa: E402
from launch.launch_description_sources import PythonLaunchDescriptionSource  # noqa: E402

from kinect_bringup.graph import TOPICS  # noqa: E402
from ros_helpers import Probe  # noqa: E402

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]
SHARE = get_package_share_directory('kinect_bringup')


def include(name, **args):
    return IncludeLaunchDescription(
        PythonLaunchDescriptionSource(os.path.join(SHARE, 'launch', name)),
        launch_arguments={k: str(v) for k, v in args.items()}.items())


EXITS = []


@launch_pytest.fixture
def driver_launch():
    EXITS.clear()
    return launch.LaunchDescription([
        include('driver.launch.py'),
        RegisterEventHandler(OnProcessExit(on_exit=lambda event, ctx: EXITS.append(
            (event.action.name, event.returncode)))),
        launch_pytest.actions.ReadyToTest(),
    ])


@pytest.mark.launch(fixture=driver_launch)
def test_node_killed_mid_run_is_reported_by_launch():
    import psutil
    probe = Probe({'/kinect/skeletons': TOPICS['/kinect/skeletons']}, name='kill_probe')
    try:
        assert probe.wait_for(['/kinect/skeletons'], count=10, timeout=60)
        me = psutil.Process()
        drivers = [p for p in me.children(recursive=True)
                   if any('kinect_driver' in part for part in p.cmdline())]
        assert drivers, 'driver process not found among launch children'
        for p in drivers:
            p.send_signal(signal.SIGKILL)
        deadline = time.monotonic() + 15
        while not EXITS and time.monotonic() < deadline:
            time.sleep(0.1)
        assert EXITS, 'launch did not report the process exit'
        assert EXITS[0][1] == -signal.SIGKILL
    finally:
        probe.close()


