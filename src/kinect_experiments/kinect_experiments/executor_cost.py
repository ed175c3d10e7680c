"""``python -m kinect_experiments.executor_cost``: the CPU time one wake-up of a node's executor
costs, per executor, measured by this process's CPU time (not the wall clock: valid on a loaded
machine). A lifecycle node as every graph node is one (its five lifecycle services, a
subscription and a timer firing every 2 ms) is spun in 0.25 s slices, as ``run_node`` spins a
node process; the executors alternate in fresh processes (single, events, single, events ...).
Also counts what a timer made and destroyed per frame leaves behind (rclpy keeps a weak
reference per timer ever made in the node's callback group).

    python -m kinect_experiments.executor_cost [--callbacks 5000] [--rounds 2]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys


def _child(kind: str, n: int) -> dict:
    import resource

    import rclpy
    from rclpy.lifecycle import LifecycleNode
    from skeleton_msgs.msg import SkeletonArray

    from skeleton_core.rosnode import node_executor
    rclpy.init()
    node = LifecycleNode('executor_cost')
    node.create_subscription(SkeletonArray, '~/unused', lambda m: None, 10)   # in the wait set
    ex = node_executor(kind)
    count = [0]
    node.create_timer(0.002, lambda: count.__setitem__(0, count[0] + 1))
    ex.add_node(node)
    while count[0] < 200:                       # warm-up: imports, first waits
        ex.spin_once(timeout_sec=0.25)

    def cpu():
        ru = resource.getrusage(resource.RUSAGE_SELF)
        return ru.ru_utime + ru.ru_stime
    c0, k0 = cpu(), count[0]
    while count[0] - k0 < n:
        ex.spin_once(timeout_sec=0.25)
    per_wake_us = (cpu() - c0) * 1e6 / (count[0] - k0)
    before = len(node.default_callback_group.entities)
    for _ in range(1000):                       # a one-shot timer per frame, made and destroyed
        t = node.create_timer(1.0, lambda: None)
        node.destroy_timer(t)
    left = len(node.default_callback_group.entities) - before
    node.destroy_node()
    rclpy.try_shutdown()
    return {'executor': kind, 'cpu_us_per_wakeup': per_wake_us, 'refs_left_per_1000_timers': left}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog='executor_cost', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--callbacks', type=int, default=5000)
    p.add_argument('--rounds', type=int, default=2)
    p.add_argument('--child', default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        print(json.dumps(_child(args.child, args.callbacks)))
        return 0
    rows = []
    for _ in range(args.rounds):
        for kind in ('single', 'events'):
            out = subprocess.run([sys.executable, '-m', 'kinect_experiments.executor_cost',
                                  '--child', kind, '--callbacks', str(args.callbacks)],
                                 capture_output=True, text=True, env=dict(os.environ))
            if out.returncode != 0:
                print(f'[executor_cost] {kind}: {out.stderr.strip().splitlines()[-1:]}',
                      file=sys.stderr)
                return 1
            rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
    print('| executor | CPU us per wake-up | weak refs left per 1000 timers made and destroyed |')
    print('|---|---:|---:|')
    for r in rows:
        print(f"| {r['executor']} | {r['cpu_us_per_wakeup']:.0f} | {r['refs_left_per_1000_timers']} |")
    print(f'(load average {os.getloadavg()[0]:.1f}: CPU time of the process, not wall time)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
