"""``bench``: end-to-end latency, throughput, drops, CPU and memory of the running graph, measured
through real DDS as a user runs it — for 1, 2, 4 and 6 users, as the one-process ``pipeline`` and as
separate processes — plus the offline ``process_bag`` speed. Writes Markdown + JSON.

    ros2 run kinect_experiments bench                       # full table (~3 min)
    ros2 run kinect_experiments bench --users 1,2 --modes pipeline --seconds 8
    ros2 run kinect_experiments bench --users 6 --modes processes --sensors 1,2   # fusion beside

With ``--sensors 2`` (in the default list) every user count also runs with two sensors:
two synthetic drivers in /kinect_1 and /kinect_2 (front + side, the same people seen from
``driver.launch.py sensors:=2``'s default poses), their frames on TF, the ``fusion`` node, then
the graph unchanged, as separate processes (``ros2 launch pipeline.launch.py sensors:=2``). The
latency is then from sensor 1's capture (the fused frames carry its stamps); ``fused`` is the
fusion's output on /kinect/skeletons, and a frame is dropped when a sensor-1 capture (counted per
user: the fusion gives the people ids of its own) never comes out.

Latency = probe receive time - the skeleton's capture stamp (the driver stamps each frame when it
is captured; every node preserves the stamp), at its first arrival on the topic (the physics node's
timer republishes the newest target's stamp while no new one arrives: counted as repeats). A
frame is dropped when its capture stamp appears on /kinect/skeletons but never on the output topic.

The floor: beside the graph, a pass-through node (``kinect_experiments.passthrough``: subscribe to
/kinect/skeletons -- with several sensors sensor 1's raw /kinect_1/skeletons --, republish the same
bytes on /bench/passthrough) runs in every case; its latency, measured by the same probe in the same
seconds, is what one DDS hop and one Python callback cost at that moment, and every row prints it.
The latency targets are judged against it: one sensor, 2 users, reconstructed p95 <= floor p95 +
5 ms and character p95 <= floor p95 + 12 ms; several sensors, fused p95 <= floor p95 + 5 ms (plus,
with the drivers elsewhere, the replayed phase of the last sensor when the fusion waits for it), and
2 users with 0 dropped frames; 6 users, every output p95 <= 33 ms with 0 dropped frames and the
graph's CPU <= 150 % (of the 2 cores' 200 %).

The probe is this process (raw subscriptions to every topic, read with ``skeleton_core.cdr_scan``:
stamps, ids and NaN skeletons without building frames; rclpy's events executor where it exists);
its CPU in the same seconds is listed as "probe (not in the graph)", apart from the graph's.

Each case starts its processes, waits until every output has delivered (the start-up -- imports,
kernels loading, DDS discovery -- is not measured; its seconds are printed), then ``--warmup`` s,
then measures ``--seconds``: every frame lost in that window counts.

``--drivers-elsewhere``: the drivers as a lab runs them, on the sensors' own computers. Their
frames (the same synthetic source, seeds, users and views) are generated before the case and one
light process (``kinect_experiments.remote_drivers``) publishes them as pre-serialized bytes,
restamped with their capture times; what stays on this machine is the DDS receive. Its CPU is
printed apart and not counted in the graph's.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Dict, List

import numpy as np

from kinect_bringup.graph import RECONSTRUCTION, graph_nodes, repo_root
from kinect_bringup.pipeline import EXECUTORS
from kinect_bringup.processes import Graph
from skeleton_core.cdr_scan import scan_cdr
from skeleton_core.bagio import bag_topics
import signal
from skeleton_data.database import build_default

from . import speed_gauge
from .remote_drivers import DEFAULT_PHASE_MS

PROCESS_BAG_MODULE = 'kinect_bringup.process_bag'

BUDGET_MS = 1000.0 / 30.0
FLOOR_TOPIC = '/bench/passthrough'
SENSOR1_TOPIC = '/kinect_1/skeletons'
TOPICS = {'/kinect/skeletons': 'input', '/posture/reconstructed': 'reconstructed',
          '/character/skeletons': 'character', FLOOR_TOPIC: 'floor', SENSOR1_TOPIC: 'sensor1'}
INPUTS = ('/kinect/skeletons', FLOOR_TOPIC, SENSOR1_TOPIC)   # not outputs: no NaN count
# the latency targets: (users, output) -> ms over the floor's p95; 6 users: absolute
OVER_FLOOR_MS = {(2, 'reconstructed'): 5.0, (2, 'character'): 12.0}
SIX_USERS_P95_MS, SIX_USERS_CPU_PCT = 33.0, 150.0
PROCESS_BAG_PHYSICS_X = 10.0
FUSED_OVER_FLOOR_MS = 5.0   # several sensors: the fused input p95 over the raw sensor's floor
FUSION_MAX_WAIT_MS = 5.0    # the fusion node's default max_wait_ms (a later sensor waited for)
STARTUP_TIMEOUT_S = 90.0    # the longest a case waits for every output to deliver
REMOTE_MARGIN_S = 30.0      # drivers elsewhere: frames generated beyond warm-up + window
PROBE = 'probe (not in the graph)'   # this process: the probe's subscriptions, its CPU apart
LINGER_S = 25.0             # publishers found before the first case: time to go away (a killed
#                             process's participant stays until its DDS lease ends, ~20 s)


def probe_executor(context):
    """The probe's executor: rclpy's events executor where it exists (Jazzy and newer: it waits
    in C++ and runs only what is ready; the single-threaded one rebuilds its wait set in Python
    on every wake-up, a cost the probe would add to the machine it measures), else the
    single-threaded one."""
    from skeleton_core.compat import events_executor
    try:
        return events_executor(context=context)
    except RuntimeError:   # (Humble)
        from rclpy.executors import SingleThreadedExecutor
        return SingleThreadedExecutor(context=context)


class LatencyProbe:
    def __init__(self):
        import rclpy
        from rclpy.node import Node
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from skeleton_msgs.msg import SkeletonArray
        self.rclpy = rclpy
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        # (no parameter services: fewer entities for the executor to wait on)
        self.node = Node('bench_probe', context=self.ctx, start_parameter_services=False)
        self.lock = threading.Lock()
        self.recording = False
        self.stamps: Dict[str, set] = {t: set() for t in TOPICS}
        self.lat: Dict[str, List[float]] = {t: [] for t in TOPICS}
        self.count: Dict[str, int] = {t: 0 for t in TOPICS}
        self.repeats: Dict[str, int] = {t: 0 for t in TOPICS}
        self.nan = 0
        self.diagnostics: Dict[str, Dict[str, str]] = {}   # node name -> its latest key/values
        self.first: Dict[str, float] = {}   # topic -> monotonic time of its first message since
        #                                     wait_for() was called (recording or not)
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        for t in TOPICS:  # serialized: the probe's own decoding must not delay what it measures
            self.node.create_subscription(SkeletonArray, t, lambda m, t=t: self._cb(t, m), qos,
                                          raw=True)
        from diagnostic_msgs.msg import DiagnosticArray
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 50)
        self.ex = probe_executor(self.ctx)
        self.ex.add_node(self.node)
        self.running = True
        self.th = threading.Thread(target=self._spin, daemon=True)
        self.th.start()

    def _spin(self):
        while self.running:
            self.ex.spin_once(timeout_sec=0.05)

    def _cb(self, topic, data):
        now = time.time_ns()
        if topic not in self.first:
            self.first[topic] = time.monotonic()
        if not self.recording:
            return
        # the stamps, ids and validity without decoding frames (the skeletons frames_from_cdr
        # returns; a NaN skeleton is one it rejects as non-finite)
        skeletons = scan_cdr(data).skeletons
        with self.lock:
            self.count[topic] += 1
            stamps, lat = self.stamps[topic], self.lat[topic]
            for uid, stamp, cause in skeletons:
                if cause is not None:
                    if cause.startswith('non-finite') and topic not in INPUTS:
                        self.nan += 1
                    continue
                key = (uid, stamp)
                if key in stamps:               # the physics node's timer republishing the
                    self.repeats[topic] += 1     # newest target's state: not a later delivery
                    continue
                stamps.add(key)
                lat.append((now - stamp) / 1e6)

    def _on_diag(self, msg):
        if not self.recording:
            return
        with self.lock:
            for st in msg.status:
                self.diagnostics[st.name.lstrip('/')] = {kv.key: kv.value for kv in st.values}

    def publishers(self, seconds: float = 2.0, linger: float = 0.0) -> Dict[str, int]:
        """The measured topics something already publishes on (after ``seconds`` of discovery):
        before the first case, another graph on this DDS domain (another shell's, scripts/env.sh
        gives every shell the same domain), whose messages would be measured as the graph's.
        ``linger``: how long found publishers get to go away (a graph just stopped: a killed
        process stays in discovery until its lease ends)."""
        deadline = time.monotonic() + seconds
        while True:
            found = {t: n for t in TOPICS if (n := self.node.count_publishers(t))}
            if found or time.monotonic() >= deadline:
                break
            time.sleep(0.1)
        deadline = time.monotonic() + linger
        while found and time.monotonic() < deadline:
            time.sleep(0.5)
            found = {t: n for t in TOPICS if (n := self.node.count_publishers(t))}
        return found

    def wait_for(self, topics, timeout: float) -> List[str]:
        """Wait until each of ``topics`` has delivered a message that came after this call (a
        graph of an earlier case, or its last messages still in flight, do not count); returns
        the topics still silent after ``timeout`` s."""
        with self.lock:
            self.first = {}
        deadline = time.monotonic() + timeout
        while True:
            missing = [t for t in topics if t not in self.first]
            if not missing or time.monotonic() >= deadline:
                return missing
            time.sleep(0.05)

    def start(self):
        with self.lock:
            self.diagnostics.clear()
            for t in TOPICS:
                self.stamps[t].clear()
                self.lat[t].clear()
                self.count[t] = 0
                self.repeats[t] = 0
            self.nan = 0
            self.recording = True

    def stop(self):
        self.recording = False

    def close(self):
        self.running = False
        self.th.join(timeout=2)
        self.ex.shutdown()
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.ctx)


def _proc_stats(graph: Graph, seconds: float, outside: Dict[str, subprocess.Popen] = None
                ) -> Dict[str, Dict[str, float]]:
    """CPU % and RSS of the graph's processes over ``seconds`` (and of the ``outside`` ones,
    measured in the same seconds, under their own names: the caller keeps them apart; and of
    this process, the probe's, as PROBE)."""
    import os
    import psutil
    procs = {}
    pids = {name: p.pid for name, p in {**graph.procs, **(outside or {})}.items()}
    for name, pid in {**pids, PROBE: os.getpid()}.items():
        try:
            ps = psutil.Process(pid)
            ps.cpu_percent(None)
            procs[name] = ps
        except psutil.NoSuchProcess:
            pass
    time.sleep(seconds)
    out = {}
    for name, ps in procs.items():
        try:
            out[name] = {'cpu_percent': ps.cpu_percent(None),
                         'rss_mb': ps.memory_info().rss / 2 ** 20}
        except psutil.NoSuchProcess:
            out[name] = {'cpu_percent': float('nan'), 'rss_mb': float('nan')}
    return out


# what each node's diagnostics call latency (skeleton_core.health, the last ~10 s)
NODE_LATENCY = {'driver': 'timer lateness (capture time -> tick)',
                'reconstruction': 'callback (decode, process, encode, publish)',
                'physics': 'capture -> character published'}


def _node_latencies(diagnostics: Dict[str, Dict[str, str]]) -> Dict[str, Dict[str, float]]:
    out = {}
    for name, kv in diagnostics.items():
        try:
            vals = {k: float(kv[k]) for k in ('p50_ms', 'p95_ms') if k in kv}
        except ValueError:
            continue
        if vals and all(np.isfinite(v) for v in vals.values()):  # nan: no samples yet
            out[name] = vals
    return out


def _physics_figures(diagnostics: Dict[str, Dict[str, str]]) -> Dict[str, float]:
    """The physics node's real-time factor, characters and worlds from its diagnostics."""
    kv = diagnostics.get('physics', {})
    out = {}
    for key in ('real_time_factor', 'characters', 'worlds', 'sim_regroups', 'ticks_input',
                'ticks_deferred', 'ticks_timer', 'tick_cpu_ms', 'tick_cpu_ms_outside_steps',
                'input_cpu_ms'):
        try:
            out[key] = float(kv[key])
        except (KeyError, ValueError):
            pass
    return out


def _add_sensors(graph: Graph, users: int, sensors: int, drivers: bool = True) -> None:
    """``driver.launch.py sensors:=N`` as processes: N synthetic drivers in /kinect_k (frames
    kinect_k_link, the same people seen from the default poses; ``drivers`` False: none, the
    frames come from elsewhere) and one static_tf."""
    from kinect_bringup.processes import node_command
    from skeleton_core.tf import default_sensor_poses, format_pose, sensor_frame, sensor_namespace
    from .remote_drivers import driver_values
    poses = default_sensor_poses(sensors)
    tf_cmd = [sys.executable, '-m', 'kinect_driver.static_tf_node']
    for k in range(1, sensors + 1):
        ns = sensor_namespace(k, sensors)
        if drivers:
            v = driver_values(users, sensors, k)
            graph.add(f'driver_{k}', node_command('driver', {
                key: v[key] for key in ('num_users', 'scenario', 'frame_id', 'view_pose')},
                ros_args=['-r', f'__ns:=/{ns}', '-r', f'/kinect/skeletons:=/{ns}/skeletons',
                          '-r', f'/kinect/ground_truth:=/{ns}/ground_truth']))
        tf_cmd += ['--pose', format_pose(poses[k - 1]), '--child', sensor_frame(k, sensors)]
    # (beside the Graph's own static_tf, which publishes the one-sensor frame kinect_link)
    graph.add('static_tf_sensors', tf_cmd + ['--ros-args', '-r', '__node:=static_tf_sensors'])


def run_case(probe: LatencyProbe, mode: str, users: int, seconds: float, warmup: float,
             physics: bool, log_dir: Path, reconstruction: str = 'fused', sensors: int = 1,
             executor: str = 'auto', drivers_elsewhere: bool = False,
             phase_ms: float = None) -> Dict:
    overrides = {'driver': {'num_users': users, 'scenario': 'b'}}
    pipeline_args = ['--num-users', str(users), '--scenario', 'b', '--no-viz',
                     '--reconstruction', reconstruction, '--executor', executor]
    nodes = graph_nodes(physics=physics, viz=False, reconstruction=reconstruction)
    if not physics:
        pipeline_args.append('--no-physics')
    case_dir = log_dir / (f'{mode}_{reconstruction}_{users}' + (f'_{sensors}s' if sensors > 1 else '')
                          + (f'_{executor}' if mode == 'pipeline' else '')
                          + ('_elsewhere' if drivers_elsewhere else ''))
    if (sensors > 1 or drivers_elsewhere) and mode != 'processes':
        raise ValueError('several sensors and drivers elsewhere run as processes only (as ros2 '
                         'launch runs them)')
    if sensors > 1:
        nodes = ['fusion'] + [n for n in nodes if n != 'driver']
    elif drivers_elsewhere:
        nodes = [n for n in nodes if n != 'driver']
    remote = None
    phase_ms = DEFAULT_PHASE_MS if phase_ms is None else float(phase_ms)
    if drivers_elsewhere and not 0 <= phase_ms * (sensors - 1) < BUDGET_MS:
        raise ValueError(f'{sensors} sensors {phase_ms:g} ms apart do not fit one frame')
    if drivers_elsewhere:   # every frame made now, before the graph starts (remote_drivers)
        from . import remote_drivers
        remote = remote_drivers.generate(users, sensors, warmup + seconds + REMOTE_MARGIN_S,
                                         case_dir / 'remote_frames.pkl')
    # the floor: one DDS hop and one Python callback on the sensor's own topic (sensor 1's
    # with several sensors: the fusion is then judged against it)
    floor = _start_passthrough(case_dir, SENSOR1_TOPIC if sensors > 1 else '/kinect/skeletons')
    started = time.monotonic()
    graph = Graph(mode, nodes=nodes, overrides=overrides, pipeline_args=pipeline_args,
                  log_dir=case_dir)
    outside = {}
    if sensors > 1:
        _add_sensors(graph, users, sensors, drivers=not drivers_elsewhere)
    if drivers_elsewhere:
        outside['remote drivers'] = _start_logged(
            case_dir / 'remote_drivers.log',
            [sys.executable, '-m', 'kinect_experiments.remote_drivers',
             str(case_dir / 'remote_frames.pkl'), '--phase-ms',
             str(phase_ms)])
    outputs = ['/kinect/skeletons', '/posture/reconstructed'] + (
        ['/character/skeletons'] if physics else [])
    try:
        # every output delivering before the warm-up begins: the start-up (processes importing,
        # kernels loading) is not in the window; what is lost after it counts
        silent = probe.wait_for(outputs, STARTUP_TIMEOUT_S)
        if silent:
            print(f'[bench] nothing on {", ".join(silent)} {STARTUP_TIMEOUT_S:g} s after the '
                  f'start: measuring anyway (see {case_dir})', flush=True)
        first = {TOPICS[t]: probe.first[t] - started for t in outputs if t in probe.first}
        time.sleep(warmup)
        probe.start()
        stats = _proc_stats(graph, seconds, outside)
        probe.stop()
    finally:
        graph.stop()
        for proc in [floor, *outside.values()]:
            _stop(proc)
    with probe.lock:
        res = {'mode': mode, 'reconstruction': reconstruction, 'users': users, 'sensors': sensors,
               'executor': executor if mode == 'pipeline' else None,
               'drivers_elsewhere': drivers_elsewhere, 'seconds': seconds,
               'processes': {k: v for k, v in stats.items() if k not in outside and k != PROBE},
               'outside': {k: v for k, v in stats.items() if k in outside},
               'probe': stats.get(PROBE, {}),
               'first_output_s': first,
               'nan_outputs': probe.nan, 'nodes': _node_latencies(probe.diagnostics),
               'physics': _physics_figures(probe.diagnostics)}
        if remote:
            res['remote_frames'] = {k: remote[k] for k in ('frames', 'rate_hz', 'generate_s')}
            if sensors > 1:
                res['remote_frames']['phase_ms'] = phase_ms
        # the captures: sensor 1's with several sensors (the fused frames carry its stamps)
        src_topic = SENSOR1_TOPIC if sensors > 1 else '/kinect/skeletons'
        src = _per_stamp(probe.stamps[src_topic])
        for topic, key in TOPICS.items():
            lat = np.array(probe.lat[topic])
            r = {'rate_hz': probe.count[topic] / seconds, 'skeletons': int(lat.size),
                 'repeated': probe.repeats[topic]}
            if lat.size:
                r.update({f'p{q}_ms': float(np.percentile(lat, q)) for q in (50, 95, 99)})
            if topic not in (src_topic, FLOOR_TOPIC, SENSOR1_TOPIC) and src:
                # user-frames captured in the window that never came out (allow the last 0.2 s
                # in flight), counted per stamp: the fusion gives the people ids of its own
                last = max(src) - 200_000_000
                out = _per_stamp(probe.stamps[topic])
                considered = {s: n for s, n in src.items() if s < last}
                r['dropped'] = sum(max(0, n - out.get(s, 0)) for s, n in considered.items())
                r['dropped_fraction'] = r['dropped'] / max(1, sum(considered.values()))
            res[key] = r
    return res


def _per_stamp(keys) -> Dict[int, int]:
    """(user id, stamp) keys -> users per stamp."""
    out: Dict[int, int] = {}
    for _, st in keys:
        out[st] = out.get(st, 0) + 1
    return out


def _start_passthrough(log_dir: Path, topic: str = '/kinect/skeletons') -> subprocess.Popen:
    """The floor node on ``topic``, as a process of its own beside the graph (its CPU is not the
    graph's)."""
    return _start_logged(log_dir / 'passthrough.log', [
        sys.executable, '-m', 'kinect_experiments.passthrough', '--input', topic,
        '--output', FLOOR_TOPIC])


def _start_logged(log: Path, cmd: List[str]) -> subprocess.Popen:
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, 'w') as out:
        return subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT)


def _stop(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def process_bag_speed(log_dir: Path) -> Dict:
    """Record 10 s of the synthetic source, then time the offline reconstruction over it, without
    and with the physics character (``--physics``)."""
    bag = log_dir / 'bench_input.mcap'
    try:
        from skeleton_core.bagio import BagError, bag_topics
        for attempt in range(2):   # a recorder stopped hard on a loaded machine: record again
            g = Graph('pipeline', pipeline_args=['--no-physics', '--no-viz', '--record', str(bag)],
                      log_dir=log_dir / 'record')
            time.sleep(14)
            g.stop(timeout=30.0)
            try:
                if bag.exists() and bag_topics(str(bag)).get('/kinect/skeletons'):
                    break
            except (BagError, ValueError, OSError):
                pass
        else:
            return {'error': 'recording failed twice'}
        out = _time_process_bag(bag, log_dir, physics=False)
        out['physics'] = _time_process_bag(bag, log_dir, physics=True)
        return out
    except Exception as e:  # noqa: BLE001 - report, don't crash the whole benchmark
        return {'error': str(e)}


def _time_process_bag(bag: Path, log_dir: Path, physics: bool) -> Dict:
    tag = '_physics' if physics else ''
    out = log_dir / f'bench_output{tag}.mcap'
    report = log_dir / f'bench_output{tag}.json'
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, '-m', PROCESS_BAG_MODULE, str(bag), '--out', str(out),
                           '--method', 'C', '--no-progress', '--report', str(report)]
                          + (['--physics'] if physics else []), capture_output=True, text=True)
    wall = time.monotonic() - t0
    if proc.returncode != 0:
        return {'error': proc.stderr.strip().splitlines()[-1:] or 'process_bag failed'}
    n = bag_topics(str(bag)).get('/kinect/skeletons', (None, 0))[1]
    loop = json.loads(report.read_text())
    # the processing loop (read, reconstruct, write) is what grows with the recording; the
    # start-up (imports, database) is paid once per command
    return {'frames': n, 'wall_s': wall, 'recorded_s': n / 30.0,
            'x_real_time': (n / 30.0) / wall if wall > 0 else float('nan'),
            'loop_s': loop['wall_s'], 'x_real_time_loop': loop['x_real_time'],
            'x_real_time_loop_cpu': loop.get('x_real_time_cpu', float('nan')),
            'startup_s': wall - loop['wall_s']}


def _label(r: Dict) -> str:
    n, ex = r.get('sensors', 1), r.get('executor')
    return (f"{r['mode']} ({r.get('reconstruction', 'split')}" + (f', {ex} executor' if ex else '')
            + ')' + (f', {n} sensors' if n > 1 else '')
            + (', drivers elsewhere' if r.get('drivers_elsewhere') else ''))


def _speed_label(r: Dict) -> str:
    sp = r.get('machine_speed', {})
    return speed_gauge.label(sp.get('before'), sp.get('after')) + (
        f" (waited {sp['waited_s']:.0f} s for it)" if sp.get('waited_s', 0) >= 1 else '')


def _outputs(r: Dict) -> List[str]:
    """The outputs judged: the fused skeletons too when there are several sensors."""
    return (['input'] if r.get('sensors', 1) > 1 else []) + ['reconstructed', 'character']


def _output_name(key: str) -> str:
    return 'fused' if key == 'input' else key


def graph_cpu(r: Dict) -> float:
    """CPU % of all the graph's processes together (100 % = one core)."""
    return float(sum(s['cpu_percent'] for s in r.get('processes', {}).values()))


def fusion_wait_ms(r: Dict) -> float:
    """The wait a fused frame must make for its last sensor (ms): the replayed sensors' phase
    times (sensors - 1) when within the fusion's bound (FUSION_MAX_WAIT_MS, its default
    ``max_wait_ms``), else 0 (that sensor is not waited for; unknown phase: 0)."""
    phase = r.get('remote_frames', {}).get('phase_ms')
    if phase is None:
        return 0.0
    lag = float(phase) * (r.get('sensors', 1) - 1)
    return lag if lag <= FUSION_MAX_WAIT_MS else 0.0


def targets(results: List[Dict], bag_speed: Dict) -> List[Dict]:
    """The latency targets judged on this run: one dict per check (what, figure, limit, met)."""
    out = []
    for r in results:
        fl = r.get('floor', {})
        several = r.get('sensors', 1) > 1
        for (users, key), over in OVER_FLOOR_MS.items():
            o = r.get(key, {})
            # (one sensor: with several the floor is sensor 1's raw topic, before the fusion)
            if r['users'] == users and not several and o.get('skeletons') and fl.get('skeletons'):
                limit = fl['p95_ms'] + over
                out.append({'case': _label(r), 'what': f'{users} users {key} p95 <= floor p95 + '
                            f'{over:g} ms', 'figure': o['p95_ms'], 'limit': limit,
                            'met': o['p95_ms'] <= limit})
        o = r.get('input', {})
        if several and o.get('skeletons') and fl.get('skeletons'):
            # a fused frame cannot leave before its last sensor's frame is captured: that
            # sensor's phase (known when the drivers are replayed) is the fusion's necessary wait
            # when it is within the fusion's bound, and is added to the floor (sensor 1's hop)
            wait = fusion_wait_ms(r)
            limit = fl['p95_ms'] + wait + FUSED_OVER_FLOOR_MS
            out.append({'case': _label(r), 'what': 'fused p95 <= floor p95 (sensor 1 raw) + '
                        + (f'{wait:g} ms wait for the last sensor + ' if wait else '')
                        + f'{FUSED_OVER_FLOOR_MS:g} ms', 'figure': o['p95_ms'], 'limit': limit,
                        'met': o['p95_ms'] <= limit})
        if several and r['users'] == 2:
            for key in _outputs(r):
                o = r.get(key, {})
                if o.get('skeletons'):
                    out.append({'case': _label(r), 'what': f'2 users {_output_name(key)} '
                                'dropped = 0', 'figure': o.get('dropped', 0), 'limit': 0,
                                'met': o.get('dropped', 0) == 0})
        if r['users'] == 6:
            for key in _outputs(r):
                o = r.get(key, {})
                name = _output_name(key)
                if o.get('skeletons'):
                    out.append({'case': _label(r), 'what': f'6 users {name} p95 <= '
                                f'{SIX_USERS_P95_MS:g} ms', 'figure': o['p95_ms'],
                                'limit': SIX_USERS_P95_MS, 'met': o['p95_ms'] <= SIX_USERS_P95_MS})
                    out.append({'case': _label(r), 'what': f'6 users {name} dropped = 0',
                                'figure': o.get('dropped', 0), 'limit': 0,
                                'met': o.get('dropped', 0) == 0})
            if r.get('reconstructed', {}).get('skeletons'):   # a graph that ran at all
                cpu = graph_cpu(r)
                out.append({'case': _label(r), 'what': f'6 users graph CPU <= '
                            f'{SIX_USERS_CPU_PCT:g} %', 'figure': cpu, 'limit': SIX_USERS_CPU_PCT,
                            'met': cpu <= SIX_USERS_CPU_PCT})
    ph = bag_speed.get('physics', {}) if bag_speed else {}
    if 'x_real_time_loop' in ph:
        out.append({'case': 'process_bag', 'what': f'process_bag --physics >= '
                    f'{PROCESS_BAG_PHYSICS_X:g}x real time (loop)', 'figure': ph['x_real_time_loop'],
                    'limit': PROCESS_BAG_PHYSICS_X,
                    'met': ph['x_real_time_loop'] >= PROCESS_BAG_PHYSICS_X})
    return out


def to_markdown(results: List[Dict], bag_speed: Dict, commit: str) -> str:
    def ms(o, k):
        return f"{o[k]:.1f}" if k in o else '-'

    lines = [f'# End-to-end benchmark (commit {commit})', '',
             f'Frame budget {BUDGET_MS:.1f} ms (30 Hz). Latency = receive time - capture stamp, over real DDS.',
             'Mode: one-process `pipeline` or `processes` (one per node, as `ros2 launch` runs them); '
             'reconstruction fused (one node) or split (reliability, completion, optimizer nodes). '
             'No viz node: nothing consumes /posture/completed, which the fused node then skips. '
             'Floor = a pass-through node beside the graph (/kinect/skeletons republished as is), '
             'measured in the same seconds: one DDS hop and one Python callback now; '
             '"over floor" = p95 - floor p95. With 2 sensors: two drivers, their frames on TF and '
             'the fusion node before the same graph; latency from sensor 1\'s capture, `fused` = '
             'the fusion\'s output (/kinect/skeletons), the floor = sensor 1\'s raw topic '
             '(/kinect_1/skeletons) republished, dropped = sensor-1 user-frames that never came '
             'out. Drivers elsewhere: the drivers\' frames generated before the run and '
             'published as pre-serialized bytes by one process (remote_drivers), whose CPU is '
             'listed apart and is not in the graph\'s. The window begins `--warmup` s after every '
             'output delivered (first output: seconds from the start).',
             '', '| mode | users | output | rate Hz | p50 ms | p95 ms | p99 ms | floor p50 / p95 ms '
             '| over floor ms | p95/budget | dropped |',
             '|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|']
    for r in results:
        fl = r.get('floor', {})
        for key in _outputs(r):
            o = r.get(key, {})
            if not o.get('skeletons'):
                continue
            over = f"{o['p95_ms'] - fl['p95_ms']:+.1f}" if 'p95_ms' in fl else '-'
            lines.append(f"| {_label(r)} | {r['users']} | {_output_name(key)} | {o['rate_hz']:.1f} | "
                         f"{o['p50_ms']:.1f} | {o['p95_ms']:.1f} | {o['p99_ms']:.1f} | "
                         f"{ms(fl, 'p50_ms')} / {ms(fl, 'p95_ms')} | {over} | "
                         f"{o['p95_ms'] / BUDGET_MS:.2f} | {o.get('dropped', 0)} "
                         f"({100 * o.get('dropped_fraction', 0):.1f} %) |")
    speeds = [r for r in results if r.get('machine_speed')]
    if speeds:
        lines += ['', 'Machine speed (`kinect_experiments.speed_gauge`: the CPU time of a fixed '
                  f'workload against {speeds[0]["machine_speed"]["before"]["nominal_ms"]:g} ms '
                  '= x1.00; x1.30 = the same work took 30 % longer), read right before the '
                  'case\'s processes started and right after they stopped:', '']
        lines += [f"- {_label(r)}, {r['users']} users: {_speed_label(r)}" for r in speeds]
    lines += ['', 'Where the time goes (p50 / p95 ms): `input` = capture -> /kinect/skeletons at the '
              'probe (driver tick lateness + one DDS hop); the nodes\' own figures from their '
              '/diagnostics: ' + '; '.join(f'{k} = {v}' for k, v in NODE_LATENCY.items()) + '.',
              '', '| mode | users | input | floor | driver | reconstruction | physics |',
              '|---|---:|---|---|---|---|---|']
    for r in results:
        def cell(d):
            return f"{d['p50_ms']:.1f} / {d['p95_ms']:.1f}" if 'p95_ms' in d else '-'
        nodes = r.get('nodes', {})
        lines.append(f"| {_label(r)} | {r['users']} | {cell(r.get('input', {}))} | "
                     f"{cell(r.get('floor', {}))} | "
                     + ' | '.join(cell(nodes.get(k, {})) for k in NODE_LATENCY) + ' |')
    lines += ['', '| mode | users | process | CPU % | RSS MB |', '|---|---:|---|---:|---:|']
    for r in results:
        for name, s in r['processes'].items():
            lines.append(f"| {_label(r)} | {r['users']} | {name} | {s['cpu_percent']:.0f} | {s['rss_mb']:.0f} |")
        lines.append(f"| {_label(r)} | {r['users']} | **graph** | {graph_cpu(r):.0f} | |")
        phase = r.get('remote_frames', {}).get('phase_ms')
        for name, s in r.get('outside', {}).items():
            apart = f'; sensors {phase:g} ms apart' if phase is not None else ''
            lines.append(f"| {_label(r)} | {r['users']} | {name} (not the graph's{apart}) | "
                         f"{s['cpu_percent']:.0f} | {s['rss_mb']:.0f} |")
        if r.get('probe'):
            lines.append(f"| {_label(r)} | {r['users']} | {PROBE} | "
                         f"{r['probe']['cpu_percent']:.0f} | {r['probe']['rss_mb']:.0f} |")
    firsts = [r for r in results if r.get('first_output_s')]
    if firsts:
        lines += ['', 'First output, s after the graph\'s processes started: '
                  + '; '.join(f"{_label(r)}, {r['users']} users: " + ', '.join(
                      f"{_output_name(k) if r.get('sensors', 1) > 1 else k} {v:.1f}"
                      for k, v in r['first_output_s'].items())
                      for r in firsts)]
    phys = [(r, r['physics']) for r in results if r.get('physics')]
    if phys:
        lines += ['', 'Physics node (its /diagnostics): real-time factor = simulated s per wall s '
                  'spent stepping (every character advances at that rate); worlds = MuJoCo models '
                  'the characters were split into at the end; regroups = merges and splits; '
                  'ticks input/deferred/timer since the start (physics_sim.scheduler: a timer '
                  'tick beside a steady input is an extra publish); CPU per tick (thread time) '
                  'and of it outside the physics steps.', '',
                  '| mode | users | characters | worlds | regroups | real-time factor | '
                  'ticks input/deferred/timer | tick CPU ms (outside steps) |',
                  '|---|---:|---:|---:|---:|---:|---|---|']
        for r, p in phys:
            rtf, n = p.get('real_time_factor', float('nan')), p.get('characters', 0)
            ticks = '/'.join(f"{p[k]:.0f}" if k in p else '-' for k in
                             ('ticks_input', 'ticks_deferred', 'ticks_timer'))
            cpu = (f"{p['tick_cpu_ms']:.1f} ({p.get('tick_cpu_ms_outside_steps', 0):.1f})"
                   if 'tick_cpu_ms' in p else '-')
            lines.append(f"| {_label(r)} | {r['users']} | {n:.0f} | {p.get('worlds', '-')} | "
                         f"{p.get('sim_regroups', '-')} | {rtf:.1f} | {ticks} | {cpu} |")
    lines += ['', f"NaN outputs: {sum(r['nan_outputs'] for r in results)}", '']
    for tag, b in (('no physics', bag_speed), ('--physics', (bag_speed or {}).get('physics', {}))):
        if 'x_real_time' in b:
            lines.append(f"process_bag (method C, {tag}): {b['frames']} frames "
                         f"({b['recorded_s']:.1f} s recorded): processing loop "
                         f"{b['loop_s']:.2f} s = **{b['x_real_time_loop']:.1f}x real "
                         f"time** ({b.get('x_real_time_loop_cpu', float('nan')):.1f}x by its CPU "
                         f"time: the figure on an idle core); whole command {b['wall_s']:.2f} s = "
                         f"{b['x_real_time']:.1f}x (start-up {b['startup_s']:.1f} s "
                         f"once per command: imports, database)")
        elif b:
            lines.append(f"process_bag ({tag}): {b}")
    checks = targets(results, bag_speed)
    if checks:
        lines += ['', '## Targets', '', '| case | target | figure | limit | met |',
                  '|---|---|---:|---:|---|']
        for c in checks:
            lines.append(f"| {c['case']} | {c['what']} | {c['figure']:.1f} | {c['limit']:.1f} | "
                         f"{'yes' if c['met'] else '**no**'} |")
    return '\n'.join(lines) + '\n'


def main(argv=None) -> int:
    # started in the background by a shell, this process ignores SIGINT, and so would every node
    # it starts (Python keeps an inherited SIG_IGN): the graphs could not be stopped cleanly (a
    # recorder killed mid-file). A handler of our own is reset to the default in the children
    signal.signal(signal.SIGINT, signal.default_int_handler)
    root = repo_root() or Path.cwd()
    p = argparse.ArgumentParser(prog='bench', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--users', default='1,2,4,6')
    p.add_argument('--modes', default='pipeline,processes')
    p.add_argument('--reconstruction', default='fused',
                   help=f'comma list of {"/".join(RECONSTRUCTION)}: the reconstruction as one node '
                        'or as three')
    p.add_argument('--sensors', default='1,2',
                   help='comma list of sensor counts: 2 adds, per user count, the graph with two '
                        'sensors and the fusion (as processes only)')
    p.add_argument('--executors', default='auto',
                   help='comma list: the one-process pipeline\'s executors to run (pipeline '
                        '--executor; e.g. single,events side by side)')
    p.add_argument('--seconds', type=float, default=10.0)
    p.add_argument('--warmup', type=float, default=4.0)
    p.add_argument('--no-physics', action='store_true')
    p.add_argument('--drivers-elsewhere', action='store_true',
                   help='the drivers as a lab runs them, on other machines: their frames (the '
                        'same synthetic source and seeds) generated before each case and '
                        'published as pre-serialized bytes by one light process, whose CPU is '
                        'printed apart and left out of the graph\'s (processes mode only)')
    p.add_argument('--phase-ms', type=float, default=None,
                   help='with --drivers-elsewhere: sensor 2 captures this long after sensor 1 '
                        '(default 3: within the fusion\'s wait bound, waited for on every frame; '
                        'e.g. 16.7: half a frame, not waited for)')
    p.add_argument('--skip-bag', action='store_true')
    p.add_argument('--max-slow', type=float, default=None, metavar='FACTOR',
                   help='refuse a case (and the rest; exit 3) while the machine speed gauge '
                        'before it reads slower than FACTOR (x1.00 = nominal, e.g. 1.3), after '
                        're-reading it every 10 s for up to --slow-wait s. Default off: every '
                        'case runs and prints the gauge beside it. With --against: a run of the '
                        'A/B, see --max-speed-change')
    p.add_argument('--slow-wait', type=float, default=120.0,
                   help='seconds to wait for a faster minute before refusing (default 120)')
    p.add_argument('--out', default=str(root / 'out' / 'bench'))
    ab = p.add_argument_group('A/B against another commit (kinect_experiments.ab)')
    ab.add_argument('--against', nargs='?', const='HEAD^', default=None, metavar='COMMIT',
                    help='build COMMIT beside this tree (cache/ab/) and alternate its bench with '
                         'this one on the same cases (A B A B ...), printing B / A per output and '
                         'process; without a value: HEAD^, the previous landed commit. Defaults '
                         'then: --modes processes --sensors 1 --skip-bag')
    ab.add_argument('--alternations', type=int, default=3, help='A/B pairs (default 3)')
    ab.add_argument('--max-busy', type=float, default=None,
                    help='refuse a run when more than this share of the machine (0-1, all cores) '
                         'was busy in the 3 s before it, after waiting up to --load-wait s '
                         '(default 0.25)')
    ab.add_argument('--load-wait', type=float, default=120.0)
    ab.add_argument('--ignore-load', action='store_true',
                    help='run on a busy machine anyway; the report is marked NOT VALID')
    ab.add_argument('--max-speed-change', type=float, default=None, metavar='RATIO',
                    help='refuse a run while the machine speed gauge reads more than RATIO x '
                         'slower than the fastest reading of this comparison, after waiting up '
                         'to --slow-wait s (default 1.25: B / A is honest only between runs at '
                         'about the same speed; 0 = off). --max-slow applies too when given')
    ab.add_argument('--fail-ratio', type=float, default=None,
                    help='exit 1 when an output p95 or the graph CPU is worse than this ratio '
                         '(and 5 ms / 10 points) on every alternation, or drops appear (CI guard)')
    args = p.parse_args(argv)
    if args.phase_ms is not None and not args.drivers_elsewhere:
        p.error('--phase-ms sets the replayed sensors\' phase: it needs --drivers-elsewhere')
    if args.phase_ms is not None and not 0 <= args.phase_ms < BUDGET_MS:
        p.error(f'--phase-ms must be in [0, {BUDGET_MS:.1f}) ms, got {args.phase_ms:g}')
    if args.max_slow is not None and not args.max_slow > 0:
        p.error(f'--max-slow must be a factor > 0 (x1.00 = nominal), got {args.max_slow:g}')
    if args.slow_wait < 0:
        p.error(f'--slow-wait must be >= 0 s, got {args.slow_wait:g}')
    if args.max_speed_change is not None and not (args.max_speed_change == 0
                                                  or args.max_speed_change >= 1):
        p.error(f'--max-speed-change must be >= 1 (or 0: off), got {args.max_speed_change:g}')
    if args.against is not None:
        return _run_against(p, args, argv, root)
    for ex in args.executors.split(','):
        if ex not in EXECUTORS:
            p.error(f'--executors: {ex!r} is not one of {list(EXECUTORS)}')
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    try:
        commit = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], cwd=root, text=True,
                                capture_output=True).stdout.strip() or 'unknown'
    except OSError:
        commit = 'unknown'
    build_default()  # the nodes' default database file (make build-db), outside the measurement
    probe = LatencyProbe()
    busy = probe.publishers(linger=LINGER_S)
    if busy:
        import os
        probe.close()
        print(f"[bench] another graph already publishes on {', '.join(sorted(busy))} in DDS "
              f"domain {os.environ.get('ROS_DOMAIN_ID', '0')}: its messages would be measured as "
              "this graph's; run with a ROS_DOMAIN_ID of its own", file=sys.stderr)
        return 2
    results = []
    refused = None
    try:
        for mode in args.modes.split(','):
            for rec in args.reconstruction.split(','):
                if rec not in RECONSTRUCTION:
                    p.error(f'--reconstruction {rec!r} is not one of {list(RECONSTRUCTION)}')
                for users in [int(u) for u in args.users.split(',')]:
                    for n in [int(k) for k in args.sensors.split(',')]:
                        if (n > 1 or args.drivers_elsewhere) and mode != 'processes':
                            continue   # several sensors: as processes (ros2 launch) only
                        for ex in (args.executors.split(',') if mode == 'pipeline' else ['auto']):
                            print(f'[bench] {mode} ({rec}{", " + ex if mode == "pipeline" else ""}'
                                  f'), {users} user(s), {n} sensor(s)'
                                  + (', drivers elsewhere' if args.drivers_elsewhere else '')
                                  + ' ...', flush=True)
                            # the machine's speed right before (the graph not yet started)
                            # and right after (the graph stopped): outside the measured window
                            chk = speed_gauge.wait_for_speed(
                                args.max_slow or float('inf'), args.slow_wait)
                            if not chk.ok:
                                refused = (f'machine speed x{chk.reading.factor:.2f} (slower '
                                           f'than --max-slow x{args.max_slow:.2f}) after waiting '
                                           f'{chk.waited_s:.0f} s: a figure taken now would '
                                           'measure the host\'s slow minute, not the graph')
                                print(f'[bench] {refused}; refusing this case and the rest',
                                      file=sys.stderr, flush=True)
                                raise _Refused
                            res = run_case(probe, mode, users, args.seconds, args.warmup,
                                           not args.no_physics, out / 'logs', rec, n, ex,
                                           args.drivers_elsewhere, args.phase_ms)
                            res['machine_speed'] = {'before': chk.reading.as_dict(),
                                                    'after': speed_gauge.measure().as_dict(),
                                                    'waited_s': round(chk.waited_s, 1)}
                            print(f"[bench] {_speed_label(res)}", flush=True)
                            results.append(res)
    except _Refused:
        pass
    finally:
        probe.close()
    bag_speed = {} if args.skip_bag or refused else process_bag_speed(out / 'logs')
    md = to_markdown(results, bag_speed, commit)
    if refused:
        md += f'\n**Refused** after {len(results)} case(s): {refused}.\n'
    (out / 'bench.md').write_text(md)
    (out / 'bench.json').write_text(json.dumps({'commit': commit, 'results': results,
                                                'process_bag': bag_speed, 'refused': refused,
                                                'speed_nominal_ms': speed_gauge.NOMINAL_MS},
                                               indent=2))
    print(md)
    print(f'[bench] wrote {out / "bench.md"} and {out / "bench.json"}')
    return 3 if refused else 0


class _Refused(Exception):
    """The machine stayed slower than --max-slow: no more cases."""


def _run_against(p, args, argv, root: Path) -> int:
    from kinect_experiments import ab
    given = set(a.split('=')[0] for a in (argv if argv is not None else sys.argv[1:]))
    case = ['--users', args.users, '--seconds', str(args.seconds), '--warmup', str(args.warmup),
            '--reconstruction', args.reconstruction,
            '--modes', args.modes if '--modes' in given else 'processes',
            '--sensors', args.sensors if '--sensors' in given else '1',
            '--executors', args.executors]
    if args.no_physics:
        case.append('--no-physics')
    if args.drivers_elsewhere:
        case.append('--drivers-elsewhere')
    if args.phase_ms is not None:
        case += ['--phase-ms', str(args.phase_ms)]
    if args.skip_bag or '--skip-bag' not in given:
        case.append('--skip-bag')
    if args.alternations < 1:
        p.error('--alternations must be >= 1')
    out = Path(args.out if '--out' in given else str(root / 'out' / 'bench-ab')).resolve()
    line = ' '.join(argv if argv is not None else sys.argv[1:])
    try:
        return ab.run_ab(root, args.against, case, args.alternations, out,
                         max_busy=ab.MAX_BUSY if args.max_busy is None else args.max_busy,
                         wait_s=args.load_wait, ignore_load=args.ignore_load,
                         fail_ratio=args.fail_ratio, args_line=line, max_slow=args.max_slow,
                         max_speed_change=(ab.MAX_SPEED_CHANGE if args.max_speed_change is None
                                           else args.max_speed_change),
                         speed_wait_s=args.slow_wait)
    except (ValueError, RuntimeError, OSError, subprocess.CalledProcessError) as e:
        print(f'[bench] {e}', file=sys.stderr)
        return 2


if __name__ == '__main__':
    sys.exit(main())
