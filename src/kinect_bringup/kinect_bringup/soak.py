"""``soak``: run the graph (one process per node) for a long time under abuse and check it survives.

    ros2 run kinect_bringup soak                 # 10 minutes (make soak)
    ros2 run kinect_bringup soak --duration 45   # the shortened soak the test suite runs

While the synthetic driver streams one user, an injector publishes on /kinect/skeletons: visitors
appearing and vanishing, bursts and gaps, and malformed messages of every kind (fuzz.MUTATIONS);
parameters are changed at run time; one node at a time is killed (SIGKILL) and restarted. It ends
with a report: crashes, NaN outputs, RSS growth after warm-up per process, recovery times, and
exits non-zero when a target is missed (no crash, no NaN, RSS growth < 5 %, every restart recovers,
every parameter change accepted).

RSS growth is judged per OS process, never across a restart: for each node the longest-lived of
its processes (the first one, or the one started by a restart), from 25 % of that process's life
on (the median of the last third of that window against the median of its first third: the RSS
follows the load, e.g. the number of characters in the physics world), and only when that
process lived at least --rss-min-duration s (default 120). Over a shorter
window the figures are reported but allocator and cache warm-up cannot be told from a leak: the
node's entry says ``judged: false`` and, when no process was judged (e.g. the 45 s soak of the test
suite), ``rss_verdict`` says ``skipped``.
"""
from __future__ import annotations

import argparse
import json
import random
import sys
import time
from pathlib import Path
from typing import Dict, List

import numpy as np

from .graph import repo_root
from .processes import Graph

# run-time parameter changes the soak cycles through: (node, parameter, values), per
# reconstruction layout (names as declared by the nodes, see config/<node>.yaml)
PARAM_CHANGES = {
    'fused': [
        ('reconstruction', 'optimizer.k', [20, 30]),
        ('reconstruction', 'optimizer.steps', [10, 20]),
        ('reconstruction', 'reliability.theta_roof_deg', [130.0, 135.0]),
        ('reconstruction', 'completion.reliable_threshold', [0.4, 0.5]),
        ('physics', 'kp', [None]),  # None: read the current value and set it again
    ],
    'split': [
        ('optimizer', 'k', [20, 30]),
        ('optimizer', 'steps', [10, 20]),
        ('reliability', 'theta_roof_deg', [130.0, 135.0]),
        ('completion', 'reliable_threshold', [0.4, 0.5]),
        ('physics', 'kp', [None]),
    ],
}
NODES = {'fused': ['driver', 'reconstruction', 'physics'],
         'split': ['driver', 'reliability', 'completion', 'optimizer', 'physics']}
KILL_ORDER = {'fused': ['reconstruction', 'physics'],
              'split': ['reliability', 'optimizer', 'physics', 'completion']}
OUTPUT_TOPIC = {'reliability': '/kinect/skeletons_reliability', 'completion': '/posture/completed',
                'optimizer': '/posture/reconstructed', 'reconstruction': '/posture/reconstructed',
                'physics': '/character/skeletons'}
# a killed process's last messages are delivered within this; a new process cannot publish
# sooner (interpreter start + imports take seconds), so output later than this is the new one's
IN_FLIGHT_S = 0.3


def main(argv=None) -> int:
    root = repo_root() or Path.cwd()
    ap = argparse.ArgumentParser(prog='soak', description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--duration', type=float, default=600.0, help='seconds (default 10 min)')
    ap.add_argument('--kills', type=int, default=None, help='node kills (default: 1 per 2.5 min, >= 1)')
    ap.add_argument('--seed', type=int, default=0)
    ap.add_argument('--reconstruction', choices=sorted(NODES), default='fused',
                    help='the reconstruction as one node (default, as launched) or as three')
    ap.add_argument('--rss-min-duration', type=float, default=120.0,
                    help='judge RSS growth only on runs at least this long (s)')
    ap.add_argument('--out', default=str(root / 'out' / 'soak'))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rnd = random.Random(args.seed)

    import psutil
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from skeleton_msgs.msg import SkeletonArray

    from skeleton_data.database import load_or_build_default
    from .fuzz import MUTATIONS, malformed, valid_array
    load_or_build_default()

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = Node('soak_injector', context=ctx)
    pub = node.create_publisher(SkeletonArray, '/kinect/skeletons', 50)
    outputs = {'/posture/reconstructed': [], '/character/skeletons': [], '/posture/completed': [],
               '/kinect/skeletons_reliability': []}
    nan_outputs = {t: 0 for t in outputs}

    def on_out(topic, msg):
        outputs[topic].append(time.monotonic())
        for sk in msg.skeletons:
            if not all(np.isfinite([p.x + p.y + p.z for p in sk.positions])):
                nan_outputs[topic] += 1

    for t in outputs:
        node.create_subscription(SkeletonArray, t, lambda m, t=t: on_out(t, m), 50)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)

    def spin_for(seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=min(0.01, max(0.0, end - time.monotonic())))

    nodes = NODES[args.reconstruction]
    graph = Graph('processes', nodes=nodes, overrides={'driver': {'num_users': 1}},
                  log_dir=out / 'logs')
    report: Dict = {'duration_s': args.duration, 'malformed_sent': {}, 'param_changes': [],
                    'kills': [], 'crashes': [], 'rss_mb': {}}
    rss: Dict[str, List] = {n: [] for n in nodes}
    expected_dead = set()
    t_start = time.monotonic()
    try:
        # wait for the graph to come up
        deadline = time.monotonic() + 120
        while not outputs['/posture/reconstructed'] and time.monotonic() < deadline:
            spin_for(0.2)
        if not outputs['/posture/reconstructed']:
            print('[soak] the graph never produced /posture/reconstructed', file=sys.stderr)
            report['crashes'].append('no output at start')
            return 1
        t0 = time.monotonic()
        n_kills = args.kills if args.kills is not None else max(1, int(args.duration // 150))
        kill_times = [t0 + args.duration * (i + 1) / (n_kills + 1) for i in range(n_kills)]
        next_param = t0 + 5.0
        next_rss = t0
        visitors: Dict[int, float] = {}
        stamp_back = 0
        i_param = 0
        last_ns = [0]

        def fresh_ns():
            # every injected message gets its own stamp: two equal stamps would be dropped as
            # 'duplicate stamp' before the malformed one is even validated
            last_ns[0] = max(time.time_ns(), last_ns[0] + 1)
            return last_ns[0]

        while time.monotonic() - t0 < args.duration:
            now = time.monotonic()
            ns = fresh_ns()
            # visitors appear and vanish
            if rnd.random() < 0.02 and len(visitors) < 3:
                visitors[rnd.randint(50, 60)] = now + rnd.uniform(1, 6)
            visitors = {u: t for u, t in visitors.items() if t > now}
            if visitors and rnd.random() < 0.9:
                pub.publish(valid_array(ns, sorted(visitors), rng=np.random.default_rng(int(ns % 1000))))
            # bursts and gaps
            if rnd.random() < 0.005:
                for k in range(30):
                    pub.publish(valid_array(fresh_ns(), (70,)))
            # malformed messages, and stamps going backwards
            if rnd.random() < 0.1:
                kind = rnd.choice(sorted(MUTATIONS))
                pub.publish(malformed(kind, fresh_ns(), user_id=rnd.choice([1, 71])))
                report['malformed_sent'][kind] = report['malformed_sent'].get(kind, 0) + 1
            if rnd.random() < 0.01:
                # alternately a small step back (dropped as out of order) and a bag loop (every
                # user restarts)
                back = 300_000_000 if stamp_back % 2 == 0 else 5_000_000_000
                pub.publish(valid_array(fresh_ns() - back, (72,)))
                stamp_back += 1
            # parameter changes at run time
            if now > next_param:
                changes = PARAM_CHANGES[args.reconstruction]
                nname, pname, values = changes[i_param % len(changes)]
                i_param += 1
                next_param = now + 7.0
                report['param_changes'].append(_set_param(node, ex, nname, pname, values, rnd))
            # kill one node and restart it
            if kill_times and now > kill_times[0]:
                kill_times.pop(0)
                order = KILL_ORDER[args.reconstruction]
                victim = order[len(report['kills']) % len(order)]
                expected_dead.add(victim)
                graph.restart(victim)
                expected_dead.discard(victim)
                mark = len(outputs['/posture/reconstructed'])
                t_kill = time.monotonic()
                report['kills'].append({'node': victim, 't': t_kill - t0, '_mark': mark,
                                        '_t': t_kill})
            # watch processes
            for n, alive in graph.alive().items():
                if not alive and n not in expected_dead:
                    code = graph.procs[n].returncode
                    report['crashes'].append(f'{n} exited with {code} at {now - t0:.0f} s')
                    expected_dead.add(n)
            if now > next_rss:
                next_rss = now + 2.0
                for n, p in graph.procs.items():
                    try:
                        rss[n].append((now - t0, psutil.Process(p.pid).memory_info().rss / 2 ** 20,
                                       p.pid))
                    except psutil.NoSuchProcess:
                        pass
            spin_for(1 / 30)
        # recovery after each kill: the restarted node's own output, then the end of the graph
        for k in report['kills']:
            own = [t for t in outputs[OUTPUT_TOPIC[k['node']]] if t > k['_t'] + IN_FLIGHT_S]
            k['recovered_after_s'] = (own[0] - k['_t']) if own else None
            if own:
                end = [t for t in outputs['/character/skeletons'] if t > own[0]]
                k['graph_output_after_s'] = (end[0] - k['_t']) if end else None
            k.pop('_mark'), k.pop('_t')
    finally:
        codes = graph.stop()
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    report['exit_codes'] = codes
    for n, code in codes.items():
        if code != 0 and f'{n} exited' not in ' '.join(report['crashes']):
            report['crashes'].append(f'{n} exited with {code} when stopped (SIGINT)')
    for log in sorted((out / 'logs').glob('*.log')):
        if 'Traceback' in log.read_text(errors='replace'):
            report['crashes'].append(f'traceback in {log}')
    report['stamps_backwards_sent'] = stamp_back
    report['nan_outputs'] = nan_outputs
    report['outputs'] = {t: len(v) for t, v in outputs.items()}
    growth_ok = True
    restarted = {k['node'] for k in report['kills']}
    judged = []
    for n, samples in rss.items():
        if len(samples) < 4:
            continue
        by_pid: Dict[int, List] = {}
        for t, mb, pid in samples:
            by_pid.setdefault(pid, []).append((t, mb))
        seg = max(by_pid.values(), key=lambda v: v[-1][0] - v[0][0])  # longest-lived process
        life = seg[-1][0] - seg[0][0]
        warm = [mb for t, mb in seg if t >= seg[0][0] + 0.25 * life]
        entry = {'process_life_s': round(life, 1), 'restarted': n in restarted,
                 'last': samples[-1][1], 'judged': False,
                 # (s, MB) about every 30 s, to see the trend (samples are every 2 s)
                 'series': [(round(t), round(mb, 1)) for t, mb, _ in samples[::15]]}
        if len(warm) >= 2:
            # the RSS follows the load (a physics world with more visitors is bigger): a leak is
            # the level rising, so the first and the last third of the window are compared by
            # their medians, not one sample against another
            k = max(1, len(warm) // 3)
            base, last = float(np.median(warm[:k])), float(np.median(warm[-k:]))
            g = (last - base) / base * 100.0
            entry.update(after_warmup=base, last=last, growth_percent=g,
                         first_to_last_sample_percent=(warm[-1] - warm[0]) / warm[0] * 100.0,
                         judged=life >= args.rss_min_duration)
            if entry['judged']:
                judged.append(n)
                growth_ok &= g < 5.0
        report['rss_mb'][n] = entry
    report['rss_verdict'] = (f'judged on {", ".join(judged)}' if judged else
                             f'skipped: no process lived --rss-min-duration '
                             f'{args.rss_min_duration:g} s (run of {args.duration:g} s)')
    recovered = all(k.get('recovered_after_s') is not None and
                    k.get('graph_output_after_s') is not None for k in report['kills'])
    # a name the node does not declare, or a valid value refused, is a failure; no answer is not
    # (a node busy or being restarted on a loaded machine)
    refused = [c for c in report['param_changes']
               if c['result'].startswith('refused') or c['result'] == 'unknown parameter']
    ok = (not report['crashes'] and sum(nan_outputs.values()) == 0 and growth_ok and recovered
          and not refused)
    report['ok'] = ok
    (out / 'soak.json').write_text(json.dumps(report, indent=2, default=str))
    print(json.dumps(report, indent=2, default=str))
    print(f'[soak] {"PASSED" if ok else "FAILED"} after {time.monotonic() - t_start:.0f} s; '
          f'crashes {len(report["crashes"])}, NaN outputs {sum(nan_outputs.values())}, '
          f'restarts recovered {sum(k.get("recovered_after_s") is not None for k in report["kills"])}'
          f'/{len(report["kills"])}, refused parameter changes {len(refused)}, '
          f'RSS {report["rss_verdict"]}' + ('' if growth_ok else ' (growth >= 5 %)'))
    print(f'[soak] report {out / "soak.json"}, node logs {out / "logs"}')
    return 0 if ok else 1


def _set_param(node, ex, nname, pname, values, rnd) -> Dict:
    from rcl_interfaces.srv import GetParameters, SetParameters
    from rclpy.parameter import Parameter, parameter_value_to_python

    def call(srv, name, req):
        cli = node.create_client(srv, name)
        try:
            if not cli.wait_for_service(timeout_sec=2.0):
                return None
            fut = cli.call_async(req)
            end = time.monotonic() + 3.0
            while not fut.done() and time.monotonic() < end:
                ex.spin_once(timeout_sec=0.01)
            return fut.result() if fut.done() else None
        finally:
            node.destroy_client(cli)

    value = rnd.choice(values)
    if value is None:
        res = call(GetParameters, f'/{nname}/get_parameters', GetParameters.Request(names=[pname]))
        if res is None or not res.values:
            return {'node': nname, 'param': pname, 'result': 'unavailable'}
        value = parameter_value_to_python(res.values[0])
        if value is None:
            return {'node': nname, 'param': pname, 'result': 'unknown parameter'}
    res = call(SetParameters, f'/{nname}/set_parameters',
               SetParameters.Request(parameters=[Parameter(pname, value=value).to_parameter_msg()]))
    if res is None:
        return {'node': nname, 'param': pname, 'result': 'no answer'}
    r = res.results[0]
    return {'node': nname, 'param': pname, 'value': value,
            'result': 'ok' if r.successful else f'refused: {r.reason}'}


if __name__ == '__main__':
    sys.exit(main())
