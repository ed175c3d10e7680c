"""Cost of one viz publish: ``python -m viz.bench [--users 2] [--ticks 100]``.

Every tick all layers change (as with 30 Hz inputs): marker geometry (:mod:`viz.markers`) and the
conversion to ``visualization_msgs/Marker`` messages (needs the ROS 2 Python packages).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS, standard_body

from . import markers as mk


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='viz.bench', description=__doc__)
    ap.add_argument('--users', type=int, default=2)
    ap.add_argument('--ticks', type=int, default=100)
    a = ap.parse_args(argv)
    from .viz_node import MarkerCache
    rng = np.random.default_rng(0)
    rest = standard_body().rest_positions()
    scene = mk.SceneState(layers=mk.LAYERS)
    cache = MarkerCache()
    t_build = t_msg = 0.0
    n_markers = 0
    for k in range(a.ticks):
        for layer in mk.LAYERS:
            frames = [SkeletonFrame(positions=rest + (2.5, u - a.users / 2, 0.0)
                                    + rng.normal(0, 0.01, rest.shape),
                                    tracking_state=np.full(NUM_JOINTS, 2, np.uint8),
                                    reliability=rng.uniform(0, 1, NUM_JOINTS).astype(np.float32),
                                    user_id=u + 1, stamp_ns=k, frame_id='kinect_link')
                      for u in range(a.users)]
            scene.update(layer, frames, 0.0)
        t0 = time.perf_counter()
        specs = scene.build(0.0)
        t1 = time.perf_counter()
        [cache.to_msg(s, 0.5) for s in specs]
        t2 = time.perf_counter()
        t_build += t1 - t0
        t_msg += t2 - t1
        n_markers = len(specs)
    print(f'viz: {a.users} user(s), {len(mk.LAYERS)} layers, {n_markers} markers per publish: '
          f'geometry {1e3 * t_build / a.ticks:.2f} ms + messages {1e3 * t_msg / a.ticks:.2f} ms '
          f'per publish (mean of {a.ticks})')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
