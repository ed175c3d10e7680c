"""Real-data accuracy with the learned sensor correction and user profiles, honestly scored.

``evaluate --real --loso`` (default folder ``<shared>/kinect/ui-prmd``): leave-one-subject-out
over the development subjects. For each held-out subject the sensor correction is learned from
the *other* subjects' paired recordings (its one free number, the ridge strength, chosen by
leave-one-subject-out among those training subjects only), and every figure of that subject is
computed with it; no figure comes from a subject the correction was trained on, and nothing is
tuned on the scored fold. ``evaluate --real DIR`` on a folder of other subjects (same layout)
scores them with the correction learned from all development subjects (the default file), the
check a lab runs on its own people; a subject of DIR that is also a training subject of that
correction (same folder) is refused.

Rows of the table (``VARIANTS``):

* ``raw``, ``holt``, ``one_euro``, ``C`` — as in ``evaluate --real``;
* ``raw+corr`` — the Kinect skeleton with the correction only;
* ``C+corr`` — method C with the correction inside the reconstruction (stage ``input``: before
  the reliability); ``C+corr@reliable`` — the same at stage ``reliable`` (on the reliable joints,
  after the reliability);
* ``C+profile``, ``C+corr+profile`` — with the user's profile (segment lengths), for each clip
  measured on the same subject's *other* clips (never the clip scored; tracking-failure clips
  not used), after the correction for the ``+corr`` row;
* ``C+labdb``, ``C+corr+labdb`` — ``C`` / ``C+corr`` with the motion database of the default
  (CMU) clips plus the training subjects' Vicon postures, imported through the Plug-in-Gait joint
  map and filtered like the database (:func:`lab_database`, built once per fold into ``cache/``):
  a lab that records its exercises once.

Rows per movement, ``overall`` (all movements with a reference, m03_s01 excluded) and
``m03_s01`` apart (the real tracking failure). Per-clip results are cached in
``cache/real_eval/`` (keyed by the code, the correction and the settings).
"""
from __future__ import annotations

import hashlib
import json
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np
import pose_reconstruction
import skeleton_core
import skeleton_data
import skeleton_eval
from skeleton_core.model import SEGMENT_CHILDREN, SEGMENT_PARENTS
from pose_reconstruction.profile import measure
from skeleton_data.uiprmd import TRACKING_FAILURE_CASES
from .mocap_db_eval import fold_database
from skeleton_eval import evaluation as E
from skeleton_eval.registry import load_plugins, make_method
from skeleton_eval import metrics as M
from skeleton_eval import no_harm as NH
from skeleton_eval.registration import apply_transform, kabsch
from skeleton_eval.real_eval import added_latency_ms, tracked_xcorr
from skeleton_eval.report import json_safe
from pose_reconstruction.correction import build_from_clips, digest
from pose_reconstruction.methods import default_database, load_preset
from kinect_bringup.graph import preset_path
from skeleton_eval.real_eval import make_streams
from skeleton_eval.sensor_params import load_params
from skeleton_eval.paired import load_dataset
from skeleton_eval.real_eval import to_markdown as base
import argparse
from pose_reconstruction import correction as C
from skeleton_data.database import default_cache_dir

VARIANTS = ('raw', 'holt', 'one_euro', 'C', 'raw+corr', 'C+corr', 'C+corr@reliable',
            'C+profile', 'C+corr+profile', 'C+labdb', 'C+corr+labdb')
DEFAULT_VARIANTS = ('raw', 'holt', 'one_euro', 'C', 'raw+corr', 'C+corr', 'C+corr+profile')
TRACKER = 'kinect_v2_sdk'


def _subject(name: str) -> int:
    return int(name.split('_')[1][1:])


def _code_digest() -> str:
    h = hashlib.sha256()
    for pkg in (pose_reconstruction, skeleton_core, skeleton_data, skeleton_eval):
        for f in sorted(Path(pkg.__file__).parent.glob('*.py')):
            h.update(f.read_bytes())
    h.update(Path(__file__).read_bytes())
    return h.hexdigest()[:16]


class _Corrected:
    """``raw+corr``: the tracker skeleton with the correction only."""

    name = 'raw+corr'

    def __init__(self, correction):
        self.correction = correction

    def reset(self):
        pass

    def process(self, frame):
        return frame.copy(positions=self.correction.apply(frame.positions))


def _segment_lengths(pos: np.ndarray) -> np.ndarray:
    return np.linalg.norm(pos[:, list(SEGMENT_CHILDREN)] - pos[:, list(SEGMENT_PARENTS)], axis=-1)


def profiles_leave_clip_out(streams: Sequence, correction=None,
                            scored: Optional[Sequence[str]] = None) -> Dict[str, np.ndarray]:
    """{clip: (19,) profile lengths from the same subject's other clips} (median over their
    frames, left/right averaged), after ``correction`` when given; tracking-failure clips are
    scored with a profile but do not contribute to one. ``scored``: only these clips get one."""
    fail = {f'{m}_{s}' for m, s in TRACKING_FAILURE_CASES}
    by_subject: Dict[int, List] = {}
    for s in streams:
        by_subject.setdefault(_subject(s.clip_name), []).append(s)
    out = {}
    for subj, lst in by_subject.items():
        pos = {s.clip_name: (s.positions if correction is None else correction.apply(s.positions))
               for s in lst}
        for s in lst:
            if scored is not None and s.clip_name not in scored:
                continue
            others = [pos[o.clip_name] for o in lst
                      if o.clip_name != s.clip_name and o.clip_name[:7] not in fail]
            if others:
                out[s.clip_name] = measure(others, f's{subj:02d}').segment_lengths
    return out


def training_clips(clips, held_out: int) -> list:
    """The clips a fold that scores subject ``held_out`` may learn from: every other subject's
    clips with a registered reference (never one of the held-out subject)."""
    return [c for c in clips if c.clip.subject != held_out and c.reference is not None]


def lab_database(src, held_out: int, clips):
    """The default database plus the Vicon postures of the training subjects of ``clips`` (those
    with a reference, never ``held_out``), through ``config/joint_maps/plug_in_gait.yaml``
    (:func:`kinect_experiments.mocap_db_eval.fold_database`; cached in ``cache/``)."""
    train = sorted({c.clip.subject for c in training_clips(clips, held_out)})
    return fold_database(src, held_out, subjects=train)


def _make(variant: str, correction, db, method_params: Optional[Dict] = None):
    if variant == 'raw+corr':
        return _Corrected(correction)
    base = variant.split('+')[0]
    if base != 'C':
        return make_method(base)
    kw = {}
    if '+corr' in variant:
        kw.update(correction=correction, input_tracker=TRACKER,
                  correction_stage='reliable' if variant.endswith('@reliable') else 'input')
    return make_method('C', db=db, **kw, **(method_params or {}))


def session_registered_mpjpe(outputs: Dict[str, np.ndarray], truths: Dict[str, np.ndarray],
                             setup_of: Dict[str, str]) -> Dict[str, Dict]:
    """MPJPE (cm) after one rigid registration per recording setup *of this output*: the
    reference is placed, per setup, where it best fits the method's own output (Kabsch over all
    frames and joints of the setup's clips), so no method is scored in a frame fitted to another
    (the reference of :func:`skeleton_eval.paired.load_dataset` is registered to the raw Kinect,
    which favours raw). {clip: {'per_joint', 'overall'}}."""
    by_setup: Dict[str, List[str]] = {}
    for name in outputs:
        by_setup.setdefault(setup_of.get(name, name), []).append(name)
    res = {}
    for names in by_setup.values():
        try:
            r, t = kabsch(np.concatenate([truths[n] for n in names]),
                          np.concatenate([outputs[n] for n in names]))
        except ValueError:
            continue
        for n in names:
            per, tot = M.mpjpe(outputs[n], apply_transform(r, t, truths[n]))
            res[n] = {'per_joint': [float(v) for v in per], 'overall': tot}
    return res


def run_variant(variant: str, streams: Sequence, correction=None, profiles=None, db=None,
                progress=None, setup_of: Optional[Dict[str, str]] = None,
                method_params: Optional[Dict] = None) -> Dict[str, Dict]:
    """{clip: {'metrics', 'latency_ms', 'times', 'frames'}} of one variant on some streams;
    the metrics include ``mpjpe_reg_cm`` (:func:`session_registered_mpjpe`)."""
    method = _make(variant, correction, db, method_params)
    out = {}
    outputs, truths = {}, {}
    for s in streams:
        if profiles is not None:
            if s.clip_name not in profiles:
                continue
            method.set_profile(profiles[s.clip_name])
        pos, t = E.run_method(method, s)
        outputs[s.clip_name], truths[s.clip_name] = pos, s.truth
        out[s.clip_name] = {'metrics': M.compute_all(pos, s.truth, s.fps),
                            'latency_one_sided_ms': added_latency_ms(pos, s.positions, s.fps),
                            'xcorr': tracked_xcorr(pos, s).tolist(),
                            'xcorr_raw': tracked_xcorr(s.positions, s).tolist(),
                            'no_harm': NH.add(NH.empty(), *NH.direction_sums(
                                pos, s.truth, NH.segment_mask(s.tracking_state))),
                            'times': t.tolist(), 'frames': len(s)}
        if progress:
            progress(variant, s.clip_name)
    nan = {'per_joint': [float('nan')] * len(out[next(iter(out))]['metrics']['mpjpe_cm']
                                             ['per_joint']), 'overall': float('nan')} \
        if out else None
    reg = session_registered_mpjpe(outputs, truths, setup_of or {})
    for name, r in out.items():
        r['metrics']['mpjpe_reg_cm'] = reg.get(name, nan)
    return out


def added_xcorr_latency(clip_results: Sequence[Dict]) -> float:
    """The latency (ms) a variant adds over some clips: the peak of its velocity
    cross-correlation with the marker reference (TRACKED joints, curves of the clips added)
    minus the raw Kinect's own (:func:`skeleton_eval.real_eval.tracked_xcorr`); resolves less
    than a frame, negative when the output leads the raw input."""
    xc = sum(np.asarray(r['xcorr'], float) for r in clip_results)
    xr = sum(np.asarray(r['xcorr_raw'], float) for r in clip_results)
    return M.xcorr_latency_ms(xc) - M.xcorr_latency_ms(xr)


def _cached(cache: Optional[Path], key: Dict, compute):
    if cache is None:
        return compute()
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:20]
    f = cache / f'{key["variant"].replace("@", "_").replace("+", "_")}_{digest}.json'
    if f.is_file():
        try:
            return json.loads(f.read_text())
        except ValueError:
            pass
    res = compute()
    cache.mkdir(parents=True, exist_ok=True)
    f.write_text(json.dumps(json_safe(res)))
    return res


def _nan(d):
    """JSON null -> NaN in a cached per-clip metric dict."""
    return {k: {'per_joint': [np.nan if v is None else v for v in m['per_joint']],
                'overall': np.nan if m['overall'] is None else m['overall']}
            for k, m in d.items()}


def evaluate(src, variants: Sequence[str] = DEFAULT_VARIANTS, loso: bool = True,
             correction=None, subjects=None, movements=None, max_clips: Optional[int] = None,
             cache: Optional[Path] = None, progress=None,
             method_params: Optional[Dict] = None) -> Dict:
    """Score ``variants`` on the clips under ``src`` (module docstring). ``loso``: corrections
    learned per held-out subject from the other subjects of ``src``; else ``correction`` (learned
    elsewhere) for every clip. Returns a dict :func:`skeleton_eval.real_eval.to_markdown` prints,
    plus ``protocol``, ``folds`` and ``correction_ms``. ``method_params``: parameter overrides of
    method C in the ``C...`` variants (e.g. earlier defaults, for a before/after table)."""
    t_start = time.time()
    load_plugins()
    bad = [v for v in variants if v not in VARIANTS]
    if bad:
        raise ValueError(f'unknown variant(s) {bad}; known: {", ".join(VARIANTS)}')
    height = float(load_params(None)['placement']['sensor_height_m'])
    # every clip is loaded (a fold's correction learns from all of the other subjects' clips);
    # subjects / movements / max_clips only select the clips scored
    clips, skipped, _ = load_dataset(src, sensor_height=height)
    rows = make_streams([c for c in clips
                         if (not subjects or c.clip.subject in subjects)
                         and (not movements or c.clip.movement in movements)])
    if max_clips:
        for k, lst in rows.items():
            if len(lst) > max_clips:
                idx = np.linspace(0, len(lst) - 1, max_clips).round().astype(int)
                rows[k] = [lst[i] for i in sorted(set(idx))]
    row_of = {s.clip_name: r for r, lst in rows.items() for s in lst}
    every = [s for lst in make_streams(clips).values() for s in lst]  # profiles: all clips
    setup_of = {c.clip.name: c.setup or c.clip.session for c in clips}
    streams = [s for lst in rows.values() for s in lst]
    test_subjects = sorted({_subject(s.clip_name) for s in streams})
    code = _code_digest()
    db = default_database() if any(v.startswith('C') for v in variants) else None
    folds = []
    per_clip: Dict[str, Dict[str, Dict]] = {v: {} for v in variants}
    corr_ms: List[float] = []
    needs_corr = any('corr' in v for v in variants)
    src_res = str(Path(src).resolve())
    for subj in test_subjects:
        fold_streams = [s for s in streams if _subject(s.clip_name) == subj]
        corr = None
        if needs_corr:
            if loso:
                corr = build_from_clips(training_clips(clips, subj))
                if f's{subj:02d}' in corr.meta['subjects']:  # cannot happen; never report it
                    raise RuntimeError(f'fold s{subj:02d} trained on its own subject')
            else:
                corr = correction
                if corr is None:
                    raise ValueError('no sensor correction to score (build one: '
                                     'make build-correction)')
                if (corr.meta.get('source') == src_res
                        and f's{subj:02d}' in corr.meta.get('subjects', [])):
                    raise ValueError(f'subject s{subj:02d} of {src} was a training subject of '
                                     'the correction: use --loso for an honest figure')
            # the correction's own cost per frame (all frames of the fold, one at a time)
            frames = np.concatenate([s.positions for s in fold_streams])[:600]
            t0 = time.perf_counter()
            for f in frames:
                corr.apply(f)
            corr_ms.append((time.perf_counter() - t0) * 1e3 / max(len(frames), 1))
        folds.append({'held_out': f's{subj:02d}', 'clips': len(fold_streams),
                      'trained_on': None if corr is None else corr.meta.get('subjects'),
                      'ridge_alpha': None if corr is None else corr.meta.get('ridge_alpha')})
        cdig = None if corr is None else digest(corr)
        for v in variants:
            prof = None
            if v.endswith('profile'):
                prof = profiles_leave_clip_out(
                    [s for s in every if _subject(s.clip_name) == subj],
                    corr if '+corr' in v else None, [s.clip_name for s in fold_streams])
            key = {'variant': v, 'code': code, 'correction': cdig if 'corr' in v else None,
                   'clips': [s.clip_name for s in fold_streams], 'src': src_res,
                   'height': height}
            if method_params and v.startswith('C'):
                key['method_params'] = method_params
            vdb = db
            if v.endswith('labdb'):
                vdb = lab_database(src, subj, clips)
                key['database'] = vdb.meta.get('cache_key')
            res = _cached(cache, key, lambda v=v, prof=prof, corr=corr, fs=fold_streams, vdb=vdb:
                          run_variant(v, fs, corr, prof, vdb, progress, setup_of,
                                      method_params if v.startswith('C') else None))
            per_clip[v].update(res)
    # tables in real_eval's format
    results: Dict[str, Dict] = {}
    for v in variants:
        results[v] = {}
        acc: Dict[str, List] = {}
        for name, r in per_clip[v].items():
            acc.setdefault(row_of[name], []).append(r)
        allp, allw, alll, allt = [], [], [], []
        for row in sorted(acc):
            lst = acc[row]
            parts = [_nan(r['metrics']) for r in lst]
            w = [r['frames'] for r in lst]
            lat = added_xcorr_latency(lst)
            t = np.concatenate([np.asarray(r['times'], float) for r in lst])
            results[v][row] = {'clips': len(lst), 'frames': int(sum(w)),
                               'metrics': E._combine(parts, w),
                               'no_harm': NH.merge([r.get('no_harm') for r in lst]),
                               'latency_ms': lat, 'time': E._time_summary(t)}
            if row != 'm03_s01':
                allp += parts
                allw += w
                alll += lst
                allt.append(t)
        if allp:
            results[v]['overall'] = {'clips': len(allp), 'frames': int(sum(allw)),
                                     'metrics': E._combine(allp, allw),
                                     'no_harm': NH.merge([r.get('no_harm') for r in alll]),
                                     'latency_ms': added_xcorr_latency(alll),
                                     'time': E._time_summary(np.concatenate(allt))}
    protocol = ('leave-one-subject-out: each subject scored with a correction learned on the '
                'other subjects only' if loso else
                'correction learned elsewhere (' + ', '.join(correction.meta.get('subjects', []))
                + ') applied to these subjects')
    return {'source': str(src), 'methods': list(variants), 'methods_unavailable': [],
            'rows': sorted(rows) + (['overall'] if rows else []),
            'clips_per_row': {k: len(v) for k, v in rows.items()},
            'skipped': [{'file': p, 'reason': r} for p, r in skipped],
            'wall_s': time.time() - t_start, 'results': results, 'protocol': protocol,
            'loso': bool(loso),
            'folds': folds, 'correction_ms_per_frame': float(np.mean(corr_ms)) if corr_ms else None}


def _pct(a, b):
    return 'n/a' if not (np.isfinite(a) and np.isfinite(b) and b) else f'{100 * (a - b) / b:+.1f} %'


def summary(res: Dict) -> str:
    """The real-data targets against raw (overall, per movement)."""
    R = res['results']
    if 'raw' not in R:
        return ''
    lines = ['### Against raw (overall; negative = better)', '',
             '| row | Eq. 18 | MPJPE | MPJPE, own registration | bone dir | bone-length std | '
             'movements better than raw (Eq. 18) | latency (ms) |',
             '|---|---|---|---|---|---|---|---|']
    movs = [r for r in res['rows'] if r not in ('overall', 'm03_s01')]
    for v in res['methods']:
        if v == 'raw' or 'overall' not in R[v]:
            continue
        o, b = R[v]['overall']['metrics'], R['raw']['overall']['metrics']
        better = sum(R[v][m]['metrics']['eq18_cm']['overall']
                     < R['raw'][m]['metrics']['eq18_cm']['overall'] for m in movs if m in R[v])
        lines.append(f'| {v} | ' + ' | '.join(_pct(o[k]['overall'], b[k]['overall']) for k in
                                              ('eq18_cm', 'mpjpe_cm', 'mpjpe_reg_cm',
                                               'bone_dir_deg', 'bone_std_cm'))
                     + f' | {better}/{len(movs)} | {R[v]["overall"]["latency_ms"]:.1f} |')
    return '\n'.join(lines)


def to_markdown(res: Dict) -> str:
    head = [f'Protocol: {res["protocol"]}.']
    for f in res['folds']:
        if f['trained_on']:
            head.append(f'- {"held out" if res.get("loso") else "scored"} {f["held_out"]} '
                        f'({f["clips"]} clips): correction trained on '
                        f'{", ".join(f["trained_on"])}, ridge alpha {f["ridge_alpha"]}')
    if res.get('correction_ms_per_frame') is not None:
        head.append(f'- correction cost: {res["correction_ms_per_frame"]:.3f} ms per frame and '
                    f'user (mean, one frame at a time)')
    lines = ['', '### MPJPE (cm) after one rigid registration per setup of each output', '',
             '| row | ' + ' | '.join(res['methods']) + ' |',
             '|---' * (len(res['methods']) + 1) + '|']
    order = [r for r in res['rows'] if r not in ('overall', 'm03_s01')] + \
        [r for r in ('overall', 'm03_s01') if r in res['rows']]
    for row in order:
        vals = []
        for m in res['methods']:
            r = res['results'][m].get(row)
            v = r['metrics'].get('mpjpe_reg_cm', {}).get('overall') if r else None
            vals.append('n/a' if v is None or not np.isfinite(v) else f'{v:.2f}')
        lines.append(f'| {row} | ' + ' | '.join(vals) + ' |')
    return ('\n'.join(head) + '\n\n' + summary(res) + '\n\n' + base(res) + '\n'
            + '\n'.join(lines) + '\n\n' + no_harm_markdown(res))


NO_HARM_PAIRS = (('C', 'raw'), ('C+corr', 'raw+corr'), ('C+corr+profile', 'raw+corr'))


def no_harm_markdown(res: Dict) -> str:
    """The per-segment "no harm" table (skeleton_eval.no_harm) on the TRACKED segments of the
    recordings, overall: C against raw and C + correction against raw + correction."""
    R = res['results']
    per = {}
    for m, ref in NO_HARM_PAIRS:
        a = R.get(m, {}).get('overall', {}).get('no_harm')
        b = R.get(ref, {}).get('overall', {}).get('no_harm')
        if a and b:
            per[f'{m} vs {ref}'] = {'method': a, 'reference': b}
    if not per:
        return ''
    return NH.to_markdown(per, 'method', 'reference', title='### No harm: per segment on the '
                          'TRACKED segments (overall, m03_s01 apart); columns: method vs reference')


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='real_loso', description=__doc__.split('\n\n')[0])
    ap.add_argument('--src', default=None, help='UI-PRMD-layout folder (default '
                    '<shared>/kinect/ui-prmd)')
    ap.add_argument('--out', default='out/real_loso')
    ap.add_argument('--variants', default=','.join(DEFAULT_VARIANTS),
                    help=f'comma-separated, of {", ".join(VARIANTS)}')
    ap.add_argument('--no-loso', action='store_true',
                    help='use the default correction (all development subjects) for every clip')
    ap.add_argument('--correction', default='', help='--no-loso: correction file (default: the '
                    'one built from <shared>)')
    ap.add_argument('--subjects', default='', help='comma-separated subject numbers')
    ap.add_argument('--movements', default='', help='comma-separated movement numbers')
    ap.add_argument('--max-clips', type=int, default=0, help='clips per movement row, 0 = all')
    ap.add_argument('--method-params', default='',
                    help='JSON parameter overrides of method C in the C variants, e.g. '
                    '\'{"position_fit": 0}\'')
    ap.add_argument('--preset', default='', metavar='NAME',
                    help='reconstruction preset of method C in the C variants '
                    '(config/presets/NAME.yaml or a path, e.g. shum2013); --method-params on top')
    ap.add_argument('--no-cache', action='store_true')
    ap.add_argument('--quiet', action='store_true')
    args = ap.parse_args(argv)
    src = Path(args.src) if args.src else C.default_source()
    if src is None or not Path(src).is_dir():
        print(f'real_loso: no UI-PRMD folder at {args.src or "<shared>/kinect/ui-prmd"}',
              file=sys.stderr)
        return 1
    def ints(text):
        return [int(x.strip().lstrip('sm')) for x in text.split(',') if x.strip()] or None
    corr = None
    try:
        variants = [v.strip() for v in args.variants.split(',') if v.strip()]
        if args.no_loso:
            corr = C.load(args.correction) if args.correction else C.load_or_build_default(
                log=lambda m: print(f'[real_loso] {m}', file=sys.stderr))
            if corr is None:
                dropped = [v for v in variants if 'corr' in v]
                variants = [v for v in variants if 'corr' not in v]
                print(f'[real_loso] no sensor correction (no paired recordings under '
                      f'<shared>/kinect/ui-prmd and no {C.default_path()}): '
                      f'{", ".join(dropped)} not scored', file=sys.stderr)
            else:
                print(f'[real_loso] {C.describe_file(corr)}', file=sys.stderr)
        over = json.loads(args.method_params) if args.method_params else None
        if over is not None and not isinstance(over, dict):
            raise ValueError('--method-params: a JSON object of C parameters')
        if args.preset:
            over = {**load_preset(preset_path(args.preset)), **(over or {})}
        prog = None if args.quiet else (lambda v, c: print(f'  {v:15s} {c}', file=sys.stderr))
        res = evaluate(src, variants,
                       loso=not args.no_loso, correction=corr, subjects=ints(args.subjects),
                       movements=ints(args.movements), max_clips=args.max_clips or None,
                       cache=None if args.no_cache else default_cache_dir() / 'real_eval',
                       progress=prog, method_params=over)
    except (ValueError, FileNotFoundError) as e:
        print(f'real_loso: {e}', file=sys.stderr)
        return 1
    md = to_markdown(res)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / 'real_loso.md').write_text(md + '\n')
    (out / 'real_loso.json').write_text(json.dumps(json_safe(res), indent=1))
    print(md)
    print(f'[real_loso] {res["wall_s"]:.0f} s; wrote {out}/real_loso.md', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
