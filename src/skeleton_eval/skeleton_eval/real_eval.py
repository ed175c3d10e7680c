"""Real-data evaluation: methods on the UI-PRMD Kinect streams, scored against the marker reference.

:func:`evaluate_real` (what ``evaluate --real`` calls) runs every method (default: raw, holt,
one_euro and whatever plug-ins register, e.g. A, B, C) on the real Kinect recordings and scores
the output against the Vicon-derived joint centres registered into the sensor frame
(:func:`skeleton_eval.paired.load_dataset`), with the same metrics as the synthetic table
(:func:`skeleton_eval.metrics.compute_all`: Eq. 18, MPJPE after the per-session rigid registration,
bone-direction error (length-free), bone-length std and error, jitter) plus the latency the method
adds (the peak shift of the velocity cross-correlation of its output with the marker reference
minus the raw input's, on the joints the sensor reports TRACKED, ms, sub-frame and signed:
:func:`tracked_xcorr`) and the processing time.

Rows: per movement (m01-m10, subjects with the reference), ``overall``, and ``m03_s01`` (the real
tracking failure: no marker reference exists for subject 1, so only the reference-free metrics —
jitter, bone-length std, latency — are reported for it).

Notes: the hands are not in the recordings (the importer extrapolates them, NOT_TRACKED), so the
reference hands are set to NaN and take no part in any score. The streams are placed in the
synthetic sensor frame convention (origin ``sensor_height_m`` above the floor, from the sensor
model parameters) so methods see the same frame as in the synthetic evaluation.

Command line: ``python -m skeleton_eval.real_eval --src ../shared/kinect/ui-prmd --out out/real``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Dict, Optional, Sequence

import numpy as np

from .report import json_safe
from .metrics import MAX_LATENCY_FRAMES, added_latency_ms  # noqa: F401 (public here too)
from skeleton_core.model import HAND_LEFT, HAND_RIGHT, NUM_JOINTS
from skeleton_core.model import TRACKED
from . import metrics as M
from .sensor_stream import KinectStream
from . import evaluation as E
from .registry import available_methods, load_plugins, make_method
from .sensor_params import load_params
from .paired import load_dataset

DEFAULT_METHODS = ('raw', 'holt', 'one_euro', 'A', 'B', 'C')
TABLE_METRICS = (('eq18_cm', 'Eq.18 (cm)'), ('mpjpe_cm', 'MPJPE (cm)'),
                 ('bone_dir_deg', 'bone dir (deg)'), ('bone_std_cm', 'bone-length std (cm)'),
                 ('bone_step_cm', 'frame-to-frame (cm)'), ('bone_err_cm', 'bone-length err (cm)'),
                 ('jitter_ms2', 'jitter (m/s^2)'))


def tracked_only(stream) -> np.ndarray:
    """The raw positions with every joint the sensor did not report TRACKED set to NaN: the
    latency is measured on the joints the sensor gives (the hands, not recorded and
    extrapolated NOT_TRACKED, are left out as from every other score)."""
    raw = np.array(stream.positions, float)
    raw[np.asarray(stream.tracking_state) != TRACKED] = np.nan
    return raw


def tracked_xcorr(out, stream) -> np.ndarray:
    """:func:`skeleton_eval.metrics.velocity_xcorr` of ``out`` against the stream's marker
    reference (``truth``) on the joints the sensor reports TRACKED: the added latency of a method
    is the peak shift of its curve minus that of the raw input's (the reference is registered
    with a lag per clip, so raw's is ~0 but not exactly)."""
    return M.velocity_xcorr(out, stream.truth, M.MAX_LATENCY_FRAMES,
                            np.isfinite(tracked_only(stream)).all(-1))


def make_streams(clips, fps: float = 30.0) -> Dict[str, list]:
    """Real clips -> ``{row: [KinectStream]}`` with truth = registered reference (NaN if none)."""
    rows: Dict[str, list] = {}
    period = int(round(1e9 / fps))
    for rc in clips:
        k = rc.kinect
        n = k.num_frames
        truth = (np.full((n, NUM_JOINTS, 3), np.nan) if rc.reference is None
                 else rc.reference.copy())
        truth[:, [HAND_LEFT, HAND_RIGHT]] = np.nan
        s = KinectStream(positions=k.positions.copy(),
                         tracking_state=np.tile(k.tracking_state, (n, 1)), truth=truth,
                         stamps_ns=1_000_000_000 + np.arange(n, dtype=np.int64) * period,
                         events=[], scenario='real', seed=0, clean=None,
                         clip_name=rc.clip.name, fps=fps)
        if rc.clip.is_tracking_failure:
            key = 'm03_s01'
        elif rc.reference is None:
            continue
        else:
            key = f'm{rc.clip.movement:02d}'
        rows.setdefault(key, []).append(s)
    return rows


def _select_methods(methods):
    if not methods or any(m not in available_methods() for m in methods):
        load_plugins()
    avail = available_methods()
    wanted = list(methods) if methods else [m for m in DEFAULT_METHODS if m in avail]
    missing = [m for m in wanted if m not in avail]
    return [m for m in wanted if m in avail], missing


def evaluate_real(src, methods: Optional[Sequence[str]] = None, subjects=None, movements=None,
                  repetitions=None, max_clips: Optional[int] = None, progress=None,
                  clips=None) -> Dict:
    """Run methods on the real recordings; returns a JSON-able dict (see :func:`to_markdown`).

    ``max_clips``: at most this many clips per row (movement), spread over subjects and
    repetitions, to keep slow methods affordable. ``clips``: already loaded
    :func:`~skeleton_eval.paired.load_dataset` clips (else loaded from ``src``)."""
    t_start = time.time()
    skipped = []
    if clips is None:
        height = float(load_params(None)['placement']['sensor_height_m'])
        clips, skipped, _ = load_dataset(src, subjects, movements, repetitions,
                                         sensor_height=height)
    rows = make_streams(clips)
    if max_clips:
        for k, lst in rows.items():
            if len(lst) > max_clips:
                idx = np.linspace(0, len(lst) - 1, max_clips).round().astype(int)
                rows[k] = [lst[i] for i in sorted(set(idx))]
    names, missing = _select_methods(methods)
    results: Dict[str, Dict] = {}
    for name in names:
        method = make_method(name)
        results[name] = {}
        K2 = 2 * M.MAX_LATENCY_FRAMES + 1
        all_parts, all_w, all_lat, all_t = [], [], [np.zeros(K2), np.zeros(K2)], []
        for row in sorted(rows):
            parts, weights, lats, times = [], [], [np.zeros(K2), np.zeros(K2)], []
            for s in rows[row]:
                out, t = E.run_method(method, s)
                parts.append(M.compute_all(out, s.truth, s.fps))
                weights.append(len(s))
                lats[0] += tracked_xcorr(out, s)
                lats[1] += tracked_xcorr(s.positions, s)
                times.append(t)
                if progress:
                    progress(name, row, s.clip_name)
            results[name][row] = {
                'clips': len(parts), 'frames': int(sum(weights)),
                'metrics': E._combine(parts, weights),
                'latency_ms': M.xcorr_latency_ms(lats[0]) - M.xcorr_latency_ms(lats[1]),
                'time': E._time_summary(np.concatenate(times))}
            if row != 'm03_s01':
                all_parts += parts
                all_w += weights
                all_lat[0] += lats[0]
                all_lat[1] += lats[1]
                all_t += times
        if all_parts:
            results[name]['overall'] = {
                'clips': len(all_parts), 'frames': int(sum(all_w)),
                'metrics': E._combine(all_parts, all_w),
                'latency_ms': M.xcorr_latency_ms(all_lat[0]) - M.xcorr_latency_ms(all_lat[1]),
                'time': E._time_summary(np.concatenate(all_t))}
    return {'source': str(src), 'methods': names, 'methods_unavailable': missing,
            'rows': sorted(rows) + (['overall'] if rows else []),
            'clips_per_row': {k: len(v) for k, v in rows.items()},
            'skipped': [{'file': p, 'reason': r} for p, r in skipped],
            'wall_s': time.time() - t_start, 'results': results}


def _fmt(v, nd=2):
    return 'n/a' if v is None or not np.isfinite(v) else f'{v:.{nd}f}'


def to_markdown(res: Dict) -> str:
    lines = ['## Real Kinect recordings (UI-PRMD) against the Vicon marker reference', '',
             f'Source: `{res["source"]}`. Methods: {", ".join(res["methods"]) or "none"}'
             + (f' (not available: {", ".join(res["methods_unavailable"])})'
                if res['methods_unavailable'] else '') + '.',
             'Reference: Plug-in-Gait joint-centre estimates, one rigid registration per subject '
             'session, or per rigid setup where a session\'s movements were recorded in several '
             '(Kabsch, no scaling), lag per clip. Hands excluded (not recorded). m03_s01: the '
             'tracking failure, reported apart. Latency = delay the method adds: peak shift of the '
             'velocity cross-correlation of its output with the reference minus the raw '
             'input\'s, on the joints the sensor reports TRACKED (sub-frame, negative = leads). '
             'Time = processing per frame (machine shared, '
             'loaded).', '']
    clip_info = ', '.join(f'{k}: {v}' for k, v in sorted(res['clips_per_row'].items()))
    lines += [f'Clips per row: {clip_info}.', '']
    order = [r for r in res['rows'] if r not in ('overall', 'm03_s01')] + \
        [r for r in ('overall', 'm03_s01') if r in res['rows']]
    # overall table: one line per method
    lines += ['### Overall (all movements with reference)', '',
              '| method | ' + ' | '.join(h for _, h in TABLE_METRICS)
              + ' | latency (ms) | time p50/p95 (ms) |',
              '|---' * (len(TABLE_METRICS) + 3) + '|']
    for m in res['methods']:
        r = res['results'][m].get('overall')
        if not r:
            continue
        vals = ' | '.join(_fmt(r['metrics'][k]['overall']) for k, _ in TABLE_METRICS)
        lines.append(f'| {m} | {vals} | {_fmt(r["latency_ms"], 1)} | '
                     f'{_fmt(r["time"]["p50_ms"])}/{_fmt(r["time"]["p95_ms"])} |')
    for key, head in (('eq18_cm', 'Eq. 18 error (cm)'), ('mpjpe_cm', 'MPJPE (cm)'),
                      ('bone_dir_deg', 'bone-direction error (deg)'),
                      ('bone_std_cm', 'bone-length std (cm)'), ('jitter_ms2', 'jitter (m/s^2)')):
        lines += ['', f'### {head} per movement', '',
                  '| row | ' + ' | '.join(res['methods']) + ' |',
                  '|---' * (len(res['methods']) + 1) + '|']
        for row in order:
            vals = []
            for m in res['methods']:
                r = res['results'][m].get(row)
                vals.append(_fmt(r['metrics'][key]['overall']) if r else 'n/a')
            lines.append(f'| {row} | ' + ' | '.join(vals) + ' |')
    lines += ['', '### Latency added (ms) per movement', '',
              '| row | ' + ' | '.join(res['methods']) + ' |',
              '|---' * (len(res['methods']) + 1) + '|']
    for row in order:
        vals = [_fmt(res['results'][m][row]['latency_ms'], 1) if row in res['results'][m]
                else 'n/a' for m in res['methods']]
        lines.append(f'| {row} | ' + ' | '.join(vals) + ' |')
    if res.get('skipped'):
        lines += ['', 'Skipped files:'] + [f'- {s["file"]}: {s["reason"]}' for s in res['skipped']]
    return '\n'.join(lines)


def write_outputs(res: Dict, out) -> str:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    md = to_markdown(res)
    (out / 'real_eval.md').write_text(md + '\n')
    (out / 'real_eval.json').write_text(json.dumps(json_safe(res), indent=1))
    return md


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='real_eval', description=__doc__.split('\n')[0])
    ap.add_argument('--src', default='../shared/kinect/ui-prmd')
    ap.add_argument('--out', default='out/real')
    ap.add_argument('--methods', default='', help='comma-separated (default: all available of '
                    + ', '.join(DEFAULT_METHODS) + ')')
    ap.add_argument('--max-clips', type=int, default=4,
                    help='clips per movement row, 0 = all [%(default)s]')
    ap.add_argument('--quiet', action='store_true')
    args = ap.parse_args(argv)
    if not Path(args.src).is_dir():
        print(f'real_eval: no UI-PRMD folder at {args.src}', file=sys.stderr)
        return 1
    methods = [m.strip() for m in args.methods.split(',') if m.strip()] or None
    prog = None if args.quiet else (lambda m, r, c: print(f'  {m:9s} {r:8s} {c}',
                                                          file=sys.stderr))
    res = evaluate_real(args.src, methods, max_clips=args.max_clips or None, progress=prog)
    print(write_outputs(res, args.out))
    return 0


if __name__ == '__main__':
    sys.exit(main())
