"""``reconstruction_cost``: the reconstruction node's work per message on a fused two-sensor stream
beside the same users seen by one sensor, in one process without DDS -- decode, the users'
reconstructions (``FusedProcessor.process_batch``, the reconstructed output only, as the node
with nobody on its other outputs), result check, encode -- with the CPU per stage and a digest
of every output message's bytes.

    python -m kinect_experiments.reconstruction_cost --users 6 --frames 300
    python -m kinect_experiments.reconstruction_cost --users 6 --profile out/rc.prof

The inputs are the frames ``bench --drivers-elsewhere`` generates (:mod:`.fusion_cost`): sensor
1's messages as they come (one sensor), and the fusion's output on both sensors' messages
(``fusion_cost.replay``). The two streams run in lockstep, each message both ways in
alternating order, on their own processors, so a shared machine's load hits both alike. CPU is
``time.process_time``; two commits fed the same frames print the same digests when their
outputs are byte for byte the same.
"""
from __future__ import annotations

import argparse
import cProfile
import hashlib
import pickle
import sys
import time
from typing import Dict, List, Sequence

import numpy as np

from .fusion_cost import load_streams, replay

STAGES = ('decode', 'reconstruct', 'encode')
INPUTS = ('one sensor', 'fused')


def input_messages(data: Dict, frames: int) -> Dict[str, List[bytes]]:
    """The reconstruction's input messages: sensor 1's (one sensor) and the fused ones."""
    from skeleton_core.cdr import restamp_cdr
    period_ns = int(round(1e9 / data['rate_hz']))
    t0_ns = 1_700_000_000_000_000_000
    msgs = data['streams'][0]['messages']
    single = [restamp_cdr(*msgs[i % len(msgs)], t0_ns + i * period_ns) for i in range(frames)]
    fused: List[bytes] = []
    replay(data, frames, warm=0, sink=fused)
    return {'one sensor': single, 'fused': fused}


def run(inputs: Dict[str, List[bytes]], db, warm: int = 30, profiles: Dict = None) -> Dict:
    """Every input stream through the node's per-message work, in lockstep. Returns per input
    the CPU ms per message per stage (after ``warm`` messages) and the digest of the outputs."""
    from pose_reconstruction.fused import FusedProcessor
    from skeleton_core.cdr import frames_from_cdr, frames_to_cdr
    from skeleton_core.conversions import frame_from_arrays

    wanted = (True, False, False)
    users = {k: {} for k in inputs}
    cpu = {k: dict.fromkeys(STAGES, 0.0) for k in inputs}
    per_msg: Dict[str, List[float]] = {k: [] for k in inputs}
    digest = {k: hashlib.sha256() for k in inputs}
    n = min(len(v) for v in inputs.values())
    names = list(inputs)
    for i in range(n):
        for name in (names if i % 2 else names[::-1]):
            prof = profiles.get(name) if profiles is not None and i >= warm else None
            if prof is not None:
                prof.enable()
            c0 = time.process_time()
            stamp, fid, frames = frames_from_cdr(inputs[name][i], [])
            c1 = time.process_time()
            procs = []
            for f in frames:
                p = users[name].get(f.user_id)
                if p is None:
                    p = users[name][f.user_id] = FusedProcessor(db, {})
                if f.stamp_ns == 0:
                    f.stamp_ns = stamp
                procs.append(p)
            outs = (FusedProcessor.process_batch(procs, frames, wanted) if len(procs) > 1
                    else [p.process(f, wanted) for p, f in zip(procs, frames)])
            checked = []
            for o in outs:
                if isinstance(o, Exception):
                    raise o
                r = o[0]
                checked.append(frame_from_arrays(r.positions, r.tracking_state, r.reliability,
                                                 r.orientations, r.user_id, r.stamp_ns,
                                                 r.frame_id))
            c2 = time.process_time()
            b = frames_to_cdr(checked, stamp, fid, validated=True)
            c3 = time.process_time()
            if prof is not None:
                prof.disable()
            digest[name].update(b)
            if i >= warm:
                for k, v in zip(STAGES, (c1 - c0, c2 - c1, c3 - c2)):
                    cpu[name][k] += v
                per_msg[name].append(1000.0 * (c3 - c0))
    m = max(n - warm, 1)
    return {k: {'cpu_ms_per_frame': {s: 1000.0 * v / m for s, v in cpu[k].items()},
                'total_ms_per_frame': 1000.0 * sum(cpu[k].values()) / m,
                'p95_ms': float(np.percentile(per_msg[k], 95)) if per_msg[k] else 0.0,
                'digest': digest[k].hexdigest(), 'messages': n} for k in inputs}


def main(argv: Sequence[str] = None) -> int:
    p = argparse.ArgumentParser(prog='reconstruction_cost', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--users', type=int, default=6)
    p.add_argument('--frames', type=int, default=300, help='messages replayed (30 a second)')
    p.add_argument('--source', default='builtin', choices=('auto', 'builtin', 'cmu'),
                   help='motion database (as bench_reconstruction --source)')
    p.add_argument('--frames-file', default='', help='a remote_frames.pkl of bench '
                   '--drivers-elsewhere (default: generated now)')
    p.add_argument('--profile', default='', help='write cProfile statistics of each input to '
                   'PATH.one_sensor / PATH.fused')
    a = p.parse_args(argv)
    if a.users < 1 or a.frames < 60:
        p.error('needs --users >= 1, --frames >= 60')
    from skeleton_data.database import DatabaseError, load_or_build_default
    from pose_reconstruction.posture_space import as_database_arrays
    try:
        data = load_streams(a.users, 2, a.frames / 30.0 + 1.0, a.frames_file)
        db = as_database_arrays(load_or_build_default(source=a.source))
    except (OSError, pickle.UnpicklingError, EOFError, ValueError, DatabaseError) as e:
        print(f'reconstruction_cost: {e}', file=sys.stderr)
        return 2
    inputs = input_messages(data, a.frames)
    profiles = {k: cProfile.Profile() for k in INPUTS} if a.profile else None
    res = run(inputs, db, profiles=profiles)
    for name, r in res.items():
        stages = ', '.join(f'{k} {v:.3f}' for k, v in r['cpu_ms_per_frame'].items())
        print(f"reconstruction_cost: {data['users']} user(s), {name:<10}: CPU "
              f"{r['total_ms_per_frame']:.3f} ms per message ({stages}; p95 {r['p95_ms']:.2f}); "
              f"{r['messages']} "
              f"messages, sha256 {r['digest']}")
        if profiles is not None:
            path = f"{a.profile}.{name.replace(' ', '_')}"
            profiles[name].dump_stats(path)
            print(f'reconstruction_cost: profile of {name} in {path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
