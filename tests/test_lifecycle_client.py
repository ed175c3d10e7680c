"""The launch files' lifecycle manager (skeleton_core.lifecycle_client.drive_to_active) over DDS:
a node started --managed, as launch starts it, is taken to active; one whose configure fails is
left unconfigured and the manager returns instead of retrying for ever."""
import os
import signal
import subprocess
import sys
import time

import pytest

rclpy = pytest.importorskip('rclpy')

from lifecycle_msgs.srv import GetState  # noqa: E402
from ros_helpers import Spinner  # noqa: E402
from skeleton_core.lifecycle_client import call_once, drive_to_active  # noqa: E402
from skeleton_core.rosnode import MANAGED_FLAG  # noqa: E402

pytestmark = pytest.mark.ros


def _start(module, ns, *params):
    return subprocess.Popen(
        [sys.executable, '-m', module, MANAGED_FLAG, '--ros-args', '-r', f'__ns:={ns}',
         *[a for p in params for a in ('-p', p)]],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)


@pytest.mark.parametrize('case', ['ok', 'refused'])
def test_drive_to_active(case, tmp_path):
    ns = f'/lcm{os.getpid()}{case}'
    if case == 'ok':
        proc, name = _start('kinect_driver.driver_node', ns), 'driver'
    else:   # no database: configure refused with one line
        proc, name = _start('pose_reconstruction.reconstruction_node', ns,
                            f'database:={tmp_path / "missing.npz"}'), 'reconstruction'
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    client = rclpy.create_node('lifecycle_manager_probe', context=ctx)
    spinner = Spinner(ctx, client)
    deadline = time.monotonic() + 120
    try:
        full = f'{ns}/{name}'
        result = drive_to_active(client, full, lambda: time.monotonic() > deadline)
        assert time.monotonic() < deadline, 'the manager did not return'
        get = client.create_client(GetState, f'{full}/get_state')
        state = None
        while state is None and time.monotonic() < deadline:
            reply = call_once(get, GetState.Request(), 2.0)
            state = reply.current_state.label if reply else None
        assert (result, state) == ((True, 'active') if case == 'ok' else (False, 'unconfigured'))
    finally:
        spinner.stop()
        client.destroy_node()
        rclpy.try_shutdown(context=ctx)
        os.killpg(proc.pid, signal.SIGINT)
        try:
            out = proc.communicate(timeout=30)[0].decode(errors='replace')
        except subprocess.TimeoutExpired:   # never left running for the modules after this one
            os.killpg(proc.pid, signal.SIGKILL)
            out = proc.communicate()[0].decode(errors='replace')
            pytest.fail(f'{name} did not stop within 30 s of SIGINT:\n{out[-2000:]}')
    assert proc.returncode == 0, out[-2000:]
    if case == 'refused':
        assert 'make build-db' in out or 'build_db' in out, out[-2000:]
