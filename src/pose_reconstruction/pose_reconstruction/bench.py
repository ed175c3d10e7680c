"""``ros2 run pose_reconstruction bench_reconstruction``: timing and accuracy figures of the
posture reconstruction (no ROS needed).

Prints
1. accuracy (Shum et al. 2013 Eq. 18, cm) of raw / A / B / C (stochastic and Gauss-Newton) on a
   corrupted synthetic clip whose motion the database contains;
2. the per-stage time split of method C per frame per user (Fig. 9 style: reliability,
   normalise+retarget, KNN, local PCA, optimisation, orientations, output), median ms and ratio to
   the 33 ms frame budget, for both solvers, on the default database;
3. method A time per query;
4. the reconstruction node's work per two-user message without DDS (CDR decode, reliability +
   method C for each user through FusedProcessor, result check, CDR encode) and the cost of a
   user's first frame (building the per-user state); the CPU time per message at 1, 2 and 6
   users, each user alone vs the users together (``--users-only``: this alone);
5. how time grows with database size (1k -> 50k postures, jittered copies) for brute-force BLAS
   KNN vs cKDTree in PCA space (with its recall of the exact Eq. 9 neighbours), and with K;
6. method C per frame per user on the large real database (every CMU clip and its mirror image,
   no filter: ~53k postures; built once into the cache), with the single-precision KNN screening
   beside the exact double-precision search (the target: <= 3 ms per frame and user).

The machine may be shared: figures are medians over the frames of a clip.
"""
from __future__ import annotations

import argparse
import time
from typing import Dict, List

import numpy as np

from skeleton_core.cdr import frames_from_cdr, frames_to_cdr
from skeleton_core.conversions import SkeletonFrame, frame_from_arrays

from .fused import FusedProcessor
from .optimizer import NaturalPostureOptimizer
from .posture_space import as_database_arrays, parent_relative_error
from .reconstructor import Reconstructor
from .synthetic import SyntheticDatabase, corrupt_clip, scenario, smooth_clip
from skeleton_data.database import DatabaseError, load_or_build_default
from . import search as opt_mod

BUDGET_MS = 1000.0 / 30.0


def run_clip(db, obs, ts, method: str, **params):
    r = Reconstructor(db, method=method, **params)
    out, total, cpu, stages, steps = [], [], [], [], []
    for t in range(len(obs)):
        f = SkeletonFrame(positions=obs[t], tracking_state=ts[t], stamp_ns=t)
        t0, c0 = time.perf_counter(), time.thread_time()
        out.append(r.process(f).positions)
        total.append(1e3 * (time.perf_counter() - t0))
        cpu.append(1e3 * (time.thread_time() - c0))
        stages.append(dict(r.timings_ms))
        steps.append(getattr(r.last_result, 'steps', 0))
    r.cpu_ms = np.array(cpu)
    r.steps = np.array(steps)
    return np.array(out), np.array(total), stages, r


def stage_medians(stages: List[Dict[str, float]]) -> Dict[str, float]:
    keys = stages[0].keys()
    return {k: float(np.median([s[k] for s in stages])) for k in keys}


def node_messages(db, obs, ts, obs2, ts2) -> Dict[str, np.ndarray]:
    """What the fused reconstruction node does per message, without DDS: two users' skeletons
    as one serialized SkeletonArray -> frames -> FusedProcessor per user (reconstructed output
    only) -> results checked -> serialized. ms per message, and per new user (its first frame:
    the processor is built)."""
    msgs = []
    for t in range(len(obs)):
        stamp = (t + 1) * 33_333_333
        frames = [SkeletonFrame(positions=o[t], tracking_state=np.asarray(s[t], np.uint8),
                                user_id=u, stamp_ns=stamp, frame_id='kinect')
                  for u, o, s in ((1, obs, ts), (2, obs2, ts2))]
        msgs.append(frames_to_cdr(frames, stamp, 'kinect'))
    db = as_database_arrays(db)
    FusedProcessor(db, {})  # the database's shared arrays, built once as in the node
    users: Dict[int, FusedProcessor] = {}
    per_msg, first = [], []
    wanted = (True, False, False)
    for data in msgs:
        t0 = time.perf_counter()
        stamp, frame_id, frames = frames_from_cdr(data, [])
        out = []
        for f in frames:
            proc = users.get(f.user_id)
            if proc is None:
                t1 = time.perf_counter()
                proc = users[f.user_id] = FusedProcessor(db, {})
                first.append(1e3 * (time.perf_counter() - t1))
            res = proc.process(f, wanted)[0]
            out.append(frame_from_arrays(res.positions, res.tracking_state, res.reliability,
                                         res.orientations, res.user_id, res.stamp_ns,
                                         res.frame_id))
        frames_to_cdr(out, stamp, frame_id, validated=True)
        per_msg.append(1e3 * (time.perf_counter() - t0))
    return {'message': np.array(per_msg[1:]), 'new_user': np.array(first)}


def user_streams(users: int, frames: int) -> List[tuple]:
    """``users`` corrupted synthetic clips (observed, tracking state), side by side in front of
    the sensor at different heights: the users of one message."""
    out = []
    for u in range(users):
        _, truth = smooth_clip(frames, seed=10 + u, height=1.55 + 0.05 * u)
        out.append(corrupt_clip(truth + np.array([0.5 * u - 1.2, 0.0, 0.0]), seed=20 + u))
    return out


def users_per_message(db, frames: int, counts=(1, 2, 6), rounds: int = 2) -> Dict[tuple, float]:
    """CPU time (thread time, ms) of the reconstruction node's processors on one message's
    users, each user alone (``FusedProcessor.process``) and the users together
    (``FusedProcessor.process_batch``), the reconstructed output only. The two run in lockstep
    on the same messages (each message both ways, in alternating order), so that a shared
    machine's load changes hit both alike; the median over the messages after the first 10 (or
    the first third of a short clip) and over ``rounds``. {(users, batched): ms}."""
    db = as_database_arrays(db)
    wanted = (True, False, False)
    got: Dict[tuple, list] = {}
    skip = min(10, frames // 3)
    for _ in range(rounds):
        for n in counts:
            st = user_streams(n, frames)
            procs = {False: [FusedProcessor(db, {}) for _ in range(n)],
                     True: [FusedProcessor(db, {}) for _ in range(n)]}
            cpu: Dict[bool, list] = {False: [], True: []}
            for t in range(frames):
                fr = [SkeletonFrame(positions=o[t], tracking_state=s[t], user_id=u + 1,
                                    stamp_ns=(t + 1) * 33_333_333, frame_id='kinect')
                      for u, (o, s) in enumerate(st)]
                for batched in ((False, True) if t % 2 else (True, False)):
                    c0 = time.thread_time()
                    if batched:
                        FusedProcessor.process_batch(procs[True], fr, wanted)
                    else:
                        for p, f in zip(procs[False], fr):
                            p.process(f, wanted)
                    cpu[batched].append(1e3 * (time.thread_time() - c0))
            for batched, v in cpu.items():
                got.setdefault((n, batched), []).append(float(np.median(v[skip:])))
    return {k: float(np.median(v)) for k, v in got.items()}


def print_users_per_message(db, frames: int) -> None:
    res = users_per_message(db, frames)
    print(f'\n## reconstruction node, users per message ({frames} frames, database '
          f'{as_database_arrays(db).size} postures): CPU ms per message (thread time, median), '
          f'each user alone vs the users together')
    print(f'{"users":>6}{"alone":>9}{"together":>10}{"per user":>10}{"together":>10}{"saved":>8}')
    for n in sorted({k[0] for k in res}):
        a, b = res[(n, False)], res[(n, True)]
        print(f'{n:>6}{a:>9.2f}{b:>10.2f}{a / n:>10.2f}{b / n:>10.2f}{1 - b / a:>8.0%}')


def jittered(db, size: int, seed: int = 0) -> SyntheticDatabase:
    """A database of ``size`` postures: copies of ``db`` with 2 cm Gaussian joint jitter."""
    d = as_database_arrays(db)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, d.size, size)
    pos = d.positions[idx] + rng.normal(0.0, 0.02, (size,) + d.positions.shape[1:])
    ori = d.orientations[idx] if d.orientations is not None else np.tile([0, 0, 0, 1.0], (size, 20, 1))
    return SyntheticDatabase(positions=pos.astype(np.float32), orientations=ori,
                             twists=np.zeros((size, 19), np.float32))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--source', default='auto', choices=('auto', 'builtin', 'cmu', 'synthetic'),
                    help='database for the timing sections (default: auto = CMU if present)')
    ap.add_argument('--frames', type=int, default=150, help='frames of the test clip')
    ap.add_argument('--quick', action='store_true', help='fewer sizes / K values')
    ap.add_argument('--users-only', action='store_true',
                    help='only the CPU time per message at 1, 2 and 6 users, each alone vs together')
    a = ap.parse_args(argv)
    if a.users_only:
        db = (scenario(frames=a.frames)[0] if a.source == 'synthetic'
              else load_or_build_default(source=a.source))
        print_users_per_message(db, a.frames)
        return 0

    print('# posture reconstruction benchmark (medians; the machine may be loaded by other jobs)')
    # 1. accuracy on a synthetic scenario
    sdb, truth, obs, ts = scenario(frames=a.frames)
    print(f'\n## accuracy: corrupted synthetic clip, {a.frames} frames, database '
          f'{len(sdb.positions)} synthetic postures (Eq. 18 error, cm)')
    print(f'{"method":<24}{"error cm":>10}{"wall ms":>9}{"CPU ms":>8}')
    print(f'{"raw Kinect":<24}{100 * parent_relative_error(obs, truth):>10.2f}{"":>11}')
    for label, m, kw in (('A (Shum & Ho 2012)', 'A', {}), ('B (no reliability)', 'B', {}),
                         ('C stochastic (paper)', 'C', {}),
                         ('C gauss_newton', 'C', {'solver': 'gauss_newton'})):
        out, tot, _, r = run_clip(sdb, obs, ts, m, **kw)
        print(f'{label:<24}{100 * parent_relative_error(out, truth):>10.2f}{np.median(tot):>9.2f}'
              f'{np.median(r.cpu_ms):>8.2f}')

    # 2. per-stage split on the default database
    if a.source == 'synthetic':
        db, src = sdb, 'synthetic'
    else:
        db = load_or_build_default(source=a.source)
        src = db.meta.get('source', a.source)
    n = len(db.positions)
    print(f'\n## method C per frame per user, database {src} ({n} postures), K=30, 20 dims')
    for solver in ('stochastic', 'gauss_newton'):
        _, tot, stages, r = run_clip(db, obs, ts, 'C', solver=solver)
        med = stage_medians(stages)
        s = sum(med.values())
        print(f'solver={solver}: total median {np.median(tot):.2f} ms wall (p95 '
              f'{np.percentile(tot, 95):.2f}), {np.median(r.cpu_ms):.2f} ms CPU = '
              f'{np.median(r.cpu_ms) / BUDGET_MS:.1%} of the 33 ms budget; '
              f'{np.mean(r.steps):.1f} optimisation steps per frame on average')
        for k, v in med.items():
            print(f'    {k:<14}{v:7.3f} ms  {v / max(s, 1e-9):6.1%}')
    _, tot_a, stages_a, ra = run_clip(db, obs, ts, 'A')
    med_a = stage_medians(stages_a)
    comp = ra.core
    ts_search = []
    for t in range(len(obs)):
        q = comp.mean + 0.01 * np.sin(t)
        t0 = time.perf_counter()
        comp.search(q)
        ts_search.append(1e3 * (time.perf_counter() - t0))
    print(f'\n## method A: PCA search {np.median(ts_search):.3f} ms per query ({comp.pca_dims} dims, '
          f'{comp.db.size} postures); whole completion (normalise, retarget, search, substitute, '
          f'orientations) {med_a["completion"]:.3f} ms per query '
          f'(+ reliability {med_a["reliability"]:.3f} ms; total {np.median(tot_a):.2f} ms wall, '
          f'{np.median(ra.cpu_ms):.2f} ms CPU per frame)')

    # 4. the node's work per message, two users
    obs2, ts2 = corrupt_clip(truth + np.array([0.8, 0.3, 0.0]), seed=7)
    nm = node_messages(db, obs, ts, obs2, ts2)
    print(f'\n## reconstruction node per two-user message, no DDS (decode, reliability + C per user, '
          f'check, encode): median {np.median(nm["message"]):.2f} ms, p95 '
          f'{np.percentile(nm["message"], 95):.2f} ms; a new user\'s state '
          f'{np.median(nm["new_user"]):.2f} ms')
    print_users_per_message(db, a.frames)

    # 5. scaling with database size and K (KNN only, and the whole frame)
    sizes = (1000, 3000, 10000) if a.quick else (1000, 3000, 10000, 50000)
    print('\n## KNN (Eq. 9) vs database size: median ms per query; kdtree recall of the exact '
          'neighbours')
    print(f'{"postures":>9}{"brute ms":>10}{"kdtree ms":>11}{"recall":>8}{"frame C ms":>12}'
          f'{"CPU ms":>8}')
    Rs = []
    est = Reconstructor(sdb, method='C')
    queries = []
    for t in range(0, len(obs), 3):
        f = SkeletonFrame(positions=obs[t], tracking_state=ts[t])
        R = est._reliability_for(f)
        queries.append(est.preparer.prepare(obs[t], R, est.reliability.height).query)
        Rs.append(R)
    for size in sizes:
        big = jittered(db, size)
        brute = NaturalPostureOptimizer(big, knn='brute')
        tree = NaturalPostureOptimizer(big, knn='kdtree')
        tb, tk, rec = [], [], []
        for q, R in zip(queries, Rs):
            t0 = time.perf_counter()
            ib, _ = brute.search.knn_search(q, R)
            t1 = time.perf_counter()
            ik, _ = tree.search.knn_search(q, R)
            t2 = time.perf_counter()
            tb.append(1e3 * (t1 - t0))
            tk.append(1e3 * (t2 - t1))
            rec.append(len(set(ib) & set(ik)) / len(ib))
        sub = slice(0, min(len(obs), 45))
        _, tot, _, rr = run_clip(big, obs[sub], ts[sub], 'C')
        print(f'{size:>9}{np.median(tb):>10.3f}{np.median(tk):>11.3f}{np.mean(rec):>8.2f}'
              f'{np.median(tot):>12.2f}{np.median(rr.cpu_ms):>8.2f}')
    print(f'\n## method C vs K (database {src}, {n} postures): median ms per frame')
    ks = (10, 30, 60) if a.quick else (10, 30, 60, 120)
    for k in ks:
        _, tot, stages, rr = run_clip(db, obs[:60], ts[:60], 'C', k=k)
        med = stage_medians(stages)
        print(f'    K={k:<4} total {np.median(tot):6.2f} ms wall, {np.median(rr.cpu_ms):6.2f} ms CPU '
              f'(knn {med["knn"]:.3f}, local PCA {med["local_pca"]:.3f}, optimise '
              f'{med["optimise"]:.3f})')
    if a.source != 'synthetic':
        big_database(obs, ts)
    return 0


def big_database(obs, ts) -> None:
    """Section 6: method C on every CMU clip and its mirror image (no filter)."""
    try:
        db = load_or_build_default(source='cmu', classes=None, split='all', mirror=True,
                                   threshold=0.0)
    except DatabaseError as e:
        print(f'\n## large database: not built ({e})')
        return
    print(f'\n## method C per frame per user, large database (all CMU clips + mirrored, no filter: '
          f'{len(db.positions)} postures), K=30: KNN screened in float32 (the default from '
          f'{opt_mod.SCREEN_FROM} postures) vs exact float64; interleaved, 3 rounds')
    rows = {'screened': [], 'exact': []}
    saved = opt_mod.SCREEN_FROM
    try:
        for _ in range(3):
            for name in rows:
                opt_mod.SCREEN_FROM = saved if name == 'screened' else 1 << 62
                _, tot, stages, r = run_clip(db, obs, ts, 'C')
                rows[name].append((np.median(tot), np.median(r.cpu_ms),
                                   np.percentile(r.cpu_ms, 95), stage_medians(stages)['knn']))
    finally:
        opt_mod.SCREEN_FROM = saved
    for name, v in rows.items():
        v = np.array(v)
        print(f'    {name:<9} median {np.median(v[:, 0]):.2f} ms wall, {np.median(v[:, 1]):.2f} ms '
              f'CPU (p95 {np.median(v[:, 2]):.2f}), knn {np.median(v[:, 3]):.3f} ms')


if __name__ == '__main__':
    raise SystemExit(main())
