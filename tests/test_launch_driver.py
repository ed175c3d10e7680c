"""launch_pytest: a node killed mid-run is reported by launch (per-node launch file).

Its own module: launch_pytest runs one launch service at a time, so this function-scoped launch
must not share a module with the module-scoped pipeline launch."""
import signal
import time

import launch
from launch_support import include, launch_pytest  # noqa: E402
import pytest
from launch.actions import RegisterEventHandler  # noqa: E402
from launch.event_handlers import OnProcessExit  # noqa: E402

from kinect_bringup.graph import TOPICS  # noqa: E402
from ros_helpers import Probe  # noqa: E402

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]


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


