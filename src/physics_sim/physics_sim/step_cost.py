"""``python -m physics_sim.step_cost``: the CPU time one output frame of the physics character
costs in this process (no ROS): ``--users`` characters side by side, swaying, driven as the
physics node drives its simulation (a serialized SkeletonArray of every user's target decoded and
set, ``advance(1/30)``, the states encoded as the node publishes them), with the node's default
settings. Prints the process CPU ms per frame (mean, median, 10th percentile of the frames: CPU
time, valid on a loaded machine only as a comparison made in the same minutes, old and new
alternated), the medians of its parts (input: decode and targets; steps: ``advance``; output:
states and encoding) and a digest of every output (positions and orientations, bit for bit): two
builds with the same digest computed the same numbers.

    python -m physics_sim.step_cost --users 6 --frames 300 [--spacing 0.8] [--solver pgs]
"""
from __future__ import annotations

import argparse
import hashlib
import sys
import time

import numpy as np


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog='step_cost', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--users', type=int, default=6)
    p.add_argument('--frames', type=int, default=300, help='timed frames (after 30 untimed)')
    p.add_argument('--spacing', type=float, default=1.2,
                   help='m between neighbours (0.8: their arms touch)')
    p.add_argument('--solver', default='auto', help='SimConfig.solver (auto, pgs, cg, newton)')
    args = p.parse_args(argv)
    if not (1 <= args.users <= 6 and args.frames >= 1 and 0.3 <= args.spacing <= 5.0):
        print('step_cost: --users must be 1-6, --frames at least 1, --spacing 0.3-5 m',
              file=sys.stderr)
        return 2

    from skeleton_core.cdr import frames_from_cdr, frames_to_cdr
    from skeleton_core.conversions import SkeletonFrame
    from skeleton_core.model import NUM_JOINTS, TRACKED, standard_body
    from .output import output_frames
    from .simulation import SimConfig, Simulation, warm_up

    warm_up()
    rest = standard_body().rest_positions() - np.array([0.0, 0.0, 0.8])
    try:
        config = SimConfig(solver=args.solver)
        config.validate()
    except ValueError as e:
        print(f'step_cost: {e}', file=sys.stderr)
        return 2
    sim = Simulation(config)
    digest = hashlib.sha256()
    sway = np.arange(NUM_JOINTS)[:, None] * 0.3

    tracked = np.full(NUM_JOINTS, TRACKED, np.uint8)
    parts = {'input': [], 'steps': [], 'output': []}
    lift = np.zeros(3)

    def message(k: int) -> bytes:
        """The reconstruction's message of frame ``k`` (not timed: the sender's cost)."""
        frames = []
        for u in range(args.users):
            pos = rest + np.array([0.0, args.spacing * (u - 2.5), 0.0])   # side by side
            pos = pos + 0.05 * np.sin(0.2 * k + u + sway)
            pos[[7, 11], 2] += 0.2 * np.sin(0.1 * k + u)       # the hands up and down
            frames.append(SkeletonFrame(pos, tracked, user_id=u + 1, stamp_ns=k * 33_333_333))
        return frames_to_cdr(frames, k * 33_333_333, 'kinect_link')

    def frame(data: bytes) -> None:
        c0 = time.process_time()
        stamp, _, frames = frames_from_cdr(data, [])
        sim.set_targets([(f.user_id, f.positions, f.orientations, f.stamp_ns or stamp)
                         for f in frames])
        c1 = time.process_time()
        sim.advance(1 / 30)
        c2 = time.process_time()
        states = sim.states()
        out, latest, ok = output_frames(states, lift, 'world')
        frames_to_cdr(out, latest, 'world', validated=ok)
        c3 = time.process_time()
        for name, dt in (('input', c1 - c0), ('steps', c2 - c1), ('output', c3 - c2)):
            parts[name].append(dt)
        for uid in sorted(states):
            digest.update(states[uid].positions.tobytes())
            digest.update(states[uid].orientations.tobytes())

    for k in range(30):
        frame(message(k))
    per = []
    for v in parts.values():
        v.clear()
    for k in range(30, 30 + args.frames):
        data = message(k)
        t0 = time.process_time()
        frame(data)
        per.append(time.process_time() - t0)
    ms = 1000.0 * np.array(per)
    med = {k: 1000.0 * float(np.median(v)) for k, v in parts.items()}
    print(f'{args.users} users {args.spacing:g} m apart, {args.frames} frames, controller '
          f'{sim.controller}, solver {args.solver}: CPU '
          f'{ms.mean():.2f} ms per frame (median {np.median(ms):.2f}, p10 '
          f'{np.percentile(ms, 10):.2f}); medians: input {med["input"]:.2f}, steps '
          f'{med["steps"]:.2f}, output {med["output"]:.2f}; outputs digest '
          f'{digest.hexdigest()[:16]}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
