"""Benchmark of the performance controller (issue 24 targets); prints every figure.

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
   and the control step time per user and frame (median, target <= 5 ms).
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
from typing import Dict, Optional

import numpy as np

from .controller import ControlParams, PerformanceController, build_models
from .features import load_world
from .intention import IntentionRecognizer, RecognizerParams
from .performances import (PERFORMANCE_PLACEMENT, SENSOR_HEIGHT, imitation_stream, jump_stream,
                           non_imitation_clips, to_sensor)

FPS = 30.0


def _sensor_world(s: np.ndarray, height: float = SENSOR_HEIGHT) -> np.ndarray:
    return s + np.array([0.0, 0.0, height])


def recognition(world, params: RecognizerParams, seed0: int, performers: int,
                noise: bool = True, sensor: Optional[Dict] = None) -> Dict:
    models = build_models(world, params)
    out = {'windows': 0, 'hit': 0, 'latency': [], 'per_feature': {}, 'confusion_frames': 0,
           'imit_frames': 0}
    for fi, f in enumerate(world.with_example()):
        hits = tot = 0
        for k in range(performers):
            seed = seed0 + 100 * fi + k
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
                other[i] = any(x.imitating for n, x in r.items() if n != f.name)
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
    for k in range(max(1, performers // 2)):
        seed = seed0 + 5000 + k
        for name, clip in non_imitation_clips(seed):
            s, st = to_sensor(clip, f'{name}_{seed}', seed, noise, sensor, states=True)
            s = _sensor_world(s)
            rec = IntentionRecognizer(list(models.values()), params)
            n_bad = 0
            for i in range(len(s)):
                r = rec.update(s[i], i / FPS, st[i])
                n_bad += any(x.imitating for x in r.values())
            fe_frames += n_bad
            fe_total += len(s)
            a, b = per_clip.get(name, (0, 0))
            per_clip[name] = (a + n_bad, b + len(s))
    out['false_frames'], out['false_total'], out['per_clip'] = fe_frames, fe_total, per_clip
    return out


def physics(world, params: ControlParams, seed0: int, noise: bool = True,
            sensor: Optional[Dict] = None) -> Dict:
    models = build_models(world, params.recognizer)
    res: Dict = {'ms': [], 'pen': 0.0, 'pen_by': {}, 'unstable': {}}

    def run(start: str, s: np.ndarray, st: np.ndarray):
        ctl = PerformanceController(world, params, models, start=start)
        rows = []
        for i in range(len(s)):
            o = ctl.step(s[i], i / FPS, st[i])
            if i > 0:
                res['ms'].append(o.compute_ms)
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
        print(f'trampoline: COM rise {ph["trampoline_rise"]:.2f} m over standing')
        print(f'water: swim speed {ph["swim_speed"]:.2f} m/s, depth drift '
              f'{ph["swim_depth_drift"]:+.2f} m')
        pen = ph['pen']
        print(f'penetration max: {100 * pen:.1f} cm (target <= 2 cm) -> '
              f'{"met" if pen <= 0.02 else "NOT met"}  ' + ', '.join(
                  f'{k} {100 * v:.1f}' for k, v in ph['pen_by'].items()))
        print('unstable physics steps (MuJoCo bad QACC): ' + ', '.join(
            f'{k} {v}' for k, v in ph['unstable'].items()))
        ms = np.array(ph['ms'])
        print(f'control step per user: median {np.median(ms):.2f} ms, p95 '
              f'{np.percentile(ms, 95):.2f} ms (target <= 5 ms median) -> '
              f'{"met" if np.median(ms) <= 5 else "NOT met"}')
    print(f'# {time.time() - t0:.0f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
