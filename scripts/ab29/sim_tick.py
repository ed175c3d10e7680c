"""Per-tick CPU time (thread_time) of physics_sim.Simulation at default config: targets from a
built-in clip for N users (spread 1.2 m apart), one tick = set targets + advance(1/30)."""
import json
import sys
import time

import numpy as np
from physics_sim.simulation import Simulation, SimConfig
from skeleton_data.motions import builtin_clips
users, ticks = int(sys.argv[1]), int(sys.argv[2])
sim = Simulation(SimConfig())
clip = builtin_clips()[0].positions
cpu, wall = [], []
for i in range(60 + ticks):
    st = 1_000_000_000 + i * 33_333_333
    t0, w0 = time.thread_time(), time.perf_counter()
    for u in range(users):
        p = clip[i % len(clip)].copy()
        p[:, 0] += 1.2 * u
        sim.set_target(u + 1, p, None, st)
    sim.advance(1 / 30)
    sim.states()
    if i >= 60:
        cpu.append(time.thread_time() - t0)
        wall.append(time.perf_counter() - w0)
c = np.array(cpu) * 1e3
print(json.dumps({'users': users, 'cpu_p50': round(float(np.median(c)), 2),
                  'cpu_p95': round(float(np.percentile(c, 95)), 2),
                  'cpu_mean': round(float(c.mean()), 2),
                  'wall_p50': round(float(np.median(wall)) * 1e3, 2)}))
