"""`ros2 launch` and the one-process `pipeline`, started as a user starts them: both give every
node the same parameters, and both exit cleanly (code 0, no traceback) on SIGINT.

Its own module, and each graph on a DDS domain of its own: a graph still running or shutting down
elsewhere in the suite (the launch_pytest fixtures) must not answer for the one under test — that
made the probe see markers at once and interrupt `ros2 launch` while its nodes were still importing.
"""
import os
import shutil
import signal
import subprocess
import sys

import pytest

import domains  # noqa: E402  (tests/domains.py)

from kinect_bringup.graph import TOPICS
from ros_helpers import Probe

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]

NODES = ['driver', 'reconstruction', 'physics', 'viz']  # the default graph (fused reconstruction)
# every node has produced output once these flow: the graph is fully up
READY = ['/posture/completed', '/posture/reconstructed', '/character/skeletons', '/viz/markers']


def _private_domain(offset: int) -> int:
    # claimed: no other suite on this machine has it (tests/domains.py)
    return domains.claim(int(os.environ.get('ROS_DOMAIN_ID', '0')) + offset)


def _params_of_running_graph(cmd, probe_name, domain):
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain))
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            start_new_session=True, env=env)
    probe = Probe({t: TOPICS[t] for t in READY}, name=probe_name, domain_id=domain)
    try:
        ok = probe.wait_for(READY, count=3, timeout=150)
        params = {n: probe.get_parameters(f'/{n}') for n in NODES} if ok else None
        counts = probe.counts()
    finally:
        probe.close()
        os.killpg(proc.pid, signal.SIGINT)
        try:
            out, _ = proc.communicate(timeout=40)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, _ = proc.communicate()
        domains.release(domain)   # the graph is gone: the domain is free for others
    text = out.decode(errors='replace')
    assert ok, f'not every output flowed from {cmd} ({counts}):\n' + text[-3000:]
    return params, proc.returncode, text


def test_ros2_launch_and_pipeline_run_the_same_configuration():
    # make setup installs the ros2 CLI (system ROS 2, or built from third_party/ros2): never skipped
    assert shutil.which('ros2'), 'the ros2 command line is not on the PATH: make setup, source scripts/env.sh'
    p_launch, rc_launch, out_launch = _params_of_running_graph(
        ['ros2', 'launch', 'kinect_bringup', 'pipeline.launch.py'], 'probe_launch',
        _private_domain(37))
    assert rc_launch == 0, out_launch[-3000:]  # clean exit on SIGINT
    assert 'Traceback' not in out_launch, out_launch[-3000:]
    p_pipe, rc_pipe, out_pipe = _params_of_running_graph(
        [sys.executable, '-m', 'kinect_bringup.pipeline'], 'probe_pipeline', _private_domain(61))
    # the default executor: rclpy's EventsExecutor where it exists (Jazzy, Kilted). It spins in
    # C++, where Python's signal handlers never run; Ctrl-C must still stop it cleanly (it ran
    # on, past Ctrl-C and --duration, until the pipeline spun it in slices)
    assert rc_pipe == 0, out_pipe[-3000:]
    assert 'Traceback' not in out_pipe and '[FATAL]' not in out_pipe, out_pipe[-3000:]
    assert '[pipeline] stopped' in out_pipe, out_pipe[-3000:]
    assert ('events executor' if _has_events_executor() else 'single executor') in out_pipe, \
        out_pipe[-3000:]
    for node in NODES:
        assert p_launch[node] == p_pipe[node], node


def _has_events_executor() -> bool:
    try:
        from rclpy.experimental import EventsExecutor  # noqa: F401
    except ImportError:
        return False
    return True


def test_pipeline_on_the_single_threaded_executor_flows_and_stops_on_sigint():
    """`pipeline --executor single` (rclpy's SingleThreadedExecutor, the default before the
    events executor; still offered): every output flows, SIGINT stops it cleanly."""
    _, rc, out = _params_of_running_graph(
        [sys.executable, '-m', 'kinect_bringup.pipeline', '--executor', 'single'],
        'probe_single', _private_domain(83))
    assert rc == 0, out[-3000:]
    assert 'Traceback' not in out and '[FATAL]' not in out, out[-3000:]
    assert '[pipeline] stopped' in out and 'single executor' in out, out[-3000:]
