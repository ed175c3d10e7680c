"""The documented `ros2 run` commands no other test runs, run for real as a user types them (the
installed executable, from a scratch directory whose out/ and cache/ hold the files the lines
name), shortened through the command's own options where the documented run takes minutes:
exit code 0, no traceback, and what the command promises (its figures printed, its files written).
The two documented nodes (`physics`, `control` with the page's `--ros-args`) are started for a few
seconds over DDS, answer for their parameters and stop cleanly on Ctrl-C.

tests/test_documented_commands.py maps every documented executable to the tests that run it for
real (these and the ones of other modules) and fails for one without.
"""
import json
import os
import re
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg')

sys.path.insert(0, str(Path(__file__).parent))
import domains  # noqa: E402  (tests/domains.py)

pytestmark = [pytest.mark.ros, pytest.mark.timeout(900)]

ROOT = Path(__file__).resolve().parents[1]


def _capture_json(path: Path, frames: int = 20):
    """An Azure Kinect Body Tracking SDK offline_processor JSON of one person standing."""
    from skeleton_core.model import standard_body
    from skeleton_data import k4abt as K
    p = standard_body().rest_positions() * np.array([-1.0, -1.0, 1.0]) + [2.5, 0.0, -0.8]
    k = K.k4abt_from_model(p) @ K.camera_to_sensor()
    body = {'body_id': 1, 'joint_positions': (k * 1000).tolist(),
            'joint_orientations': [[1, 0, 0, 0]] * 32, 'confidence_levels': [K.CONF_MEDIUM] * 32}
    path.write_text(json.dumps({
        'k4abt_sdk_version': '1.1.2', 'joint_names': list(K.JOINTS),
        'frames': [{'frame_id': i, 'num_bodies': 1, 'timestamp_usec': 1000 + 33333 * i,
                    'bodies': [body]} for i in range(frames)]}))


def _two_sensor_bags(first: Path, second: Path, seconds: float = 8.0):
    """One recording per sensor of one person walking round a loop (the sensor model), the second
    sensor at calibrate_extrinsics --synthetic's view of the first (2.5 m ahead, 2.5 m aside,
    turned -90 deg)."""
    from skeleton_core.bagio import BagWriter
    from skeleton_core.cdr import SKELETON_ARRAY, frames_to_cdr
    from skeleton_core.conversions import SkeletonFrame
    from skeleton_core.tf import Transform
    from skeleton_eval.extrinsics import synthetic_tracks
    view = Transform.from_xyz_ypr(2.5, 2.5, 0.0, yaw=-90.0)
    tracks = synthetic_tracks(view, seed=3, duration_s=seconds)[:2]
    for path, track, frame in ((first, tracks[0], 'kinect_1_link'),
                               (second, tracks[1], 'kinect_2_link')):
        with BagWriter(path) as bag:
            for i, stamp in enumerate(int(t) for t in track.stamps_ns):
                f = SkeletonFrame(positions=track.positions[i], tracking_state=track.tracking_state[i],
                                  user_id=1, stamp_ns=stamp, frame_id=frame)
                bag.write_raw('/kinect/skeletons', frames_to_cdr([f], stamp, frame), stamp,
                              SKELETON_ARRAY)


def _workspace(work: Path) -> Path:
    from test_launch_replay import _write_input   # a short sensor-model recording (3 s)
    (work / 'out').mkdir()
    _write_input(work / 'out' / 'demo.mcap')
    _capture_json(work / 'capture.json')
    _two_sensor_bags(work / 'kinect1.mcap', work / 'kinect2.mcap')
    return work


def _bag_topics(path: Path):
    from skeleton_core.bagio import read_messages
    counts = {}
    for m in read_messages(path, decode=False):
        counts[m.topic] = counts.get(m.topic, 0) + 1
    return counts


def _process_bag_check(work, out):
    topics = _bag_topics(work / 'out' / 'processed.mcap')
    assert topics.get('/posture/reconstructed', 0) >= 60, topics
    assert topics.get('/character/skeletons', 0) >= 60, topics   # --physics
    assert re.search(r'process_bag: \d+ frames in', out) and 'MPJPE' in out, out[-1500:]


def _report_check(work, out):
    report = json.loads((work / 'out' / 'm01.json').read_text())
    assert report.get('frames', 0) >= 60, report


def _azure_check(work, out):
    from skeleton_core import tracker as T
    bag = work / 'cache' / 'capture.mcap'
    assert _bag_topics(bag).get('/kinect/skeletons') == 20
    assert T.from_bag(bag) == 'azure_kinect_bt'


def _extrinsics_check(work, out):
    assert re.search(r'^seed 3: +[\d.]+ cm +[\d.]+ deg', out, re.M), out[-2000:]
    from skeleton_core.tf import load_transforms   # the file the launch files' extrinsics:= load
    assert 'kinect_2_link' in {c for _, c, _ in load_transforms(work / 'cache' / 'extrinsics.yaml')}


def _extrinsics_from_bags_check(work, out):
    from skeleton_core.tf import Transform, load_transforms
    poses = {c: t for _, c, t in load_transforms(work / 'cache' / 'extrinsics_bags.yaml')}
    # the second sensor's world pose: the first's default (0.8 m up) times the view it was given
    want = Transform.from_xyz_ypr(0.0, 0.0, 0.8) * Transform.from_xyz_ypr(2.5, 2.5, 0.0, yaw=-90.0)
    err = np.linalg.norm(poses['kinect_2_link'].translation - want.translation)
    assert err < 0.1, (poses['kinect_2_link'], out[-2000:])


def _bench_check(work, out):
    results = json.loads((work / 'out' / 'bench' / 'bench.json').read_text())['results']
    assert results and (work / 'out' / 'bench' / 'bench.md').stat().st_size > 0, out[-2000:]


def _figures(pattern):
    def check(work, out):
        assert re.search(pattern, out, re.M), out[-2000:]
    return check


def _files(*names, pattern=None):
    def check(work, out):
        for n in names:
            assert (work / n).is_file() and (work / n).stat().st_size > 0, \
                f'{n} not written\n' + out[-1500:]
        if pattern:
            assert re.search(pattern, out, re.M), out[-2000:]
    return check


# id: (pkg, exe, the documented line's arguments shortened where it runs long, the check of its
# promise); the id is the one tests/test_documented_commands.py's table names
COMMANDS = {   # (longest first: two run at a time)
    'bench_physics': ('physics_sim', 'bench_physics',
                      '--rtf-only --quick --frames 10 --out out/bench_physics.json',
                      _files('out/bench_physics.json', pattern=r'RTF .* wall +[\d.]+')),
    'bench': ('kinect_experiments', 'bench',
              '--users 1 --modes processes --sensors 1 --seconds 2 --warmup 1 --skip-bag '
              '--no-physics --out out/bench', _bench_check),
    'demo_control': ('performance_control', 'demo_control',
                     '--scenes rope,water --seconds 1 --out out',
                     _files('out/control_demo.png', 'out/control_demo.mcap',
                            pattern=r'imitating +[\d.]+ %')),
    'bench_control': ('performance_control', 'bench_control', '--performers 1 --skip-physics',
                      _figures(r'recognised within 0\.5 s: [\d.]+ %')),
    'process_bag': ('kinect_bringup', 'process_bag',
                    'out/demo.mcap --out out/processed.mcap --method C --physics --no-progress',
                    _process_bag_check),
    'calibrate_extrinsics': ('kinect_bringup', 'calibrate_extrinsics',
                             '--synthetic --seeds 3 --seconds 4 --out cache/extrinsics.yaml',
                             _extrinsics_check),
    'calibrate_extrinsics_bags': ('kinect_bringup', 'calibrate_extrinsics',
                                  'kinect1.mcap kinect2.mcap --out cache/extrinsics_bags.yaml',
                                  _extrinsics_from_bags_check),
    'bench_hri': ('viz', 'bench_hri', '--frames 3', _figures(r'6 character\(s\): [\d.]+ ms')),
    'bench_reconstruction': ('pose_reconstruction', 'bench_reconstruction',
                             '--frames 10 --quick --source synthetic',
                             _figures(r'^C stochastic \(paper\) +[\d.]+')),
    'process_bag_report': ('kinect_bringup', 'process_bag',
                           'out/demo.mcap --method A --report out/m01.json --no-progress',
                           _report_check),
    'import_azure_json': ('skeleton_data', 'import_azure_json',
                          'capture.json --out cache/capture.mcap', _azure_check),
}


def _executable(pkg, exe):
    from ament_index_python.packages import get_package_prefix
    return [sys.executable, os.path.join(get_package_prefix(pkg), 'lib', pkg, exe)]


def _env(domain):
    return dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1',
                KINECT_POSTURE_CACHE=str(ROOT / 'cache'))


def _run(work, key, timeout=600):
    pkg, exe, args, _ = COMMANDS[key]
    domain = domains.claim(20 + abs(hash(key)) % 60)
    t0 = time.monotonic()
    try:
        res = subprocess.run(_executable(pkg, exe) + args.split(), cwd=work,
                             env=_env(domain), capture_output=True, text=True, timeout=timeout)
        return res.returncode, res.stdout + res.stderr, time.monotonic() - t0
    except subprocess.TimeoutExpired as e:   # this command fails, the others still run
        out = ''.join(x.decode(errors='replace') if isinstance(x, bytes) else x
                      for x in (e.stdout or '', e.stderr or ''))
        return None, f'still running after {timeout} s\n{out}', timeout
    finally:
        domains.release(domain)


@pytest.fixture(scope='module')
def runs(request, tmp_path_factory):
    """The selected commands (`-k` selects some), two at a time (2 cores)."""
    keys = [item.callspec.params['key'] for item in request.session.items
            if item.module is request.module and getattr(item, 'callspec', None)
            and 'key' in item.callspec.params]
    work = _workspace(tmp_path_factory.mktemp('documented_runs'))
    with ThreadPoolExecutor(max_workers=2) as pool:
        return work, dict(zip(keys, pool.map(lambda k: _run(work, k), keys)))


@pytest.mark.parametrize('key', list(COMMANDS))
def test_documented_command_runs(runs, key):
    work, results = runs
    rc, out, took = results[key]
    pkg, exe, args, check = COMMANDS[key]
    line = f'ros2 run {pkg} {exe} {args}'
    print(f'{line}: {took:.1f} s')   # (shown with -s: where the module's time goes)
    assert rc == 0 and 'Traceback' not in out, f'{line}: exit {rc} after {took:.0f} s\n{out[-3000:]}'
    check(work, out)


NODES = {   # the documented node lines: (pkg, exe, --ros-args given, parameters they must show)
    'physics': ('physics_sim', 'physics', [], {}),
    'control': ('performance_control', 'control',
                ['--ros-args', '-p', 'start_feature:=rope', '-p', 'e1_threshold:=0.04'],
                {'start_feature': 'rope', 'e1_threshold': 0.04}),
}
HOLD_S = 3.0


def _stand_on_the_input(probe, seconds):
    """A person standing in the world frame (no TF needed) on /posture/reconstructed (the input of
    both nodes), 30 Hz."""
    from skeleton_core.conversions import SkeletonFrame, frames_to_array_msg
    from skeleton_core.model import standard_body
    from skeleton_msgs.msg import SkeletonArray
    pub = probe.node.create_publisher(SkeletonArray, '/posture/reconstructed', 10)
    p = standard_body().rest_positions()
    p = p - [0.0, 0.0, p[:, 2].min()]   # feet on the floor
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        stamp = time.time_ns()
        f = SkeletonFrame(positions=p, tracking_state=np.full(len(p), 2, np.uint8), user_id=1,
                          stamp_ns=stamp, frame_id='world')
        pub.publish(frames_to_array_msg([f], stamp, 'world'))
        time.sleep(1 / 30)


def test_documented_nodes_run_over_dds_and_stop_on_ctrl_c(tmp_path):
    """`ros2 run physics_sim physics` and `ros2 run performance_control control --ros-args ...`,
    started together on a DDS domain of their own: each comes up (configured and active on its
    own, no lifecycle manager), answers over DDS with the parameters the line gave it, runs a few
    seconds given a standing person on their input (/posture/reconstructed: the physics'
    character and the control's composed pose come out) and exits 0 on Ctrl-C without a
    traceback."""
    from ros_helpers import Probe, wait_until
    domain = domains.claim(30 + os.getpid() % 50)
    procs, logs = {}, {}
    for name, (pkg, exe, args, _) in NODES.items():
        logs[name] = tmp_path / f'{name}.log'
        with open(logs[name], 'w') as f:
            procs[name] = subprocess.Popen(_executable(pkg, exe) + args, cwd=tmp_path,
                                           env=_env(domain), stdout=f, stderr=subprocess.STDOUT,
                                           start_new_session=True)
    probe = Probe({'/character/skeletons': 'skeleton_msgs/msg/SkeletonArray',
                   '/control/target': 'skeleton_msgs/msg/SkeletonArray'},
                  name='documented_nodes_probe', domain_id=domain)
    got = {}
    try:
        def up():
            return set(NODES) <= set(probe.node.get_node_names()) or any(
                p.poll() is not None for p in procs.values())
        assert wait_until(up, timeout=120, step=0.5), 'the nodes never appeared on DDS'
        for name, (_, _, _, want) in NODES.items():
            if procs[name].poll() is None:
                got[name] = probe.get_parameters(f'/{name}', list(want) or None)
        _stand_on_the_input(probe, HOLD_S)
        outputs = probe.counts()
    finally:
        probe.close()
        for p in procs.values():
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGINT)
        for p in procs.values():
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
        domains.release(domain)
    for name, (_, _, _, want) in NODES.items():
        text = logs[name].read_text(errors='replace')
        assert procs[name].returncode == 0 and 'Traceback' not in text, \
            f'{name}: exit {procs[name].returncode}\n{text[-3000:]}'
        assert name in got, f'{name} ended before it answered over DDS\n{text[-3000:]}'
        for k, v in want.items():
            assert got[name][k] == (pytest.approx(v) if isinstance(v, float) else v), \
                (name, k, got[name])
    for name, topic in (('physics', '/character/skeletons'), ('control', '/control/target')):
        assert outputs[topic] > 0, \
            f'no {topic} from {name}\n{logs[name].read_text(errors="replace")[-3000:]}'


def test_live_calibration_stopped_by_ctrl_c_says_so_without_a_traceback(tmp_path):
    """`calibrate_extrinsics --live 2` stopped before its recording is complete (Ctrl-C, or the
    launch that started it shutting down): one line, a clean exit as a node's (0: the launch
    logs no death), nothing written, no traceback."""
    domain = domains.claim(70)
    try:
        proc = subprocess.Popen(
            _executable('kinect_bringup', 'calibrate_extrinsics')
            + ['--live', '2', '--duration', '30', '--out', str(tmp_path / 'x.yaml')],
            cwd=tmp_path, env=_env(domain), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True)
        time.sleep(4.0)   # (no sensor: it waits for the first skeleton of each)
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
    finally:
        domains.release(domain)
    assert proc.returncode == 0, out
    assert 'Traceback' not in out and 'interrupted' in out and 'nothing written' in out, out
    assert not (tmp_path / 'x.yaml').exists()
