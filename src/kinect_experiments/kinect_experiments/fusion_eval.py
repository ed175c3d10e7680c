"""``evaluate --sensors N``: several sensors watching the same people, fused.

Every dev clip x class x seed is seen by N sensor-model views (skeleton_eval.sensor_model, ``view``:
the same motion and turns, per-view noise, occlusion and failures): sensor 1 is the reference
placement (its frame is ``world`` here), sensor 2 at 90 deg on the user's side (front + side),
further sensors around the user; ``--layout diagonal`` turns that ring by 45 deg (two sensors at
45 deg either side of the front; the single-sensor rows stay the front sensor alone). Rows per
class: single-sensor raw and C (sensor 1 alone), fused raw
(:class:`pose_reconstruction.fusion.MultiSensorFusion`), sensor 2 alone (raw, put in the reference
frame) and fused + C (the reconstruction
unchanged, fed the fused skeletons). Eq. 18 error (cm) against the truth, and MPJPE.
"""
from __future__ import annotations

import sys
import time
from dataclasses import replace
from typing import Dict, List

import numpy as np

from pose_reconstruction.fusion import MultiSensorFusion
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.tf import Transform
from skeleton_eval import evaluation as E
from skeleton_eval.sensor_model import SensorModel


LAYOUTS = ('front-side', 'diagonal')


def view_poses(sensor: SensorModel, n: int, layout: str = 'front-side') -> List[Transform]:
    """Sensor k's pose in the reference (front) sensor's frame, around the user's place at the
    same distance and height, 90 deg apart: ``front-side``: k = 0 the front sensor itself, 1 on
    the user's side, ...; ``diagonal``: the ring turned by 45 deg (two sensors at 45 deg either
    side of the front: neither sees the user in profile)."""
    if layout not in LAYOUTS:
        raise ValueError(f'unknown layout {layout!r} (known: {", ".join(LAYOUTS)})')
    pl = sensor.params['placement']
    d, lat = float(pl['distance_m']), float(pl['lateral_offset_m'])
    user = np.array([d, lat, 0.0])
    out = []
    for k in range(n):
        a = np.pi + k * np.pi / 2            # angle of the sensor around the user (front at pi)
        if layout == 'diagonal':
            a -= np.pi / 4
        if abs(a - np.pi) < 1e-12:
            out.append(Transform.identity())
            continue
        pos = user + d * np.array([np.cos(a), np.sin(a), 0.0])
        out.append(Transform.from_xyz_ypr(*pos, yaw=float(a - np.pi), degrees=False))
    return out


def fused_frames(streams, poses: List[Transform], user_id: int = 1) -> List[SkeletonFrame]:
    """The fused skeletons of N views' streams (one user), in the reference sensor's frame."""
    fu = MultiSensorFusion({f'kinect_{k + 1}': p for k, p in enumerate(poses)}, frame_id=E.FRAME_ID)
    out = []
    for i in range(len(streams[0])):
        for k, s in enumerate(streams):
            f = SkeletonFrame(positions=s.positions[i].copy(), tracking_state=s.tracking_state[i].copy(),
                              user_id=user_id, stamp_ns=int(s.stamps_ns[i]), frame_id=f'kinect_{k + 1}_link')
            fu.add(f'kinect_{k + 1}', [f], int(s.stamps_ns[i]))
        frames, stamp, _ = fu.fuse(int(streams[0].stamps_ns[i]))
        if frames:
            f = frames[0]
            f.user_id = user_id
        else:   # nobody seen: a not-tracked skeleton at the previous place
            prev = out[-1].positions if out else streams[0].positions[i]
            f = SkeletonFrame(positions=prev.copy(), tracking_state=np.zeros(len(prev), np.uint8),
                              user_id=user_id, stamp_ns=stamp, frame_id=E.FRAME_ID)
        out.append(f)
    return out


def in_reference(stream, pose: Transform):
    """A view's stream (and its truth) put in the reference sensor's frame through its pose:
    that sensor alone, scored like the reference sensor."""
    return replace(stream, positions=pose.apply(stream.positions), truth=pose.apply(stream.truth))


def run(args, dev_clips, methods=('raw', 'C')) -> int:
    n = int(args.sensors)
    scenarios = [s for s in args.scenarios.split(',') if s]
    sensor = SensorModel(args.sensor_params, seed=args.seed)
    layout = getattr(args, 'layout', 'front-side')
    poses = view_poses(sensor, n, layout)
    front = Transform.identity()
    mf = args.max_frames if args.max_frames and args.max_frames > 0 else None
    single: Dict[str, list] = {}
    others: Dict[str, list] = {}    # sensor 2 alone, put in the reference frame
    fused: Dict[int, List[SkeletonFrame]] = {}
    for sc in scenarios:
        single[sc] = []
        for r in range(max(1, args.repeats)):
            for c in dev_clips:
                views = [sensor.corrupt(c, sc, seed=args.seed + r, max_frames=mf, view=p) for p in poses]
                one = views[0] if layout == 'front-side' else sensor.corrupt(
                    c, sc, seed=args.seed + r, max_frames=mf, view=front)
                single[sc].append(one)
                others.setdefault(sc, []).append(in_reference(views[1], poses[1]))
                fused[id(one)] = fused_frames(views, poses)
                if not args.quiet:
                    print(f'[evaluate] {n} sensors {sc} {c.name}', file=sys.stderr)
    res_single = E.evaluate_streams(list(methods), single)['results']
    res_fused = E.evaluate_streams(list(methods), single, frame_transform=lambda s: fused[id(s)])['results']
    res_other = E.evaluate_streams(['raw'], others)['results']
    lines = [f'# {n} sensors ({layout}, 90 deg apart), seed {args.seed}, {len(dev_clips)} clips, '
             f'{mf or "all"} frames', '',
             '| class | row | Eq. 18 (cm) | MPJPE (cm) | vs single raw |', '|---|---|---|---|---|']
    for sc in scenarios:
        base = res_single['raw'][sc]['metrics']['eq18_cm']['overall']
        for label, res in (('single', res_single), ('sensor 2', res_other), ('fused', res_fused)):
            for m in (methods if label != 'sensor 2' else ['raw']):
                mt = res[m][sc]['metrics']
                e = mt['eq18_cm']['overall']
                lines.append(f'| {sc} | {label} {m} | {e:.2f} | {mt["mpjpe_cm"]["overall"]:.2f} | '
                             f'{100 * (e - base) / base:+.1f} % |')
    longest = max(dev_clips, key=lambda c: len(c.positions))
    last = [sensor.corrupt(longest, scenarios[-1], seed=args.seed, max_frames=300, view=p)
            for p in poses]
    cost = fusion_cost(last, poses)
    lines += ['', f'fusion cost ({cost["sensors"]} sensors x {cost["users"]} users, '
              f'{cost["frames"]} frames, class {scenarios[-1]}): {cost["mean_ms"]:.3f} ms mean, '
              f'{cost["p95_ms"]:.3f} ms p95 per frame and user ({cost["cpu_mean_ms"]:.3f} ms CPU '
              f'time); without the per-sensor Eq. 1-8 (which '
              f'the reconstruction then takes as given instead of computing it): '
              f'{cost["no_eq8_mean_ms"]:.3f} ms mean, {cost["no_eq8_p95_ms"]:.3f} ms p95 (target '
              '<= 0.5 ms; shared machine: timings disturbed by other jobs)']
    print('\n'.join(lines))
    return 0


def fusion_cost(streams, poses: List[Transform], users: int = 6, spacing: float = 1.0) -> Dict:
    """Fusion time per frame and user (ms; wall clock, and ``cpu_mean_ms`` the thread's CPU
    time, less disturbed by other jobs on a shared machine): ``users`` copies of the views' streams side by side
    (``spacing`` m apart along the reference sensor's y) through one :class:`MultiSensorFusion`,
    Eq. 1-8 per sensor and user included (the views carry no reliability)."""
    fu = MultiSensorFusion({f'kinect_{k + 1}': p for k, p in enumerate(poses)}, frame_id=E.FRAME_ID)
    shifts = [(0.0, (u - (users - 1) / 2) * spacing, 0.0) for u in range(users)]
    times, rel, cpu, tracks = [], [], [], []
    for i in range(len(streams[0])):
        batches = []
        for k, s in enumerate(streams):
            inv = poses[k].inverse()
            # a user shifted in world is shifted by the view's rotation of the shift in its frame
            d = [inv.apply(np.asarray([sh]))[0] - inv.apply(np.zeros((1, 3)))[0] for sh in shifts]
            batches.append([SkeletonFrame(positions=s.positions[i] + d[u],
                                          tracking_state=s.tracking_state[i].copy(), user_id=u + 1,
                                          stamp_ns=int(s.stamps_ns[i])) for u in range(users)])
        r0 = fu.stats.reliability_s
        c0 = time.thread_time()     # outside the wall-clock window (a clock_gettime of its own)
        t0 = time.perf_counter()
        for k, b in enumerate(batches):
            fu.add(f'kinect_{k + 1}', b, int(streams[k].stamps_ns[i]))
        out, _, _ = fu.fuse()
        t1 = time.perf_counter()
        cpu.append((time.thread_time() - c0) * 1e3)
        times.append((t1 - t0) * 1e3)
        rel.append((fu.stats.reliability_s - r0) * 1e3)
        tracks.append(len(out))   # more than users: a view's confident failure (class d's
        #                           person jump) left its person apart for a while
    t = np.array(times[10:]) / users
    r = t - np.array(rel[10:]) / users
    c = np.array(cpu[10:]) / users
    return {'cpu_mean_ms': float(c.mean()), 'tracks_mean': float(np.mean(tracks[10:])),
            'users': users, 'sensors': len(streams), 'frames': len(t),
            'mean_ms': float(t.mean()), 'p95_ms': float(np.percentile(t, 95)),
            'no_eq8_mean_ms': float(r.mean()), 'no_eq8_p95_ms': float(np.percentile(r, 95))}
