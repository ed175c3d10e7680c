"""The control step's CPU time, main against this branch in one run (issue 30 item 2).

    python scripts/control30/cpu_ab.py [--main /work/main] [--rounds 2] [--frames 900]

Records one stream first (the continuous performance's seed 0 through the sensor model, the
first ``--frames`` frames, into out/cpu_ab_stream.npz), then steps a fresh PerformanceController
over the same frames in a subprocess per checkout -- main, branch, main, branch, ... -- with
``performance_control`` and ``physics_sim`` imported from that checkout's src (the others
from the environment), and prints the CPU time (time.thread_time) per step: median and p95, and the
sum of the per-step figures over the run. ``--profile`` prints the branch's cProfile instead;
``--bench`` times the steps of ``bench_control``'s physics runs (bars, rope, trampoline, water on
the test seeds: the figure ``bench_control`` prints) instead of the recorded stream.
"""
import argparse
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[2]

CHILD = r'''
import sys, time, numpy as np
from performance_control import __file__ as where
import physics_sim.feature_geometry as fg
from performance_control.features import load_world
from performance_control.controller import ControlParams, PerformanceController
z = np.load(sys.argv[1])
sa, sta = z['frames'], z['states']
ctl = PerformanceController(load_world('playground'), ControlParams(sensor_height=1.2))
cpu = []
def run():
    for i in range(len(sa)):
        c = time.thread_time()
        ctl.step(sa[i], i / 30.0, sta[i])
        cpu.append(time.thread_time() - c)
if len(sys.argv) > 2:
    import cProfile, pstats
    cProfile.run('run()', sys.argv[2])
    pstats.Stats(sys.argv[2]).sort_stats('tottime').print_stats(25)
else:
    run()
c = 1e3 * np.array(cpu[5:])
print(f'{where} ({fg.__file__}): {len(c)} steps, CPU median {np.median(c):.2f} ms, p95 '
      f'{np.percentile(c, 95):.2f} ms, mean {c.mean():.2f} ms', flush=True)
'''


BENCH = r'''
import time, numpy as np
from performance_control import __file__ as where, bench, controller
from performance_control.features import load_world
cpu = []
orig = controller.PerformanceController.step
def step(self, *a, **k):
    c = time.thread_time()
    o = orig(self, *a, **k)
    cpu.append(time.thread_time() - c)
    return o
controller.PerformanceController.step = step
bench.PerformanceController.step = step
bench.physics(load_world('playground'), controller.ControlParams(sensor_height=1.2), 1000)
c = 1e3 * np.array(cpu[1:])
print(f'{where} bench.physics: {len(c)} steps, CPU median {np.median(c):.2f} ms, p95 '
      f'{np.percentile(c, 95):.2f} ms, mean {c.mean():.2f} ms', flush=True)
'''


def record(path: Path, frames: int) -> None:
    from performance_control.features import load_world
    from performance_control.performances import continuous_stream, _watched_sensor
    w = load_world('playground')
    a, _ = continuous_stream(w, np.random.default_rng(0), rope_at=13.2)
    sa, sta = _watched_sensor(a, 0, True)
    np.savez(path, frames=sa[:frames], states=sta[:frames])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--main', default='/work/main')
    ap.add_argument('--rounds', type=int, default=2)
    ap.add_argument('--frames', type=int, default=900)
    ap.add_argument('--profile', action='store_true')
    ap.add_argument('--bench', action='store_true')
    a = ap.parse_args()
    out = HERE / 'out'
    out.mkdir(exist_ok=True)
    stream = out / 'cpu_ab_stream.npz'
    record(stream, a.frames)
    trees = [('main', Path(a.main)), ('branch', HERE)]
    if a.profile:
        trees, a.rounds = trees[1:], 1
    for _ in range(a.rounds):
        for label, root in trees:
            env = dict(os.environ)
            env['PYTHONPATH'] = os.pathsep.join(
                [str(root / 'src' / pkg) for pkg in ('performance_control', 'physics_sim')]
                + [env.get('PYTHONPATH', '')])
            args = [sys.executable, '-c', BENCH if a.bench else CHILD, str(stream)]
            if a.profile:
                args.append(str(out / 'cpu_ab.prof'))
            r = subprocess.run(args, env=env, capture_output=True, text=True)
            print(label, (r.stdout + r.stderr).strip(), flush=True)


if __name__ == '__main__':
    main()
