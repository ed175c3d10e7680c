"""Every node is a lifecycle node that configures from files: the constructor touches no file,
``on_configure`` loads by path and fails with one line naming the command that builds a missing
file, and the transitions work over real DDS (the ``~/change_state`` / ``~/get_state``
services that ``ros2 lifecycle`` and launch's LifecycleNode call)."""
import builtins
import io
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')

from rclpy.parameter import Parameter  # noqa: E402

from kinect_bringup.graph import NODES, node_class  # noqa: E402
from ros_helpers import Spinner, call_until_answered, wait_until  # noqa: E402
from skeleton_core.lifecycle_client import call_once  # noqa: E402
from skeleton_core.rosnode import MANAGED_FLAG, TransitionFailed, bring_up  # noqa: E402

pytestmark = pytest.mark.ros

# every parameter that names a file or folder, pointed at paths that do not exist
MISSING = '/nonexistent/kp_lifecycle'
FILE_PARAMS = {
    'driver': {'source': 'replay', 'replay_file': f'{MISSING}/in.mcap'},
    'completion': {'database': f'{MISSING}/db.npz'},
    'optimizer': {'database': f'{MISSING}/db.npz', 'sensor_correction': f'{MISSING}/c.npz',
                  'user_profile': 'nobody', 'profiles_dir': f'{MISSING}/profiles'},
    'reconstruction': {'database': f'{MISSING}/db.npz', 'sensor_correction': f'{MISSING}/c.npz',
                       'user_profile': 'nobody', 'profiles_dir': f'{MISSING}/profiles'},
    'control': {'world': f'{MISSING}/world.yaml'},
    'physics': {},
    'viz': {},
    'hri': {},
    'fusion': {},
    'reliability': {},
    'recorder': {},   # its output, in a temporary folder: made on configure, not before
}


def test_no_constructor_reads_or_writes_a_file(rclpy_context, monkeypatch, tmp_path):
    """Construct every node with its file parameters pointing nowhere while every way to open,
    create or load a file raises: nothing is touched before on_configure, which then fails with
    one line (the node stays unconfigured)."""
    assert set(FILE_PARAMS) == set(NODES)
    params = {**FILE_PARAMS, 'recorder': {'output': str(tmp_path / 'rec' / 'out.mcap')}}
    classes = {name: node_class(name) for name in NODES}   # imported before the trap is set
    touched = []

    # rclpy itself reads its own resources from the Python installation (type support, the
    # IDL grammar) the first time a message type is used, and the entry-point lookup of the
    # driver's sources reads the installed packages' metadata: allowed; any other path is not
    installation = tuple(str(p) for p in {sys.prefix, sys.base_prefix})
    search_path = set(sys.path)

    def trap(what, real):
        def f(*a, **k):
            path = str(a[0]) if a else ''
            if path.startswith(installation) or path in search_path or any(
                    m in path for m in ('.egg-info', '.dist-info', '.egg-link')):
                return real(*a, **k)
            touched.append((what, path))
            raise AssertionError(f'{what}({path!r}) in a constructor')
        return f
    for mod, attr in ((builtins, 'open'), (io, 'open'), (os, 'open'), (os, 'mkdir'),
                      (os, 'makedirs'), (os, 'listdir'), (os, 'scandir'), (os, 'stat'),
                      (np, 'load'), (np, 'save'), (np, 'savez')):
        monkeypatch.setattr(mod, attr, trap(f'{mod.__name__}.{attr}', getattr(mod, attr)))
    nodes = []
    try:
        for name, cls in classes.items():
            nodes.append(cls(context=rclpy_context, parameter_overrides=[
                Parameter(k, value=v) for k, v in params[name].items()]))
    finally:
        monkeypatch.undo()
        for n in nodes:
            assert n.lifecycle_state == 'unconfigured'
    try:
        assert touched == [], touched
        assert not (tmp_path / 'rec').exists()
        for n in nodes:
            if FILE_PARAMS[n.get_name()]:
                with pytest.raises(TransitionFailed) as e:
                    bring_up(n)
                assert '\n' not in str(e.value) and n.lifecycle_state == 'unconfigured'
                if 'database' in FILE_PARAMS[n.get_name()]:
                    assert 'make build-db' in str(e.value)
            elif n.get_name() == 'recorder':
                bring_up(n)
                assert (tmp_path / 'rec' / 'out.mcap').is_file()   # opened on configure
    finally:
        for n in nodes:
            n.destroy_node()


def test_a_default_correction_that_applies_but_is_missing_names_its_producer(
        rclpy_context, monkeypatch, tmp_path):
    """The correction is learned by `make build-correction`, never by the node: with the input
    declared to come from its tracker and no file, configure fails with that command."""
    import pose_reconstruction.correction as C
    from pose_reconstruction.reconstruction_node import ReconstructionNode
    monkeypatch.setattr(C, 'default_path', lambda tracker=C.UIPRMD_TRACKER: tmp_path / 'no.npz')
    node = ReconstructionNode(context=rclpy_context, parameter_overrides=[
        Parameter('sensor_correction', value='auto'),
        Parameter('input_tracker', value=C.UIPRMD_TRACKER)])
    try:
        with pytest.raises(TransitionFailed, match='make build-correction'):
            bring_up(node)
        assert not (tmp_path / 'no.npz').exists()     # nothing learned, nothing written
    finally:
        node.destroy_node()


@pytest.mark.slow
def test_transitions_over_dds_a_failed_configure_is_retried_after_a_fix(tmp_path):
    """A reconstruction process started --managed (as the launch file starts it) stays
    unconfigured; configure over DDS fails with one line while its database is missing; after
    the parameter names the default file, configure and activate succeed and the node
    reconstructs; deactivate silences it, cleanup and shutdown release it."""
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState, GetState
    from rcl_interfaces.srv import SetParameters
    from skeleton_data.database import default_path
    from skeleton_msgs.msg import SkeletonArray

    from skeleton_core.conversions import SkeletonFrame, frames_to_array_msg
    from skeleton_data.motions import builtin_clips

    assert default_path().is_file()   # (the session fixture built it)
    ns = f'/lc{os.getpid()}'
    proc = subprocess.Popen(
        [sys.executable, '-m', 'pose_reconstruction.reconstruction_node', MANAGED_FLAG,
         '--ros-args', '-r', f'__ns:={ns}', '-p', f'database:={tmp_path / "missing.npz"}',
         '-p', f'input_topic:={ns}/in', '-p', f'output_topic:={ns}/out'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    client = rclpy.create_node('lifecycle_client', context=ctx)
    got = []
    client.create_subscription(SkeletonArray, f'{ns}/out', got.append, 100)
    pub = client.create_publisher(SkeletonArray, f'{ns}/in', 100)
    spinner = Spinner(ctx, client)
    change = client.create_client(ChangeState, f'{ns}/reconstruction/change_state')
    get = client.create_client(GetState, f'{ns}/reconstruction/get_state')
    setp = client.create_client(SetParameters, f'{ns}/reconstruction/set_parameters')

    def state():
        return call_until_answered(get, GetState.Request(), 30).current_state.label

    def transition(tid, then):
        """Whether the transition succeeded; when its reply is lost (a fresh reply path not
        matched yet), whether the node reached ``then``: a transition is not repeated."""
        assert change.wait_for_service(timeout_sec=30)
        reply = call_once(change, ChangeState.Request(transition=Transition(id=tid)), 20)
        return reply.success if reply is not None else state() == then
    try:
        assert state() == 'unconfigured'
        assert not transition(Transition.TRANSITION_CONFIGURE, 'inactive')     # no database: refused
        assert state() == 'unconfigured'
        req = SetParameters.Request(parameters=[
            Parameter('database', value=str(default_path())).to_parameter_msg()])
        assert call_until_answered(setp, req, 30).results[0].successful
        assert transition(Transition.TRANSITION_CONFIGURE, 'inactive')
        assert state() == 'inactive'
        clip = builtin_clips()[0].positions
        ts = np.full(20, 2, np.uint8)

        def send(i):
            st = 1_000_000_000 + i * 33_333_333
            pub.publish(frames_to_array_msg(
                [SkeletonFrame(positions=clip[i % len(clip)], tracking_state=ts, user_id=1,
                               stamp_ns=st)], st, 'kinect_link'))
        for i in range(5):
            send(i)
            time.sleep(0.05)
        assert got == []                      # inactive: no input taken, nothing published
        assert transition(Transition.TRANSITION_ACTIVATE, 'active')
        assert state() == 'active'
        assert wait_until(lambda: pub.get_subscription_count() > 0, 20)
        i = 5
        deadline = time.monotonic() + 30
        while not got and time.monotonic() < deadline:
            send(i)
            i += 1
            time.sleep(0.05)
        assert got, 'no reconstruction while active'
        assert transition(Transition.TRANSITION_DEACTIVATE, 'inactive')
        assert wait_until(lambda: pub.get_subscription_count() == 0, 20)   # input released
        assert transition(Transition.TRANSITION_CLEANUP, 'unconfigured')
        assert state() == 'unconfigured'
        assert transition(Transition.TRANSITION_UNCONFIGURED_SHUTDOWN, 'finalized')
        assert state() == 'finalized'
    finally:
        spinner.stop()
        client.destroy_node()
        rclpy.shutdown(context=ctx)
        os.killpg(proc.pid, signal.SIGINT)
        try:
            out, _ = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, _ = proc.communicate()
    text = out.decode(errors='replace')
    errors = [ln for ln in text.splitlines() if '[ERROR]' in ln]
    assert len(errors) == 1 and 'make build-db' in errors[0], text[-3000:]
    assert 'Traceback' not in text, text[-3000:]
    assert proc.returncode == 0, text[-3000:]
