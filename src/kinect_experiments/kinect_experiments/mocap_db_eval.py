"""What a database of the lab's own mocap does to method C, scored on a held-out subject.

For each held-out subject s of the UI-PRMD development set (folds), two motion databases:

* ``CMU`` — the default database (CMU five-class database clips);
* ``CMU+vicon`` — the same clips plus the Vicon (Plug-in-Gait marker -> joint centre) postures of
  the *other* subjects (:func:`skeleton_data.database.uiprmd_vicon_source`, through
  ``config/joint_maps/plug_in_gait.yaml``), built into ``cache/`` like the default one.

Subject s's Kinect clips are then reconstructed by method C with each database (default
parameters) and scored against s's own marker reference (:func:`skeleton_eval.paired.load_dataset`,
:func:`skeleton_eval.metrics.compute_all`), next to the raw Kinect skeleton. Subject s's postures
are never in the database its clips are scored with (checked: the fold stops if a database clip
names subject s). Nothing is tuned: C runs with its defaults.

Rows: per movement (m01-m10) and ``overall`` (frame-weighted over the folds' clips, m03_s01, the
tracking failure, excluded as in ``evaluate --real``).

``python -m kinect_experiments.mocap_db_eval --folds 1,2,3,4,5 [--max-clips N] [--out out/mocap_db]``
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np
from skeleton_data.database import load_or_build_default, uiprmd_vicon_source
from pose_reconstruction.methods import default_database
from skeleton_eval import evaluation as E
from skeleton_eval.clips import load_clips
from skeleton_eval.registry import load_plugins, make_method
from skeleton_eval import metrics as M
from skeleton_eval.paired import load_dataset
from skeleton_eval.real_eval import make_streams
from skeleton_eval.sensor_params import load_params
from skeleton_data.database import default_shared_dir
from skeleton_eval.report import json_safe

SUBJECTS = (1, 2, 3, 4, 5)
VARIANTS = ('raw', 'C (CMU)', 'C (CMU+vicon)')
METRICS = (('eq18_cm', 'Eq. 18 (cm)'), ('mpjpe_cm', 'MPJPE (cm)'),
           ('bone_dir_deg', 'bone dir (deg)'), ('bone_std_cm', 'bone-length std (cm)'),
           ('jitter_ms2', 'jitter (m/s^2)'))


def fold_database(src, held_out: int, subjects: Sequence[int] = SUBJECTS, stats=None,
                  source: str = 'auto', cache_dir=None):
    """The default (``source``) + Vicon-postures database of the fold that scores ``held_out``
    (training subjects only); raises RuntimeError if a clip of ``held_out`` got in."""
    train = [s for s in subjects if s != held_out]
    db = load_or_build_default(source, cache_dir=cache_dir, stats=stats,
                               mapped=[uiprmd_vicon_source(src, subjects=train)])
    leak = [c for c in db.meta.get('clips', []) if f'_s{held_out:02d}_' in c]
    if leak:
        raise RuntimeError(f'fold s{held_out:02d}: database holds its clips {leak[:3]}')
    return db


def _pick(streams: List, max_clips: int) -> List:
    if not max_clips or len(streams) <= max_clips:
        return streams
    idx = np.linspace(0, len(streams) - 1, max_clips).round().astype(int)
    return [streams[i] for i in sorted(set(idx))]


class _TrustProbe:
    """Wraps a method; after every frame records its trust in the sensor (method C: 1 = the
    output follows the observation, 0 = the database solution)."""

    def __init__(self, method):
        self.method, self.name, self.trust = method, method.name, []

    def reset(self):
        self.method.reset()

    def process(self, frame):
        out = self.method.process(frame)
        self.trust.append(float(getattr(self.method, 'trust_sensor', np.nan)))
        return out


def evaluate(src, folds: Sequence[int] = SUBJECTS, max_clips: int = 0, progress=None,
             params: Optional[Dict] = None) -> Dict:
    """``params``: overrides of C's parameters, the same for both databases."""
    load_plugins()
    height = float(load_params(None)['placement']['sensor_height_m'])
    db_cmu = default_database()
    parts: Dict[str, Dict[str, list]] = {v: {} for v in VARIANTS}
    times: Dict[str, list] = {v: [] for v in VARIANTS}
    trust: Dict[str, Dict[str, list]] = {v: {} for v in VARIANTS[1:]}
    folds_info = []
    t0 = time.time()
    for s in folds:
        st: Dict = {}
        db_mix = fold_database(src, s, stats=st)
        clips, _, _ = load_dataset(src, subjects=[s], sensor_height=height)
        rows = make_streams(clips)
        rows.pop('m03_s01', None)
        info = {'held_out': s, 'db_cmu': len(db_cmu), 'db_mix': len(db_mix),
                'db_mix_path': st.get('path'), 'clips': 0, 'frames': 0}
        methods = {'raw': make_method('raw'),
                   'C (CMU)': _TrustProbe(make_method('C', db=db_cmu, **(params or {}))),
                   'C (CMU+vicon)': _TrustProbe(make_method('C', db=db_mix, **(params or {})))}
        for row in sorted(rows):
            for stream in _pick(rows[row], max_clips):
                info['clips'] += 1
                info['frames'] += len(stream)
                for v, m in methods.items():
                    out, t = E.run_method(m, stream)
                    times[v].append(t)
                    if isinstance(m, _TrustProbe):
                        for key in (row, 'overall'):
                            trust[v].setdefault(key, []).extend(m.trust)
                        m.trust = []
                    res = M.compute_all(out, stream.truth, stream.fps)
                    for key in (row, 'overall', f'fold s{s:02d}'):
                        parts[v].setdefault(key, []).append((res, len(stream)))
                if progress:
                    progress(s, stream.clip_name)
        folds_info.append(info)
    results = {v: {row: E._combine([p for p, _ in lst], [w for _, w in lst])
                   for row, lst in rows_.items()} for v, rows_ in parts.items()}
    return {'source': str(src), 'folds': folds_info, 'max_clips': max_clips, 'params': params or {},
            'wall_s': time.time() - t0, 'results': results,
            'time_ms': {v: E._time_summary(np.concatenate(t)) for v, t in times.items() if t},
            'trust': {v: {row: float(np.nanmean(x)) for row, x in rows_.items()}
                      for v, rows_ in trust.items()}}


def evaluate_synthetic(src, subjects: Sequence[int] = SUBJECTS, max_frames: int = 300,
                       sensor_params=None, params: Optional[Dict] = None) -> Dict:
    """The other side of the trade: C with CMU vs CMU + every listed subject's Vicon postures on
    the sensor-model streams of the CMU dev clips (``evaluate``'s Table IV: scenarios a, b, c).
    {variant: {scenario: Eq. 18 cm}}."""
    load_plugins()
    _, dev_clips, _ = load_clips('auto', 0)
    mix = load_or_build_default(mapped=[uiprmd_vicon_source(src, subjects=subjects)])
    p = dict(params or {})
    res = E.evaluate([('C', dict(p, db=default_database()), VARIANTS[1]),
                      ('C', dict(p, db=mix), VARIANTS[2])], dev_clips, max_frames=max_frames,
                     sensor_params=sensor_params)
    return {v: {sc: r['metrics']['eq18_cm']['overall'] for sc, r in res['results'][v].items()
                if isinstance(r, dict) and 'metrics' in r} for v in VARIANTS[1:]}


def _order(rows):
    mv = sorted(r for r in rows if r.startswith('m'))
    fo = sorted(r for r in rows if r.startswith('fold'))
    return mv + fo + ['overall']


def to_markdown(res: Dict) -> str:
    f = ', '.join(f"s{i['held_out']:02d} ({i['clips']} clips, database {i['db_cmu']} -> "
                  f"{i['db_mix']} postures)" for i in res['folds'])
    lines = [f'Held-out folds: {f}.'
             + (f" C parameters: {res['params']}." if res.get('params') else ''), '']
    rows = _order(res['results']['raw'])
    for key, head in METRICS:
        lines += [f'| {head} | ' + ' | '.join(VARIANTS) + ' | C+vicon vs C |',
                  '|---' * (len(VARIANTS) + 2) + '|']
        for row in rows:
            vals = [res['results'][v][row][key]['overall'] for v in VARIANTS]
            a, b = vals[1], vals[2]
            rel = f'{100 * (b - a) / a:+.1f} %' if np.isfinite(a) and a else 'n/a'
            lines.append(f'| {row} | ' + ' | '.join(f'{x:.2f}' for x in vals) + f' | {rel} |')
        lines.append('')
    if res.get('trust'):
        lines += ['| mean trust in the sensor | ' + ' | '.join(VARIANTS[1:]) + ' |',
                  '|---' * len(VARIANTS) + '|']
        for row in [r for r in rows if not r.startswith('fold')]:
            lines.append(f'| {row} | ' + ' | '.join(f"{res['trust'][v][row]:.2f}"
                                                    for v in VARIANTS[1:]) + ' |')
        lines.append('')
    lines.append('Time per frame p50/p95 (ms, machine shared): ' + ', '.join(
        f"{v} {t['p50_ms']:.2f}/{t['p95_ms']:.2f}" for v, t in res.get('time_ms', {}).items()))
    return '\n'.join(lines)


def main(argv=None) -> int:
    shared = default_shared_dir()
    ap = argparse.ArgumentParser(prog='mocap_db_eval', description=__doc__.split('\n')[0])
    ap.add_argument('--src', type=Path,
                    default=(shared / 'kinect' / 'ui-prmd') if shared else None)
    ap.add_argument('--folds', default='1,2,3,4,5', help='held-out subjects [%(default)s]')
    ap.add_argument('--max-clips', type=int, default=0,
                    help='clips per movement and fold, 0 = all [%(default)s]')
    ap.add_argument('--out', type=Path, default=Path('out/mocap_db'))
    ap.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                    help='override a parameter of C for both databases (robustness checks)')
    ap.add_argument('--synthetic', action='store_true',
                    help='instead: C with CMU vs CMU + all --folds subjects\' Vicon postures on '
                         'the sensor-model streams of the CMU dev clips (Eq. 18 per scenario)')
    ap.add_argument('--sensor-params', default=None, help='--synthetic: sensor model YAML')
    ap.add_argument('--quiet', action='store_true')
    args = ap.parse_args(argv)
    if args.src is None or not Path(args.src).is_dir():
        print(f'mocap_db_eval: no UI-PRMD folder at {args.src}', file=sys.stderr)
        return 1
    try:
        folds = [int(x) for x in args.folds.split(',') if x.strip()]
    except ValueError:
        print(f'mocap_db_eval: --folds must be subject numbers, got {args.folds!r}',
              file=sys.stderr)
        return 2
    bad = [s for s in folds if s not in SUBJECTS]
    if bad:
        print(f'mocap_db_eval: unknown subject(s) {bad}; development subjects: {SUBJECTS}',
              file=sys.stderr)
        return 2
    params = {}
    for item in args.set:
        name, sep, val = item.partition('=')
        if not sep or not name:
            print(f'mocap_db_eval: --set needs NAME=VALUE, got {item!r}', file=sys.stderr)
            return 2
        try:
            params[name] = json.loads(val)
        except ValueError:
            params[name] = val
    if args.synthetic:
        syn = evaluate_synthetic(args.src, folds, sensor_params=args.sensor_params, params=params)
        scs = sorted(next(iter(syn.values())))
        lines = ['| Eq. 18 (cm), sensor-model streams of the CMU dev clips | '
                 + ' | '.join(scs) + ' |', '|---' * (len(scs) + 1) + '|']
        lines += [f'| {v} | ' + ' | '.join(f'{syn[v][sc]:.2f}' for sc in scs) + ' |'
                  for v in syn]
        print('\n'.join(lines))
        return 0
    prog = None if args.quiet else (lambda s, c: print(f'  s{s:02d} {c}', file=sys.stderr))
    res = evaluate(args.src, folds, args.max_clips, prog, params)
    md = to_markdown(res)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / 'mocap_db.md').write_text(md + '\n')
    (args.out / 'mocap_db.json').write_text(json.dumps(json_safe(res), indent=1))
    print(md)
    return 0


if __name__ == '__main__':  # pragma: no cover
    sys.exit(main())
