"""Compile the workspace's numba kernels once, into numba's on-disk cache, before anything runs.

    python -m kinect_bringup.warm_kernels

Every node compiles (or loads) its kernels when it starts; after a fresh build that first compile
takes seconds per kernel module (10-25 s for Eq. 1-8 on a loaded 2-core machine), and the graph's
processes would each pay it at once, side by side. ``scripts/run-tests.sh`` runs this first, so
the test suite's nodes load compiled code. Nothing happens with ``KINECT_NUMBA=0`` or without numba.

First it writes the workspace's Python bytecode (:mod:`kinect_bringup.bytecode`), which the first
start of the graph would otherwise compile in every process at once.
"""
from __future__ import annotations

import sys
import time

from physics_sim.simulation import warm_up as warm_physics
from pose_reconstruction.fusion_kernels import warm_up as warm_fusion
from pose_reconstruction.kernels import warm_up as warm_optimizer
from pose_reconstruction.reliability_kernels import warm_up as warm_reliability
from pose_reconstruction.segment_output_kernels import warm_up as warm_segment_output
from skeleton_core import jit

from kinect_bringup.bytecode import compile_workspace


def main(argv=None) -> int:
    t = time.perf_counter()
    try:
        n, failed = compile_workspace()
        print(f'warm_kernels: bytecode of {n} workspace file(s) written in '
              f'{time.perf_counter() - t:.1f} s' + (f' ({failed} failed)' if failed else ''))
    except Exception as e:  # noqa: BLE001 - not installed (no ament index): the kernels still
        print(f'warm_kernels: no bytecode written ({e})')
    if not jit.enabled():
        print('warm_kernels: numba off (KINECT_NUMBA=0 or not installed): nothing to compile')
        return 0
    t0 = time.perf_counter()
    for name, warm in (('reliability (Eq. 1-8)', warm_reliability),
                       ('optimizer (Eq. 15)', warm_optimizer), ('physics (Eq. 1)', warm_physics),
                       ('multi-sensor fusion', warm_fusion),
                       ('segment output', warm_segment_output)):
        t = time.perf_counter()
        warm()
        print(f'warm_kernels: {name} {time.perf_counter() - t:.1f} s')
    print(f'warm_kernels: compiled kernels ready in {time.perf_counter() - t0:.1f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
