"""CPU time (thread_time) of PerformanceController.step over bench_control's physics runs."""

import sys
import time
import numpy as np
import performance_control
from performance_control import bench, controller
from performance_control.features import load_world
from performance_control.performances import SENSOR_HEIGHT

cpu, wall = [], []
orig = controller.PerformanceController.step


def step(self, *a, **k):
    c0, w0 = time.thread_time(), time.perf_counter()
    o = orig(self, *a, **k)
    cpu.append(time.thread_time() - c0)
    wall.append(time.perf_counter() - w0)
    return o


controller.PerformanceController.step = step
bench.PerformanceController.step = step
W = load_world("playground")
cp = controller.ControlParams(sensor_height=SENSOR_HEIGHT)
bench.physics(W, cp, 1000)
c, w = 1e3 * np.array(cpu[1:]), 1e3 * np.array(wall[1:])
print(
    f"{sys.argv[1]} {performance_control.__file__}: {len(c)} steps, "
    f"CPU median {np.median(c):.2f} ms p95 {np.percentile(c, 95):.2f}; "
    f"wall median {np.median(w):.2f} p95 {np.percentile(w, 95):.2f}",
    flush=True,
)
