"""Benchmark of the performance controller (against its targets); prints every figure.

    ros2 run performance_control bench_control                 # test seeds (the reported figures)
    ros2 run performance_control bench_control --dev           # dev seeds (used for tuning)
    ros2 run performance_control bench_control --performers 2 --skip-physics   # quick
    ros2 run performance_control bench_control --performers 6    # the first, smaller set

The default, 30 performers per feature (180 imitation windows, 15 seeds of non-imitation clips),
was fixed before any test run of it; ``--performers 6`` is the first set (36 windows, one window =
2.8 %: too coarse for a 90 % target), whose performers are the default's first six. Dev and test
seeds stay disjoint (dev 0..., test 1000...).

1. Intention recognition on sensor-model streams (scenario a): per feature with an example
   motion, ``--performers`` users of another body size (1.5-1.95 m), style, tempo and amplitude
   imitate it twice (stand 2 s, imitate 4 s, stand 2 s, imitate 4 s); a window counts as
   recognised when the feature's recognizer says "imitating" within 0.5 s of the window's start
   (its fade-in start). False engagements: share of frames of walking, boxing (punch, kick) and
   standing clips (built-in motions of other seeds, through the same sensor model) in which any
   feature's recognizer says "imitating". Targets: >= 90 % and <= 2 %.
2. Physics through the whole controller: the character started on the bars / rope while the user
   imitates (stays on: both hands held during every imitation window; falls: no hand held 2 s
   after the user stops and the COM dropped), jumping on the trampoline (peak COM rise), swimming
   (speed); the deepest penetration of the character's capsules into any feature (target <= 2 cm)
   and the control step time per user and frame (median, target <= 5 ms: the step's CPU time,
   ``time.thread_time``, which the other processes of a loaded machine do not inflate, beside its
   wall time); the COM speed when the hands let go of the bars / rope and how far away the feet
   land (the release of a user lowering the arms is a dismount, not a fling).
3. ``--real`` / ``--real-only`` (needs ../shared): frames "imitating" on real movements that
   imitate nothing -- UI-PRMD Kinect v2 leave-one-subject-out over s01-s05 (per fold the
   bent-legs veto's constants picked on the other four, :func:`loso`; per fold, pooled per
   exercise), CMU clips of every class through the sensor model (per class) -- and CMU subject
   01's real hanging recognised as the monkey bars. Targets <= 2 % overall, <= 5 % each, >= 80 %.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, Optional

import numpy as np

from . import real_data as rd
from . import support
from .controller import ControlParams, PerformanceController, build_models
from .features import load_world
from .intention import IntentionRecognizer, RecognizerParams
from .performances import (PERFORMANCE_PLACEMENT, SENSOR_HEIGHT, imitation_stream, jump_stream,
                           non_imitation_clips, to_sensor)

FPS = 30.0


def _sensor_world(s: np.ndarray, height: float = SENSOR_HEIGHT) -> np.ndarray:
    return s + np.array([0.0, 0.0, height])


def walking_features(world) -> set:
    """The features whose example is a walk (the floor, Sec. 8.3): real walking is one."""
    return {f.name for f in world.with_example() if f.kind == 'floor'}


def recognition(world, params: RecognizerParams, seed0: int, performers: int,
                noise: bool = True, sensor: Optional[Dict] = None, walking: bool = False) -> Dict:
    """The imitation windows of the features with an example (``walking``: of the walk on the
    floor only -- walking in place; else every other feature: the 180-window set) and the
    false engagements on the built-in non-imitation clips (the walk recognizer not counted on
    the walking clip)."""
    models = build_models(world, params)
    walk = walking_features(world)
    out = {'windows': 0, 'hit': 0, 'latency': [], 'per_feature': {}, 'confusion_frames': 0,
           'imit_frames': 0}
    feats = [f for f in world.with_example() if (f.name in walk) == walking]
    for fi, f in enumerate(feats):    # the seeds of the 180-window set as before the walk
        hits = tot = 0
        for k in range(performers):
            seed = seed0 + (3000 if walking else 0) + 100 * fi + k
            rng = np.random.default_rng(seed)
            p, windows = imitation_stream(f, rng)
            s, st = to_sensor(p, f'{f.name}_{k}', seed, noise, sensor, states=True)
            s = _sensor_world(s)
            rec = IntentionRecognizer(list(models.values()), params)
            flags = np.zeros(len(s), bool)
            other = np.zeros(len(s), bool)
            for i in range(len(s)):
                r = rec.update(s[i], i / FPS, st[i])
                flags[i] = r[f.name].imitating
                other[i] = any(x.imitating for n, x in r.items()
                               if n != f.name and n not in walk)
            t = np.arange(len(s)) / FPS
            for a, b in windows:
                tot += 1
                inwin = np.nonzero((t >= a) & (t <= b) & flags)[0]
                if len(inwin) and t[inwin[0]] - a <= 0.5:
                    hits += 1
                    out['latency'].append(t[inwin[0]] - a)
                win = (t >= a + 0.5) & (t <= b)
                out['confusion_frames'] += int(np.sum(other & win))
                out['imit_frames'] += int(np.sum(win))
        out['per_feature'][f.name] = (hits, tot)
        out['windows'] += tot
        out['hit'] += hits
    fe_frames = fe_total = 0
    per_clip = {}
    for k in range(0 if walking else max(1, performers // 2)):
        seed = seed0 + 5000 + k
        for name, clip in non_imitation_clips(seed):
            s, st = to_sensor(clip, f'{name}_{seed}', seed, noise, sensor, states=True)
            s = _sensor_world(s)
            rec = IntentionRecognizer(list(models.values()), params)
            n_bad = 0
            for i in range(len(s)):
                r = rec.update(s[i], i / FPS, st[i])
                n_bad += any(x.imitating for n, x in r.items()
                             if not (name == 'walk' and n in walk))
            fe_frames += n_bad
            fe_total += len(s)
            a, b = per_clip.get(name, (0, 0))
            per_clip[name] = (a + n_bad, b + len(s))
    out['false_frames'], out['false_total'], out['per_clip'] = fe_frames, fe_total, per_clip
    return out


def _imitating(models, params, pos, st, bent_legs_gate: bool = True):
    """(T, features) bool: each feature's recognizer says "imitating", per frame; without
    ``bent_legs_gate`` also the per-frame support depth and airborne flags (T,), (T,) (the
    bent-legs veto applied offline: :func:`.support.bent_legs_mask`)."""
    rec = IntentionRecognizer(list(models.values()), params)
    rec.bent_legs_gate = bent_legs_gate
    out = np.zeros((len(pos), len(models)), bool)
    depth = np.zeros(len(pos))
    air = np.zeros(len(pos), bool)
    for i in range(len(pos)):
        r = rec.update(pos[i], i / FPS, st[i])
        out[i] = [r[n].imitating for n in models]
        depth[i], air[i] = rec.support.depth, rec.support.airborne
    return out if bent_legs_gate else (out, depth, air)


# The bent-legs veto's constants tried leave-one-subject-out (support.CROUCH, CROUCH_HOLD): the
# share of the standing hip height lowered, the hold (s) after the hips are back up
CROUCH_GRID = (0.3, 0.2, 0.15, 0.1, 0.07, 0.05)
HOLD_GRID = (0.0, 0.25, 0.5, 1.0)
TARGET_ALL, TARGET_EACH = 2.0, 5.0     # % of frames "imitating": overall, every exercise


def _uiprmd_rates(streams, pair):
    """{exercise: [imitating frames, frames, vetoed frames]} and 'all' for the UI-PRMD streams
    [(Stream, flags, depth, airborne)] with the veto constants ``pair`` (None: no veto)."""
    tab: Dict = {}
    for s, f, depth, air in streams:
        t = np.arange(len(f)) / FPS
        veto = (support.bent_legs_mask(t, depth, air, *pair) if pair is not None
                else np.zeros(len(f), bool))
        fired = f.any(axis=1) & ~veto
        for key in (s.group, 'all'):
            a = tab.setdefault(key, np.zeros(3))
            a += (fired.sum(), len(f), veto.sum())
    return tab


def _meets(tab) -> bool:
    rate = {k: 100 * a[0] / max(a[1], 1) for k, a in tab.items()}
    return rate['all'] <= TARGET_ALL and all(v <= TARGET_EACH for k, v in rate.items()
                                             if k != 'all')


def pick_pair(streams):
    """(pair, met): the veto constants (CROUCH, CROUCH_HOLD) of the grid that meet the targets
    (<= 2 % overall, <= 5 % every exercise) on each subject of ``streams`` with the fewest frames
    vetoed (the least strict: do no harm), else the pair with the lowest worst exercise. (Met on
    the subjects pooled, the least strict pair sat on the boundary and failed on two left-out
    subjects.)"""
    subjects = sorted({s.subject for s, *_ in streams})
    pairs = [(c, h) for c in CROUCH_GRID for h in HOLD_GRID]
    tabs = {pr: _uiprmd_rates(streams, pr) for pr in pairs}
    each = {pr: [_uiprmd_rates([x for x in streams if x[0].subject == o], pr) for o in subjects]
            for pr in pairs}
    ok = [pr for pr in pairs if all(_meets(t) for t in each[pr])]
    if ok:
        return min(ok, key=lambda pr: tabs[pr]['all'][2]), True
    return min(pairs, key=lambda pr: max(100 * a[0] / max(a[1], 1)
                                         for t in each[pr] for k, a in t.items()
                                         if k != 'all')), False


def loso(streams) -> Dict:
    """Leave-one-subject-out over the UI-PRMD subjects: per fold the veto constants are
    :func:`pick_pair` on the four other subjects, reported on the left-out one."""
    folds = {}
    for subj in sorted({s.subject for s, *_ in streams}):
        pick, ok = pick_pair([x for x in streams if x[0].subject != subj])
        folds[subj] = (pick, ok, _uiprmd_rates([x for x in streams if x[0].subject == subj],
                                               pick))
    return folds


TUNE_SUBJECTS = ('s01', 's02')   # UI-PRMD subjects looked at while choosing the mechanisms


def real_recognition(world, params: RecognizerParams, seed: int = 0) -> Dict:
    """Recognition on real movements (:mod:`.real_data`, needs ../shared): frames "imitating"
    any feature in the UI-PRMD Kinect v2 clips (per exercise and subject; leave-one-subject-out
    for the bent-legs veto's constants) and in the CMU clips through the sensor model (per class,
    tuning / held-out clips; the walk recognizer not counted on locomotion: walking is walking),
    and subject 01's hanging frames recognised as the monkey bars after the first 0.5 s of each
    segment."""
    models = build_models(world, params)
    names = list(models)
    walk = [names.index(n) for n in walking_features(world)]
    res: Dict = {'uiprmd': {}, 'cmu': {}, 'hang': {}, 'names': names}

    def add(table, key, flags):
        a = table.setdefault(key, np.zeros(2 + len(names)))
        a[0] += flags.any(axis=1).sum()
        a[1] += len(flags)
        a[2:] += flags.sum(axis=0)

    ui = []
    shipped = (support.CROUCH, support.CROUCH_HOLD)
    for s in rd.uiprmd_streams():
        f, depth, air = _imitating(models, params, s.positions, s.states, bent_legs_gate=False)
        ui.append((s, f, depth, air))
        add(res['uiprmd'], ('no veto', s.group), f)
        add(res['uiprmd'], ('no veto', 'all'), f)
        g = f & ~support.bent_legs_mask(np.arange(len(f)) / FPS, depth, air, *shipped)[:, None]
        for key in (('subject', s.subject), ('all', s.group), ('all', 'all')):
            add(res['uiprmd'], key, g)
    if ui:
        res['loso'] = loso(ui)
        res['pick_all'] = pick_pair(ui)
    for s in rd.cmu_streams(seed=seed):
        f = _imitating(models, params, s.positions, s.states)
        if s.group == 'locomotion':
            f[:, walk] = False
        for key in ((s.split, s.group), (s.split, 'all')):
            add(res['cmu'], key, f)
    if 'monkey_bars' in names:
        mb = names.index('monkey_bars')
        for s in rd.hanging_segments(seed=seed):
            f = _imitating(models, params, s.positions, s.states)
            hit = tot = 0
            for a, b in rd.segments(s.label):
                a2 = a + int(round(0.5 * FPS))
                if b > a2:
                    hit += int(f[a2:b, mb].sum())
                    tot += b - a2
            res['hang'][s.name] = (hit, tot, int(s.label.sum()))
    return res


def print_real(res: Dict, world) -> None:
    names = res['names']

    def row(label, a):
        per = ', '.join(f'{n} {100 * x / max(a[1], 1):.1f}' for n, x in zip(names, a[2:]) if x)
        return f'  {label:22s} {100 * a[0] / max(a[1], 1):5.2f} % of {int(a[1]):6d}' + (
            f'  ({per})' if per else '')

    lo = res.get('loso')
    if lo:
        print('real Kinect v2 (UI-PRMD), leave-one-subject-out: the bent-legs veto\'s constants '
              '(CROUCH share of the standing hip height, CROUCH_HOLD s) chosen on the four other '
              f'subjects, frames "imitating" on the left-out one (shipped: CROUCH '
              f'{support.CROUCH}, CROUCH_HOLD {support.CROUCH_HOLD} s)')
        pooled: Dict = {}
        for subj, (pick, ok, tab) in lo.items():
            rates = {k: 100 * a[0] / max(a[1], 1) for k, a in tab.items()}
            worst = max((k for k in rates if k != 'all'), key=rates.get)
            print(f'  fold {subj}: CROUCH {pick[0]}, HOLD {pick[1]} s'
                  f'{"" if ok else " (no pair met the targets on the other four)"} -> '
                  f'{rates["all"]:.2f} % overall, worst {worst} {rates[worst]:.1f} %, vetoed '
                  f'{100 * tab["all"][2] / max(tab["all"][1], 1):.1f} % of frames')
            for k, a in tab.items():
                pooled.setdefault(k, np.zeros(3))
                pooled[k] += a
        rates = {k: 100 * a[0] / max(a[1], 1) for k, a in pooled.items()}
        worst = max(v for k, v in rates.items() if k != 'all')
        print(f'  pooled over the five folds: {rates["all"]:.2f} % overall (target <= 2 %), worst '
              f'exercise {worst:.1f} % (target <= 5 %) -> '
              f'{"met" if rates["all"] <= 2 and worst <= 5 else "NOT met"}')
        print('  per exercise (left-out subjects): ' + ', '.join(
            f'{k} {v:.1f}' for k, v in sorted(rates.items()) if k != 'all'))
        pick, ok = res['pick_all']
        print(f'  the same rule on all five subjects: CROUCH {pick[0]}, HOLD {pick[1]} s'
              f'{"" if ok else " (no pair met the targets on each)"} (shipped: '
              f'{support.CROUCH}, {support.CROUCH_HOLD} s)')
    u = res['uiprmd']
    if u:
        print('real Kinect v2 (UI-PRMD), the shipped constants on every subject, and without the '
              'veto:')
        for k in sorted(u):
            print(row(f'{k[0]} {k[1]}', u[k]))
    c = res['cmu']
    if c:
        held = [k for k in c if k[0] == 'held-out' and k[1] != 'all']
        worst = max((100 * c[k][0] / max(c[k][1], 1) for k in held), default=0.0)
        tot = c.get(('held-out', 'all'), np.zeros(2))
        fr = 100 * tot[0] / max(tot[1], 1)
        print(f'CMU through the sensor model, held-out clips: {fr:.2f} % overall, worst class '
              f'{worst:.1f} % (targets <= 2 / 5 %) -> {"met" if fr <= 2 and worst <= 5 else "NOT met"}')
        for k in sorted(c):
            print(row(f'{k[0]} {k[1]}', c[k]))
    h = res['hang']
    if h:
        ex = world.features['monkey_bars'].example
        own = Path(ex.bvh).stem if ex is not None and ex.bvh else ''
        held = [k for k in h if k != own]
        hit = sum(h[k][0] for k in held)
        tot = sum(h[k][1] for k in held)
        print(f'CMU subject 01 hanging frames recognised as monkey bars after 0.5 s, clips other '
              f'than the example\'s ({own or "generated"}): {100 * hit / max(tot, 1):.1f} % of '
              f'{tot} (target >= 80 %) -> {"met" if hit >= 0.8 * tot and tot else "NOT met"}')
        for k, (a, b, n) in h.items():
            print(f'  {k}{" (the example clip)" if k == own else ""}: {a}/{b} '
                  f'({n} hanging frames)')


def release(rows, world) -> tuple:
    """(COM speed m/s at the last hand's release -- the most over the 0.2 s before it and the
    0.1 s after --, horizontal distance m from there to where a foot next holds the floor, or nan)
    of a run that starts holding a feature with the hands: the release of a user who lowers the
    arms is a dismount, not a fling."""
    held = [any(e.startswith('Hand') for e in o.contacts) for o in rows]
    k = next((i for i in range(len(held) - 1, 0, -1) if held[i - 1] and not held[i]), None)
    if k is None:
        return float('nan'), float('nan')
    com = np.array([o.com for o in rows])
    v = np.linalg.norm(np.diff(com, axis=0), axis=1) * FPS
    speed = float(v[max(0, k - 6):k + 3].max())
    land = next((i for i in range(k, len(rows)) if any(
        e.startswith('Foot') and world.features[f].kind == 'floor'
        for e, f in rows[i].contacts.items())), None)
    return speed, (float(np.linalg.norm(com[land, :2] - com[k, :2])) if land is not None
                   else float('nan'))


def physics(world, params: ControlParams, seed0: int, noise: bool = True,
            sensor: Optional[Dict] = None) -> Dict:
    models = build_models(world, params.recognizer)
    res: Dict = {'ms': [], 'cpu': [], 'pen': 0.0, 'pen_by': {}, 'unstable': {}, 'release': {}}

    def run(start: str, s: np.ndarray, st: np.ndarray):
        ctl = PerformanceController(world, params, models, start=start)
        rows = []
        for i in range(len(s)):
            o = ctl.step(s[i], i / FPS, st[i])
            if i > 0:
                res['ms'].append(o.compute_ms)
                res['cpu'].append(o.cpu_ms)
            res['pen'] = max(res['pen'], o.penetration)
            res['pen_by'][start] = max(res['pen_by'].get(start, 0.0), o.penetration)
            rows.append(o)
        res['unstable'][start] = res['unstable'].get(start, 0) + ctl.dp.unstable_steps
        return rows

    for name in ('monkey_bars', 'rope'):
        f = world.features[name]
        stays = falls = trials = 0
        for k in range(3):
            seed = seed0 + 7000 + k
            rng = np.random.default_rng(seed)
            p, windows = imitation_stream(f, rng, pattern=((-1.0, 6.0),), total=9.0, fade=0.2)
            # the user imitates from the first frame with the hands up, then stops (arms down)
            rows = run(name, *to_sensor(p, f'phys_{name}_{k}', seed, noise, sensor, states=True))
            t = np.arange(len(rows)) / FPS
            held = np.array([sum(e.startswith('Hand') for e in o.contacts) for o in rows])
            z = np.array([o.com[2] for o in rows])
            trials += 1
            stays += bool(np.all(held[(t >= 0.0) & (t <= 5.8)] >= 1))
            after = t >= 6.0 + 2.0
            falls += bool(np.all(held[after] == 0) and z[after].min() < z[t <= 5.8].min() - 0.3)
            res['release'].setdefault(name, []).append(release(rows, world))
        res[name] = (stays, falls, trials)
    # trampoline: jumping in place
    rng = np.random.default_rng(seed0 + 8000)
    rows = run('trampoline', *to_sensor(jump_stream(rng), 'jumps', seed0 + 8000, noise, sensor,
                                        states=True))
    z = np.array([o.com[2] for o in rows])
    res['trampoline_rise'] = float(z.max() - z[:20].mean())
    # water: breaststroke imitation
    f = world.features['water']
    rng = np.random.default_rng(seed0 + 9000)
    p, _ = imitation_stream(f, rng, pattern=((-1.0, 9.0),), total=8.0, fade=0.2)
    rows = run('water', *to_sensor(p, 'swim', seed0 + 9000, noise, sensor, states=True))
    xy = np.array([o.com[:2] for o in rows])
    res['swim_speed'] = float(np.linalg.norm(xy[-1] - xy[30]) / ((len(rows) - 31) / FPS))
    res['swim_depth_drift'] = float(rows[-1].com[2] - rows[0].com[2])
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--world', default='playground')
    ap.add_argument('--dev', action='store_true', help='dev seeds (tuning), not the test seeds')
    ap.add_argument('--performers', type=int, default=30, help='imitating users per feature')
    ap.add_argument('--no-noise', action='store_true', help='sensor placement only, no noise')
    ap.add_argument('--skip-physics', action='store_true')
    ap.add_argument('--real', action='store_true',
                    help='also the real recordings of ../shared (UI-PRMD Kinect v2, CMU clips '
                         'through the sensor model, CMU subject 01 hanging; several minutes)')
    ap.add_argument('--real-only', action='store_true', help='only the real recordings')
    ap.add_argument('--e1', type=float, default=None, help='e1 threshold (default: node default)')
    ap.add_argument('--e2', type=float, default=None)
    ap.add_argument('--min-activity', type=float, default=None)
    ap.add_argument('--set', action='append', default=[], metavar='KEY=VALUE',
                    help='another recognizer parameter (RecognizerParams field), e.g. smoothing=0.1')
    ap.add_argument('--sensor', action='append', default=[], metavar='PATH=VALUE',
                    help='a sensor-model parameter (dotted path), e.g. '
                         'scenarios.a.occlusion_per_min=4 (robustness checks)')
    a = ap.parse_args(argv)
    sensor = None
    if a.sensor:
        import copy
        sensor = copy.deepcopy(PERFORMANCE_PLACEMENT)
        for kv in a.sensor:
            path, _, val = kv.partition('=')
            keys = path.split('.')
            d = sensor
            for key in keys[:-1]:
                d = d.setdefault(key, {})
            try:
                d[keys[-1]] = float(val)
            except ValueError:
                ap.error(f'--sensor {kv}: the value must be a number')
    world = load_world(a.world)
    rp = RecognizerParams()
    if a.e1 is not None:
        rp.e1_threshold = a.e1
    if a.e2 is not None:
        rp.e2_threshold = a.e2
    if a.min_activity is not None:
        rp.min_activity = a.min_activity
    for kv in a.set:
        k, _, val = kv.partition('=')
        if not hasattr(rp, k):
            ap.error(f'--set {kv}: no recognizer parameter {k}')
        cur = getattr(rp, k)
        if isinstance(cur, bool):
            setattr(rp, k, val.lower() in ('1', 'true', 'yes'))
        else:
            setattr(rp, k, val if isinstance(cur, str) else type(cur)(float(val)))
    rp.validate()
    seed0 = 0 if a.dev else 1000
    try:
        commit = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], capture_output=True,
                                text=True, timeout=5).stdout.strip()
    except Exception:  # noqa: BLE001
        commit = '?'
    print(f'# bench_control world={world.name} seeds={"dev" if a.dev else "test"} '
          f'performers={a.performers} noise={not a.no_noise} commit={commit}')
    print(f'# recognizer {rp}')
    t0 = time.time()
    if sensor is not None:
        print(f'# sensor model overrides {sensor}')
    if a.real or a.real_only:
        print_real(real_recognition(world, rp), world)
        if a.real_only:
            print(f'# {time.time() - t0:.0f} s')
            return 0
    rw = recognition(world, rp, seed0, a.performers, not a.no_noise, sensor, walking=True)
    if rw['windows']:
        rate = rw['hit'] / rw['windows']
        print(f'walking in place recognised within 0.5 s: {100 * rate:.1f} % of '
              f'{rw["windows"]} windows (target >= 90 %) -> {"met" if rate >= 0.9 else "NOT met"}'
              + (f'; latency median {np.median(rw["latency"]):.2f} s' if rw['latency'] else ''))
    r = recognition(world, rp, seed0, a.performers, not a.no_noise, sensor)
    rate = r['hit'] / max(r['windows'], 1)
    fe = r['false_frames'] / max(r['false_total'], 1)
    print(f'recognition within 0.5 s: {100 * rate:.1f} % of {r["windows"]} imitation windows '
          f'(target >= 90 %) -> {"met" if rate >= 0.9 else "NOT met"}')
    for n, (h, tot) in r['per_feature'].items():
        print(f'  {n:12s} {h}/{tot}')
    if r['latency']:
        print(f'  latency median {np.median(r["latency"]):.2f} s, max {np.max(r["latency"]):.2f} s')
    print(f'  other features also "imitating" during windows: '
          f'{100 * r["confusion_frames"] / max(r["imit_frames"], 1):.1f} % of frames')
    print(f'false engagements: {100 * fe:.2f} % of {r["false_total"]} frames of walking/boxing/'
          f'standing (target <= 2 %) -> {"met" if fe <= 0.02 else "NOT met"}')
    for n, (b, tot) in r['per_clip'].items():
        print(f'  {n:6s} {100 * b / max(tot, 1):.2f} %')
    if not a.skip_physics:
        cp = ControlParams(recognizer=rp, sensor_height=SENSOR_HEIGHT)
        ph = physics(world, cp, seed0, not a.no_noise, sensor)
        for n in ('monkey_bars', 'rope'):
            s, f, tot = ph[n]
            print(f'{n}: stays on while imitating {s}/{tot}, falls after stopping {f}/{tot}')
            rel = np.array(ph['release'][n])
            print('  release (arms lowered): COM speed ' + ', '.join(
                f'{x:.1f}' for x in rel[:, 0]) + ' m/s; lands ' + ', '.join(
                f'{x:.1f}' for x in rel[:, 1]) + ' m away')
        print(f'trampoline: COM rise {ph["trampoline_rise"]:.2f} m over standing')
        print(f'water: swim speed {ph["swim_speed"]:.2f} m/s, depth drift '
              f'{ph["swim_depth_drift"]:+.2f} m')
        pen = ph['pen']
        print(f'penetration max: {100 * pen:.1f} cm (target <= 2 cm) -> '
              f'{"met" if pen <= 0.02 else "NOT met"}  ' + ', '.join(
                  f'{k} {100 * v:.1f}' for k, v in ph['pen_by'].items()))
        print('unstable physics steps (MuJoCo bad QACC): ' + ', '.join(
            f'{k} {v}' for k, v in ph['unstable'].items()))
        ms, cpu = np.array(ph['ms']), np.array(ph['cpu'])
        print(f'control step per user, CPU time (this thread; robust to the machine\'s load): '
              f'median {np.median(cpu):.2f} ms, p95 {np.percentile(cpu, 95):.2f} ms (target <= 5 '
              f'ms median) -> {"met" if np.median(cpu) <= 5 else "NOT met"}; wall time: median '
              f'{np.median(ms):.2f} ms, p95 {np.percentile(ms, 95):.2f} ms')
    print(f'# {time.time() - t0:.0f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
