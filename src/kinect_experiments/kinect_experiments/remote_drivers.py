"""``remote_drivers``: the benchmark's stand-in for sensor drivers that run on other machines.

A lab runs each Kinect's driver on the computer the sensor is plugged into; what such a driver
costs the machine of the graph is receiving its messages. ``bench --drivers-elsewhere`` therefore
generates the synthetic drivers' frames BEFORE the run (:func:`generate`: the same source, seeds,
users, views and frame ids as the ``driver`` nodes the bench would start) and serializes them
once; during the run this one light process (:func:`main`) publishes those bytes on each sensor's
topic at the sensor rate, every stamp rewritten to the frame's scheduled capture time
(``skeleton_core.cdr.restamp_cdr``: no message is built or decoded). Its CPU is measured and
printed beside the graph's, not counted in it.

    python -m kinect_experiments.remote_drivers FRAMES.pkl [--phase-ms 3]

Sensor k captures at ``start + i / rate + (k - 1) * phase``: unsynchronised sensors, at a fixed
phase so that runs compare (the default, 3 ms, is within the fusion's wait bound: the fusion waits
for sensor 2 on every frame). The frames loop when the run outlasts them (generate enough).
"""
from __future__ import annotations

import argparse
import pickle
import sys
import time
from pathlib import Path
from typing import Dict, List, Sequence

DEFAULT_PHASE_MS = 3.0
MAX_CATCHUP = 15   # frames, as kinect_driver.sources.synthetic


def sensor_topics(sensors: int) -> List[str]:
    """Each sensor's SkeletonArray topic, as the bench's drivers publish them."""
    from skeleton_core.tf import sensor_namespace
    if sensors == 1:
        return ['/kinect/skeletons']
    return [f'/{sensor_namespace(k, sensors)}/skeletons' for k in range(1, sensors + 1)]


def driver_values(users: int, sensors: int, k: int, overrides: Dict = None) -> Dict:
    """Sensor k's driver parameters as the bench starts it (config/driver.yaml, then the bench's
    values: users, scenario b, the sensor's frame and view)."""
    from kinect_bringup.graph import load_params
    from skeleton_core.tf import default_sensor_poses, format_pose, sensor_frame
    v = dict(load_params('driver'))
    v.update({'num_users': users, 'scenario': 'b'})
    if sensors > 1:
        poses = default_sensor_poses(sensors)
        v.update({'frame_id': sensor_frame(k, sensors),
                  'view_pose': format_pose(poses[0].inverse() * poses[k - 1])})
    v.update(overrides or {})
    return v


def generate(users: int, sensors: int, seconds: float, out: Path) -> Dict:
    """Serialize ``seconds`` of every sensor's synthetic frames into ``out`` (a pickle the
    publisher reads). Returns what it wrote: topics, rate, frame count, generation time."""
    from kinect_driver.sources.synthetic import SyntheticConfig, SyntheticSource
    from skeleton_core.cdr import frames_to_cdr, stamp_offsets
    from skeleton_core.params import build
    t0 = time.perf_counter()
    topics = sensor_topics(sensors)
    streams, rate = [], None
    for k, topic in enumerate(topics, start=1):
        v = driver_values(users, sensors, k)
        if v.get('source', 'synthetic') != 'synthetic':
            raise ValueError(f"--drivers-elsewhere replays the synthetic source, the driver's "
                             f"configuration says source {v['source']!r}")
        src = SyntheticSource.from_config(build(SyntheticConfig, v), frame_id=v['frame_id'])
        src.open()
        period = int(round(src.period_s * 1e9))
        rate = 1e9 / period
        n = max(1, int(round(seconds * rate)))
        msgs = []
        for i in range(n):   # poll(i periods): frame i of the motion, as a driver's i-th frame
            for o in src.poll(i * period):
                data = frames_to_cdr(o.frames, o.stamp_ns, o.frame_id or v['frame_id'])
                msgs.append((data, stamp_offsets(data)))
        src.close()
        streams.append({'topic': topic, 'messages': msgs[:n]})
    info = {'rate_hz': rate, 'frames': len(streams[0]['messages']), 'users': users,
            'sensors': sensors, 'generate_s': time.perf_counter() - t0}
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    with open(out, 'wb') as f:
        pickle.dump({**info, 'streams': streams}, f, protocol=pickle.HIGHEST_PROTOCOL)
    return {**info, 'topics': topics}


def main(argv: Sequence[str] = None) -> int:
    p = argparse.ArgumentParser(prog='remote_drivers', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('frames', help='the file bench --drivers-elsewhere generated')
    p.add_argument('--phase-ms', type=float, default=DEFAULT_PHASE_MS,
                   help='capture phase of sensor k+1 after sensor k (ms)')
    args, ros_args = p.parse_known_args(argv if argv is not None else sys.argv[1:])
    try:
        with open(args.frames, 'rb') as f:
            data = pickle.load(f)
    except (OSError, pickle.UnpicklingError, EOFError) as e:
        print(f'remote_drivers: cannot read {args.frames}: {e}', file=sys.stderr)
        return 2
    streams = data['streams']
    period_ns = 1e9 / data['rate_hz']
    phase_ns = int(args.phase_ms * 1e6)
    if not 0 <= phase_ns * (len(streams) - 1) < period_ns:
        print(f'remote_drivers: --phase-ms {args.phase_ms:g} x {len(streams) - 1} is not within '
              f'one frame period ({period_ns / 1e6:.1f} ms)', file=sys.stderr)
        return 2
    import rclpy
    from rclpy.qos import QoSProfile
    from skeleton_core.cdr import restamp_cdr
    from skeleton_msgs.msg import SkeletonArray
    rclpy.init(args=[sys.argv[0]] + ros_args)
    node = rclpy.create_node('remote_drivers')
    pubs = [node.create_publisher(SkeletonArray, s['topic'], QoSProfile(depth=10))
            for s in streams]
    n = data['frames']
    print(f"remote_drivers: {len(streams)} sensor(s), {data['users']} user(s), {n} frames "
          f"each at {data['rate_hz']:.1f} Hz, phase {args.phase_ms:g} ms: "
          + ', '.join(s['topic'] for s in streams), flush=True)
    start = time.time_ns() + 100_000_000
    i = 0
    try:
        while rclpy.ok():
            base = start + int(round(i * period_ns))
            behind = int((time.time_ns() - base) // period_ns)
            if behind > MAX_CATCHUP:   # stalled: skip the backlog, as the synthetic driver does
                i += behind
                continue
            for k, (s, pub) in enumerate(zip(streams, pubs)):
                due = base + k * phase_ns
                wait = (due - time.time_ns()) / 1e9
                if wait > 0:
                    time.sleep(wait)
                msg, offsets = s['messages'][i % n]
                pub.publish(restamp_cdr(msg, offsets, due))
            i += 1
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
