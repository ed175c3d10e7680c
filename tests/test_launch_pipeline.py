"""launch_pytest tests: pipeline.launch.py started as a user would, checked over real DDS.

They need the launch tooling (a system ROS 2, or the tooling built from ../shared/ros2 by
scripts/setup.sh); without it they skip with that reason.
"""
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest

launch_pytest = pytest.importorskip(
    'launch_pytest', reason='ROS 2 launch tooling not installed: no /opt/ros/<distro> and no '
    '../shared/ros2 to build it from (scripts/setup.sh builds it when ../shared/ros2 exists)')

import launch  # noqa: E402
from ament_index_python.packages import get_package_share_directory  # noqa: E402
from launch.actions import IncludeLaunchDescription  # noqa: E402
from launch.launch_description_sources import PythonLaunchDescriptionSource  # noqa: E402

from kinect_bringup.graph import TOPICS, load_params  # noqa: E402
from ros_helpers import Probe  # noqa: E402

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]

SHARE = get_package_share_directory('kinect_bringup')
SKELETON_TOPICS = {t: ty for t, ty in TOPICS.items() if ty.endswith('SkeletonArray')}
PIPELINE_TOPICS = dict(SKELETON_TOPICS)
PIPELINE_TOPICS['/viz/markers'] = TOPICS['/viz/markers']
PIPELINE_TOPICS.pop('/kinect/ground_truth')
NODES = ['driver', 'reliability', 'completion', 'optimizer', 'physics', 'viz']


def include(name, **args):
    return IncludeLaunchDescription(
        PythonLaunchDescriptionSource(os.path.join(SHARE, 'launch', name)),
        launch_arguments={k: str(v) for k, v in args.items()}.items())


@launch_pytest.fixture(scope='module')
def pipeline_launch():
    return launch.LaunchDescription([
        include('pipeline.launch.py', num_users=2, scenario='b'),
        launch_pytest.actions.ReadyToTest(),
    ])


@pytest.fixture(scope='module')
def probe():
    p = Probe(PIPELINE_TOPICS, name='launch_test_probe')
    yield p
    p.close()


@pytest.mark.launch(fixture=pipeline_launch)
def test_messages_flow_on_every_topic_at_expected_rates(probe):
    assert probe.wait_for(PIPELINE_TOPICS, count=5, timeout=90), \
        f'not every topic is flowing: {probe.counts()}'
    time.sleep(6.0)
    rates = {t: probe.rate(t, 5.0) for t in PIPELINE_TOPICS}
    # the driver captures at 30 Hz: judged on the capture stamps it puts on the frames
    msgs = [probe.message(t, i) for t, i in probe.indices('/kinect/skeletons')]
    stamps = sorted({m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in msgs})
    capture_hz = (len(stamps) - 1) / (stamps[-1] - stamps[0])
    assert 27.0 <= capture_hz <= 31.0, capture_hz
    # every stage keeps up (the bounds leave room for a busy 2-core CI machine)
    assert rates['/kinect/skeletons'] >= 24.0, rates
    for t in ('/kinect/skeletons_reliability', '/posture/completed', '/posture/reconstructed',
              '/character/skeletons'):
        assert rates[t] >= 15.0, (t, rates)
    assert rates['/viz/markers'] >= 5.0, rates
    last = probe.last('/posture/reconstructed')
    assert sorted(s.user_id for s in last.skeletons) == [1, 2]


@pytest.mark.launch(fixture=pipeline_launch)
def test_yaml_parameters_are_set_on_the_running_nodes(probe):
    for node in NODES:
        expected = load_params(node)
        assert expected, f'config/{node}.yaml has no parameters'
        got = probe.get_parameters(f'/{node}', list(expected))
        overridden = {'driver': {'num_users', 'scenario', 'source', 'seed', 'replay_file'},
                      'optimizer': {'method'}, 'physics': {'input_topic'}}.get(node, set())
        for k, v in expected.items():
            if k in overridden:
                continue
            assert got[k] == pytest.approx(v) if isinstance(v, float) else got[k] == v, (node, k)
    assert probe.get_parameters('/driver', ['num_users'])['num_users'] == 2  # launch argument


@pytest.mark.launch(fixture=pipeline_launch)
def test_parameter_changed_at_run_time_takes_effect(probe):
    assert probe.wait_for(['/viz/markers'], count=1, timeout=60)

    def raw_namespaces():
        probe.reset()
        assert probe.wait_for(['/viz/markers'], count=3, timeout=10)
        time.sleep(0.5)
        m = probe.last('/viz/markers')
        return {mk.ns for mk in m.markers if mk.ns.startswith('raw') and mk.action == 0}

    assert raw_namespaces(), 'raw skeleton layer not drawn'
    res = probe.set_parameter('/viz', 'show_raw', False)
    assert res.successful, res.reason
    time.sleep(0.5)
    assert not raw_namespaces(), 'raw layer still drawn after show_raw:=false'
    bad = probe.set_parameter('/optimizer', 'k', 100000)
    assert not bad.successful and bad.reason  # out-of-range sets are refused with a reason
    assert probe.set_parameter('/viz', 'show_raw', True).successful


# ---- `ros2 launch` and the one-process `pipeline`: same parameters, clean SIGINT exit ----------
def _params_of_running_graph(cmd, probe_name):
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            start_new_session=True, env=dict(os.environ))
    probe = Probe({'/viz/markers': TOPICS['/viz/markers']}, name=probe_name)
    try:
        ok = probe.wait_for(['/viz/markers'], count=3, timeout=150)
        params = {n: probe.get_parameters(f'/{n}') for n in NODES} if ok else None
    finally:
        probe.close()
        os.killpg(proc.pid, signal.SIGINT)
        try:
            out, _ = proc.communicate(timeout=40)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, _ = proc.communicate()
    assert ok, f'no /viz/markers from {cmd}:\n' + out.decode(errors='replace')[-3000:]
    return params, proc.returncode, out.decode(errors='replace')


@pytest.mark.skipif(shutil.which('ros2') is None, reason='ros2 CLI not installed')
def test_ros2_launch_and_pipeline_run_the_same_configuration():
    p_launch, rc_launch, out_launch = _params_of_running_graph(
        ['ros2', 'launch', 'kinect_bringup', 'pipeline.launch.py'], 'probe_launch')
    assert rc_launch == 0, out_launch[-3000:]  # clean exit on SIGINT
    assert 'Traceback' not in out_launch, out_launch[-3000:]
    p_pipe, rc_pipe, out_pipe = _params_of_running_graph(
        [sys.executable, '-m', 'kinect_bringup.pipeline'], 'probe_pipeline')
    assert rc_pipe == 0, out_pipe[-3000:]
    assert 'Traceback' not in out_pipe, out_pipe[-3000:]
    for node in NODES:
        assert p_launch[node] == p_pipe[node], node
