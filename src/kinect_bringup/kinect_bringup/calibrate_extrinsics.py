"""``calibrate_extrinsics``: where the other sensors are, from the skeletons of one person walking
in their shared view for ~10 s (``skeleton_eval.extrinsics``). Writes the sensor-pose YAML that
``driver.launch.py extrinsics:=FILE`` (and ``pipeline.launch.py``) turn into the static TF.

    # two recordings (one per sensor PC, or one bag with both topics)
    ros2 run kinect_bringup calibrate_extrinsics kinect1.mcap kinect2.mcap --out cache/extrinsics.yaml
    ros2 run kinect_bringup calibrate_extrinsics both.mcap --out cache/extrinsics.yaml
    # live: the drivers of driver.launch.py sensors:=N are running (or its calibrate:=FILE)
    ros2 run kinect_bringup calibrate_extrinsics --live 2 --duration 12 --out cache/extrinsics.yaml
    # the synthetic source: the error against the true placement, over seeds
    ros2 run kinect_bringup calibrate_extrinsics --synthetic --seeds 3-12

The first sensor is the reference: its pose in world comes from the first bag's ``/tf_static``, else
``--reference-pose`` (default 0.8 m above the floor at the origin, as the launch files). Every
other sensor is calibrated against it. The person should walk round a loop 2.5-3 m across
where every sensor sees them (facing every way; walking on the spot leaves the rotation weak).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Dict, List, Tuple

import numpy as np

from skeleton_core.tf import (TfBuffer, Transform, WORLD_FRAME, format_pose, parse_pose,
                              sensor_frame, transforms_from_msg, transforms_to_yaml)
from skeleton_eval.extrinsics import (Calibration, CalibrationError, MAX_OFFSET_S, Track,
                                      calibrate, pick_user, synthetic_tracks, tracks_from_frames)
from skeleton_eval.sensor_params import tracker_params

DEFAULT_REFERENCE_POSE = '0 0 0.8 0 0 0'
DEFAULT_VIEW = '2.5 2.5 0 -90 0 0'     # sensor 2 in sensor 1's frame: front + side at 90 deg
SKELETONS = 'skeleton_msgs/msg/SkeletonArray'


def _seeds(text: str) -> List[int]:
    out = []
    for part in text.split(','):
        a, _, b = part.partition('-')
        out += list(range(int(a), int(b) + 1)) if b else [int(a)]
    return out


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='calibrate_extrinsics', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('bags', nargs='*', help='one bag per sensor (the first is the reference), or '
                   'one bag holding every sensor\'s topic')
    p.add_argument('--topics', default='', help='skeleton topic per sensor, comma-separated '
                   '(default: /kinect_k/skeletons when a bag has them, else each bag\'s only '
                   'SkeletonArray topic)')
    p.add_argument('--frames', default='', help='frame per sensor, comma-separated (default: the '
                   'messages\' frame_id; kinect_k_link when they are all alike)')
    p.add_argument('--reference-pose', default=None,
                   help='the first sensor\'s pose in world "x y z yaw pitch roll" (m, deg; '
                        f'default: the first bag\'s /tf_static, else "{DEFAULT_REFERENCE_POSE}")')
    p.add_argument('--max-offset', type=float, default=MAX_OFFSET_S,
                   help='largest clock offset between the sensors searched (s)')
    p.add_argument('--out', default='', help='sensor-pose YAML to write')
    p.add_argument('--live', type=int, default=0, metavar='N',
                   help='record N running sensors (/kinect_k/skeletons) for --duration s, then '
                        'calibrate')
    p.add_argument('--duration', type=float, default=12.0, help='--live: seconds to record')
    p.add_argument('--synthetic', action='store_true',
                   help='the sensor model: two sensors (the second at --view) watching one '
                        'person walk; prints the error against the true placement per seed')
    p.add_argument('--view', default=DEFAULT_VIEW,
                   help=f'--synthetic: the second sensor in the first\'s frame (default "{DEFAULT_VIEW}")')
    p.add_argument('--seeds', default='3-12', help='--synthetic: seeds, e.g. 3-12 or 1,4')
    p.add_argument('--scenario', default='a', help='--synthetic: sensor-model scenario class')
    p.add_argument('--on-the-spot', action='store_true',
                   help='--synthetic: the person walks on the spot facing the first sensor '
                        'instead of round a loop')
    p.add_argument('--seconds', type=float, default=10.0, help='--synthetic: walk duration (s)')
    p.add_argument('--tracker', default='',
                   help="--synthetic: the sensor model of this skeleton tracker (e.g. "
                        "azure_kinect_bt); default the Kinect v1 model")
    return p


# ------------------------------------------------------------------ inputs
def tracks_from_bags(bags: List[str], topics: List[str]):
    """(tracks per sensor: {user: Track}, frame per sensor, TF of the first bag)."""
    from skeleton_core.bagio import bag_topics, read_messages
    from skeleton_core.cdr import frames_from_cdr
    if len(bags) == 1:
        avail = bag_topics(bags[0])
        if not topics:
            topics = sorted(t for t in avail if t.startswith('/kinect_') and
                            t.endswith('/skeletons') and avail[t][0] == SKELETONS)
        if len(topics) < 2:
            raise ValueError(f'{bags[0]}: one bag needs two sensors\' topics (--topics; found '
                             f'{sorted(t for t in avail if avail[t][0] == SKELETONS)})')
        sources = [(bags[0], t) for t in topics]
    else:
        if topics and len(topics) != len(bags):
            raise ValueError(f'{len(bags)} bags but {len(topics)} --topics')
        sources = []
        for i, b in enumerate(bags):
            if topics:
                sources.append((b, topics[i]))
                continue
            sk = sorted(t for t, (ty, _) in bag_topics(b).items() if ty == SKELETONS)
            pick = [t for t in sk if t.endswith('/skeletons') and 'reliability' not in t]
            if '/kinect/skeletons' in sk:
                pick = ['/kinect/skeletons']
            if len(pick) != 1:
                raise ValueError(f'{b}: which skeleton topic? (--topics; found {sk})')
            sources.append((b, pick[0]))
    tf = TfBuffer()
    per_sensor, frames = [], []
    for i, (bag, topic) in enumerate(sources):
        got = []
        frame = ''
        wanted = [topic] + (['/tf_static'] if i == 0 else [])
        for m in read_messages(bag, topics=wanted, decode=['/tf_static']):
            if m.topic == '/tf_static':
                try:
                    tf.update(transforms_from_msg(m.msg))
                except (AttributeError, ValueError):
                    pass
                continue
            try:
                _, frame_id, fs = frames_from_cdr(m.data)
            except ValueError:
                continue
            frame = frame or frame_id
            got += fs
        if not got:
            raise ValueError(f'{bag}: no skeletons on {topic}')
        per_sensor.append(tracks_from_frames(got))
        frames.append(frame)
    return per_sensor, frames, tf


class Interrupted(Exception):
    """The live recording was stopped (Ctrl-C, the launch shutting down) before it was complete."""


def tracks_live(n: int, duration: float):
    """Record ``/kinect_k/skeletons`` of n running sensors for ``duration`` s (after the first
    skeleton of every sensor); returns (tracks per sensor, frame per sensor, TF)."""
    import rclpy
    from skeleton_core.cdr import frames_from_cdr
    from skeleton_core.tf_ros import StaticTfListener
    from skeleton_msgs.msg import SkeletonArray
    rclpy.init()
    node = rclpy.create_node('calibrate_extrinsics')
    tf = TfBuffer()
    StaticTfListener(node, tf)
    got: List[list] = [[] for _ in range(n)]
    frames = [''] * n

    def cb(k):
        def on(data):
            try:
                _, frame_id, fs = frames_from_cdr(data)
            except ValueError:
                return
            frames[k] = frames[k] or frame_id
            got[k].extend(fs)
        return on
    for k in range(n):
        node.create_subscription(SkeletonArray, f'/kinect_{k + 1}/skeletons', cb(k), 100,
                                 raw=True)
    node.get_logger().info(f'walk round a loop 2.5-3 m across where all {n} sensors see you; '
                           f'recording {duration:.0f} s from the first skeleton of every sensor')
    from rclpy.executors import ExternalShutdownException
    start = None
    try:
        while rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.1)
            if start is None and all(got):
                start = time.monotonic()
            if start is not None and time.monotonic() - start >= duration:
                break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass   # Ctrl-C: judged below, as a recording that stopped early
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    if start is None or time.monotonic() - start < duration:
        raise Interrupted(f'stopped after {0.0 if start is None else time.monotonic() - start:.0f}'
                          f' of the {duration:.0f} s to record, nothing written')
    if not all(got):
        raise ValueError('no skeletons from ' + ', '.join(f'/kinect_{k + 1}/skeletons'
                                                          for k in range(n) if not got[k]))
    return [tracks_from_frames(g) for g in got], frames, tf


# ------------------------------------------------------------------ output
def solve(per_sensor: List[Dict[int, Track]], frames: List[str], reference: Transform,
          max_offset: float) -> Tuple[List[Tuple[str, str, Transform]], Dict[str, Dict],
                                      List[Calibration]]:
    """Every sensor against the first: the world transforms, the information kept beside them,
    and the calibrations."""
    a = per_sensor[0][pick_user(per_sensor[0])]
    items = [(WORLD_FRAME, frames[0], reference)]
    extra = {frames[0]: {'role': 'reference'}}
    cals = []
    for k in range(1, len(per_sensor)):
        b = per_sensor[k][pick_user(per_sensor[k])]
        c = calibrate(a, b, max_offset_s=max_offset)
        cals.append(c)
        items.append((WORLD_FRAME, frames[k], reference * c.transform))
        extra[frames[k]] = dict(c.info(), relative_to=frames[0])
    return items, extra, cals


def run_synthetic(args) -> int:
    view = parse_pose(args.view)
    params = tracker_params(args.tracker) if args.tracker else None
    rows = []
    for seed in _seeds(args.seeds):
        rng = np.random.default_rng(seed + 100)   # the sensors' clock offset and capture phase
        off, phase = float(rng.uniform(-0.8, 0.8)), float(rng.uniform(0.0, 1.0 / 30.0))
        a, b, _ = synthetic_tracks(view, seed=seed, scenario=args.scenario,
                                   duration_s=args.seconds, clock_offset_s=off, phase_s=phase,
                                   circle=not args.on_the_spot, sensor_params=params)
        t0 = time.perf_counter()
        try:
            c = calibrate(a, b, seed=seed, max_offset_s=args.max_offset)
        except CalibrationError as e:
            print(f'seed {seed}: {e}')
            rows.append((seed, math.inf, math.inf, math.inf))
            continue
        dt, da = c.transform.distance(view)
        rows.append((seed, dt, da, c.time_offset_s - off))
        print(f'seed {seed}: {dt * 100:5.2f} cm {da:5.2f} deg, clock offset {off * 1000:+7.1f} ms '
              f'found {c.time_offset_s * 1000:+7.1f} ms; motion residual {c.rms_m * 100:.1f} cm, '
              f'{c.inliers}/{c.pairs} correspondences ({time.perf_counter() - t0:.1f} s)',
              flush=True)
        if args.out and len(rows) == 1:
            ref = parse_pose(args.reference_pose or DEFAULT_REFERENCE_POSE)
            items = [(WORLD_FRAME, 'kinect_1_link', ref),
                     (WORLD_FRAME, 'kinect_2_link', ref * c.transform)]
            Path(args.out).parent.mkdir(parents=True, exist_ok=True)
            Path(args.out).write_text(transforms_to_yaml(
                items, {'kinect_2_link': c.info()},
                header=f'calibrate_extrinsics --synthetic, seed {seed}'))
    d = np.array([r[1] for r in rows]) * 100
    a = np.array([r[2] for r in rows])
    ok = int(np.sum((d <= 3.0) & (a <= 2.0)))
    tracker = f', tracker {args.tracker}' if args.tracker else ''
    print(f'{len(rows)} seeds, {"walking round a loop" if not args.on_the_spot else "on the spot"}'
          f', scenario {args.scenario}{tracker}: translation median {np.median(d):.2f} cm, max '
          f'{np.max(d):.2f} cm; rotation median {np.median(a):.2f} deg, max {np.max(a):.2f} deg; '
          f'{ok}/{len(rows)} within 3 cm and 2 deg')
    return 0


def main(argv=None) -> int:
    if argv is None:   # started by a launch file: without the --ros-args part
        from rclpy.utilities import remove_ros_args
        argv = remove_ros_args(sys.argv)[1:]
    args = build_parser().parse_args(argv)
    try:
        if args.synthetic:
            return run_synthetic(args)
        if args.live:
            if args.live < 2:
                raise ValueError('--live needs at least 2 sensors')
            per_sensor, frames, tf = tracks_live(args.live, args.duration)
        elif args.bags:
            topics = [t for t in args.topics.split(',') if t]
            per_sensor, frames, tf = tracks_from_bags(args.bags, topics)
        else:
            raise ValueError('give bags, --live N or --synthetic (--help)')
        if args.frames:
            frames = [f for f in args.frames.split(',') if f]
            if len(frames) != len(per_sensor):
                raise ValueError(f'{len(per_sensor)} sensors but {len(frames)} --frames')
        elif len(set(frames)) < len(frames) or not all(frames):
            frames = [sensor_frame(k + 1, len(per_sensor)) for k in range(len(per_sensor))]
        if args.reference_pose is not None:
            reference = parse_pose(args.reference_pose)
        elif tf.can_transform(WORLD_FRAME, frames[0]):
            reference = tf.lookup(WORLD_FRAME, frames[0])
        else:
            reference = parse_pose(DEFAULT_REFERENCE_POSE)
        items, extra, cals = solve(per_sensor, frames, reference, args.max_offset)
    except (ValueError, OSError, CalibrationError) as e:
        print(f'calibrate_extrinsics: error: {e}', file=sys.stderr)
        return 1
    except Interrupted as e:   # a stop asked for (Ctrl-C through rclpy, a launch shutting
        #                          down): a clean exit, as a node's, with what was not done said
        print(f'calibrate_extrinsics: interrupted: {e}', file=sys.stderr)
        return 0
    except KeyboardInterrupt:
        print('calibrate_extrinsics: interrupted, nothing written', file=sys.stderr)
        return 130
    for (_, child, t), c in zip(items[1:], cals):
        print(f'{child}: {format_pose(t)} (x y z m, yaw pitch roll deg in {WORLD_FRAME}); clock '
              f'offset {c.time_offset_s * 1000:+.1f} ms; motion residual {c.rms_m * 100:.1f} cm '
              f'over {c.inliers}/{c.pairs} correspondences')
    text = transforms_to_yaml(items, extra, header='calibrate_extrinsics: the sensors\' poses '
                              'in world (driver.launch.py extrinsics:=THIS_FILE)')
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
        print(f'wrote {args.out}')
    else:
        print(text, end='')
    return 0


if __name__ == '__main__':
    sys.exit(main())
