"""``fusion_cost``: the fusion node's work per fused frame, replayed in one process without DDS --
decode both sensors' messages, fuse, encode -- on the frames ``bench --drivers-elsewhere``
generates (the same synthetic source, users, views and frame ids as the bench's drivers), with the
CPU per stage and a digest of every fused message's bytes (two commits fed the same frames give
the same digest when their outputs are byte for byte the same).

    python -m kinect_experiments.fusion_cost --users 6 --frames 600
    python -m kinect_experiments.fusion_cost --frames-file out/bench/.../remote_frames.pkl

Sensor k's message i is stamped ``i`` periods + ``(k - 1) * phase`` after the start and arrives
in that order (the bench's replay); the fusion clock is driven with those times as its wall
clock (its deadline handled before the next arrival, as the node's timer), so the stamps it
publishes and its holds are the node's, minus the DDS delivery. CPU is
``time.process_time`` of this process: the figure other jobs on the machine move least.
"""
from __future__ import annotations

import argparse
import hashlib
import pickle
import sys
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Optional, Sequence

STAGES = ('decode', 'add', 'fuse', 'encode')


def load_streams(users: int, sensors: int, seconds: float, frames_file: str = '') -> Dict:
    """The serialized frames of every sensor: ``frames_file`` (a ``remote_frames.pkl``) or made
    now as ``bench --drivers-elsewhere`` makes them."""
    from .remote_drivers import generate
    if not frames_file:
        tmp = Path(tempfile.mkdtemp(prefix='fusion_cost_')) / 'frames.pkl'
        generate(users, sensors, seconds, tmp)
        frames_file = str(tmp)
    with open(frames_file, 'rb') as f:
        return pickle.load(f)


def replay(data: Dict, frames: int, phase_ms: float = 3.0, warm: int = 30,
           sink: Optional[List[bytes]] = None) -> Dict:
    """Every sensor's messages through decode, the fusion, its clock and encode, as the node
    does. Returns CPU ms per fused frame per stage (after ``warm`` frames), the count, the
    digest of the fused messages (appended to ``sink`` when given)."""
    from pose_reconstruction.fusion import MultiSensorFusion
    from pose_reconstruction.fusion_clock import FusionClock
    from skeleton_core.cdr import frames_from_cdr, frames_to_cdr, restamp_cdr
    from skeleton_core.tf import default_sensor_poses, sensor_frame

    streams = data['streams']
    n_s = len(streams)
    if n_s < 2:
        raise ValueError('fusion_cost needs the frames of two or more sensors')
    names = [s['topic'] for s in streams]
    poses = default_sensor_poses(n_s)
    # the fusion node's placements: world <- kinect_k_link (TF of the launch files' static_tf)
    frame_pose = {sensor_frame(k, n_s): poses[k - 1] for k in range(1, n_s + 1)}
    fusion = MultiSensorFusion({s: None for s in names})
    clock = FusionClock(names, max_wait_s=0.005)
    period_ns = int(round(1e9 / data['rate_hz']))
    phase_ns = int(round(phase_ms * 1e6))
    t0_ns = 1_700_000_000_000_000_000
    cpu = dict.fromkeys(STAGES, 0.0)
    digest = hashlib.sha256()
    published = 0
    counted = 0
    n_msgs = len(streams[0]['messages'])
    for i in range(frames):
        for k, s in enumerate(streams):
            msg, offsets = s['messages'][i % n_msgs]
            stamp = t0_ns + i * period_ns + k * phase_ns
            raw = restamp_cdr(msg, offsets, stamp)
            measure = i >= warm
            c0 = time.process_time()
            st, fid, fr = frames_from_cdr(raw, [])
            c1 = time.process_time()
            if fusion.poses[names[k]] is None:
                fusion.poses[names[k]] = frame_pose[fid]
            fusion.add(names[k], fr, st)
            wall = (stamp - t0_ns) * 1e-9
            due = clock.deadline()   # the node's deadline timer, had it fired before this arrival
            out = clock.on_timer(due) if due is not None and due <= wall else []
            out += clock.on_frame(names[k], st, wall)
            c2 = time.process_time()
            t_fuse = t_enc = 0.0
            for o in out:
                f, ost, ofid = fusion.fuse(o)
                c3 = time.process_time()
                b = frames_to_cdr(f, ost, ofid)
                c4 = time.process_time()
                t_fuse += c3 - c2
                t_enc += c4 - c3
                c2 = c4
                digest.update(b)
                if sink is not None:
                    sink.append(b)
                published += 1
            if measure:
                cpu['decode'] += c1 - c0
                cpu['add'] += c2 - c1 - t_fuse - t_enc     # add + the clock
                cpu['fuse'] += t_fuse
                cpu['encode'] += t_enc
                counted += len(out)
    per = {k: 1000.0 * v / max(counted, 1) for k, v in cpu.items()}
    return {'published': published, 'measured': counted, 'cpu_ms_per_frame': per,
            'total_ms_per_frame': sum(per.values()), 'digest': digest.hexdigest(),
            'forced': clock.forced}


def main(argv: Sequence[str] = None) -> int:
    p = argparse.ArgumentParser(prog='fusion_cost', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--users', type=int, default=6)
    p.add_argument('--sensors', type=int, default=2)
    p.add_argument('--frames', type=int, default=600, help='fused frames replayed (30 a second)')
    p.add_argument('--phase-ms', type=float, default=3.0, help='sensor k+1 after sensor k (ms)')
    p.add_argument('--frames-file', default='', help='a remote_frames.pkl of bench '
                   '--drivers-elsewhere (default: generated now)')
    p.add_argument('--repeat', type=int, default=3, help='replays; the least CPU is printed')
    a = p.parse_args(argv)
    if a.users < 1 or a.sensors < 2 or a.frames < 60 or a.repeat < 1:
        p.error('needs --users >= 1, --sensors >= 2, --frames >= 60, --repeat >= 1')
    try:
        data = load_streams(a.users, a.sensors, a.frames / 30.0 + 1.0, a.frames_file)
    except (OSError, pickle.UnpicklingError, EOFError, ValueError) as e:
        print(f'fusion_cost: {e}', file=sys.stderr)
        return 2
    runs: List[Dict] = [replay(data, a.frames, a.phase_ms) for _ in range(a.repeat)]
    best = min(runs, key=lambda r: r['total_ms_per_frame'])
    stages = ', '.join(f'{k} {v:.3f}' for k, v in best['cpu_ms_per_frame'].items())
    print(f"fusion_cost: {data['users']} user(s) x {len(data['streams'])} sensors, "
          f"{best['measured']} fused frames measured: CPU {best['total_ms_per_frame']:.3f} ms "
          f"per fused frame ({stages}; least of {a.repeat}: "
          + ', '.join(f"{r['total_ms_per_frame']:.3f}" for r in runs) + ')')
    print(f"fusion_cost: {best['published']} fused messages, sha256 {best['digest']}, "
          f"{best['forced']} published without a late sensor")
    return 0


if __name__ == '__main__':
    sys.exit(main())
