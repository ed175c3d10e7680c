"""``python -m kinect_experiments.physics_memory``: the physics node's resident memory while users
come and go, without DDS and without the wall clock (valid on a loaded machine): the node is
configured and activated in this process and handed serialized input frames directly (capture
stamps one period apart), ``--users`` steady users and one visitor replaced every
``--visitor-every`` frames (a world recompile each time). Prints the RSS every 60 frames and its
Theil-Sen slope after the first quarter, in kB per frame (x 30 = kB/s at 30 Hz; the soak's
limit 0.05 MB/s is 1.7 kB per frame). ``--no-release`` runs it with the freed heap pages kept
(``skeleton_core.memory.release_freed_memory`` a no-op) for an A/B.

    python -m kinect_experiments.physics_memory --frames 900 --users 5 --visitor-every 90
"""
from __future__ import annotations

import argparse
import sys


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog='physics_memory', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--frames', type=int, default=900)
    p.add_argument('--users', type=int, default=5)
    p.add_argument('--visitor-every', type=int, default=90)
    p.add_argument('--no-release', action='store_true')
    args = p.parse_args(argv)

    import numpy as np
    import rclpy
    from rclpy.parameter import Parameter

    from skeleton_core.cdr import frames_to_cdr
    from skeleton_core.conversions import SkeletonFrame
    from skeleton_core.memory import rss_mb, slope
    from skeleton_core.model import NUM_JOINTS, TRACKED, standard_body
    from skeleton_core.rosnode import bring_up, node_executor
    from skeleton_core.tf import Transform
    from physics_sim import simulation
    from physics_sim.physics_node import PhysicsNode
    if args.no_release:
        simulation.release_freed_memory = lambda: False

    rclpy.init()
    node = bring_up(PhysicsNode(parameter_overrides=[
        Parameter('user_timeout_s', value=60.0)]))   # users leave when this tool says
    node.tf.set('world', 'kinect_link', Transform.from_xyz_ypr(0, 0, 0.8))
    ex = node_executor()
    ex.add_node(node)
    rng = np.random.default_rng(0)
    base = standard_body().rest_positions() + np.array([2.5, 0.0, -0.8])
    t0, period = 1_000_000_000_000, 33_333_333
    visitor, samples = 1000, []
    try:
        for i in range(args.frames):
            if i % args.visitor_every == 0:
                if visitor > 1000:   # the visitor leaves (as the node's timeout would do)
                    node._user_stamp.pop(visitor, None)
                    node.presence.forget(visitor)
                    node.sim.remove_character(visitor)
                visitor += 1
            stamp = t0 + i * period
            frames = [SkeletonFrame(
                positions=base + np.array([0.0, 0.8 * k - 2.0, 0.0]) + rng.normal(0, 0.01, base.shape),
                tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8), user_id=u,
                stamp_ns=stamp, frame_id='kinect_link')
                for k, u in enumerate(list(range(1, args.users + 1)) + [visitor])]
            node._on_input(frames_to_cdr(frames, stamp, 'kinect_link'))
            for _ in range(3):
                ex.spin_once(timeout_sec=0.0)
            if i % 10 == 0:
                samples.append((i, rss_mb()))
            if i % 60 == 0:
                print(f'frame {i}: RSS {samples[-1][1]:.1f} MB', flush=True)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    t = np.array([s[0] for s in samples], float)
    y = np.array([s[1] for s in samples])
    kb = 1024.0 * slope(t, y, warmup=0.25)
    print(f'RSS {y[0]:.1f} -> {y[-1]:.1f} MB over {args.frames} frames, '
          f'{args.frames // args.visitor_every} visitors; slope after the first quarter '
          f'{kb:.2f} kB per frame = {kb * 30 / 1024:.3f} MB/s at 30 Hz'
          + (' (freed pages kept: --no-release)' if args.no_release else ''))
    return 0


if __name__ == '__main__':
    sys.exit(main())
