"""``build_correction``: learn a sensor correction from a lab's own pairs, with its
leave-one-subject-out report.

Input, per recording: a bag of the graph's input topic (``/kinect/skeletons``, any tracker; the
tracker is the one the bag declares on ``/kinect/tracker`` or ``--tracker``) plus a reference
from the lab's mocap (:mod:`skeleton_data.reference`: CSV joint positions, BVH or C3D / marker
text through a joint map), each on its own clock and in its own frame. Steps:

1. the tracker's skeletons are read from the bag (the user seen in most frames);
2. the clocks are aligned by cross-correlation and the reference is registered rigidly into
   the sensor frame, one transform per session (:mod:`skeleton_eval.pairing`); the offsets and
   residuals are reported;
3. the correction (:func:`pose_reconstruction.correction.fit`) is learned on every subject and
   saved for the tracker (default ``cache/sensor_correction_<tracker>.npz``: the file the
   reconstruction's ``sensor_correction:=auto`` picks for a stream of that tracker);
4. its own leave-one-subject-out report: for each subject, a correction learned on the others
   applied to that subject's tracker skeletons, raw against corrected (Eq. 18, MPJPE, bone
   direction), written beside the file (``<out>.report.md`` / ``.json``).

The UI-PRMD layout (``--src``) is one adapter: its clips are paired by
:func:`skeleton_eval.paired.load_dataset` (per-clip lag, one transform per setup) and go through
the same fit and report.

A manifest (``--pairs pairs.csv``) lists many recordings: columns ``bag``, ``reference``,
``subject`` and optionally ``session`` (one rigid registration per session; default the
subject), ``joint_map``, ``units`` (CSV references), ``offset_s`` (a known clock offset: skips
the search); relative paths are relative to the manifest.
"""
from __future__ import annotations

import csv
import json
import sys
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np

from skeleton_core.model import HAND_LEFT, HAND_RIGHT

from . import correction as C


def read_tracker_bag(path, topic: str = '/kinect/skeletons'):
    """(times s (T,), positions (T, 20, 3), declared tracker) of the user seen most in a bag."""
    from skeleton_core import tracker as T
    from skeleton_core.bagio import bag_topics, read_messages
    from skeleton_core.cdr import CdrError, frames_from_cdr
    topics = bag_topics(path)
    if topic not in topics:
        raise ValueError(f'{path}: no {topic} in the bag (topics: {", ".join(sorted(topics))})')
    per_user: Dict[int, list] = {}
    for m in read_messages(path, topics=[topic], decode=False):
        try:
            stamp, _, frames = frames_from_cdr(m.data)
        except CdrError:
            continue
        for f in frames:
            per_user.setdefault(f.user_id, []).append(((f.stamp_ns or stamp or m.stamp_ns) * 1e-9,
                                                       f.positions))
    if not per_user:
        raise ValueError(f'{path}: no skeleton on {topic}')
    rows = max(per_user.values(), key=len)
    t = np.array([r[0] for r in rows])
    order = np.argsort(t, kind='stable')
    t = t[order]
    keep = np.concatenate([[True], np.diff(t) > 0])
    pos = np.stack([rows[i][1] for i in order])[keep]
    return t[keep], pos, T.from_bag(path)


def loso_report(tracker_seqs: Sequence[np.ndarray], reference_seqs: Sequence[np.ndarray],
                groups: Sequence[str], tracker: str, posture: bool = True) -> Dict:
    """For each subject: a correction learned on the others (its ridge strength chosen among
    them), applied to that subject; raw and corrected Eq. 18 / MPJPE / bone direction against
    the reference (hands excluded: the trackers extrapolate them), per subject and overall
    (frame-weighted)."""
    from skeleton_eval.metrics import bone_direction_error, eq18_error, mpjpe
    labels = sorted(set(groups))
    if len(labels) < 2:
        return {'subjects': labels, 'note': 'one subject: no leave-one-subject-out report'}
    rows, tot = {}, {}
    for s in labels:
        tr = [i for i, g in enumerate(groups) if g != s]
        te = [i for i, g in enumerate(groups) if g == s]
        corr = C.fit([tracker_seqs[i] for i in tr], [reference_seqs[i] for i in tr], tracker,
                     groups=[groups[i] for i in tr], posture=posture)
        raw = np.concatenate([tracker_seqs[i] for i in te])
        ref = np.concatenate([reference_seqs[i] for i in te]).copy()
        ok = np.isfinite(ref[:, [j for j in range(ref.shape[1]) if j not in (HAND_LEFT,
                                                                              HAND_RIGHT)]]
                         ).all(axis=(1, 2))
        raw, ref = raw[ok], ref[ok]
        ref[:, [HAND_LEFT, HAND_RIGHT]] = np.nan
        fixed = corr.apply(raw)
        r = {'frames': int(len(raw)), 'ridge_alpha': corr.meta.get('ridge_alpha'),
             'trained_on': [g for g in labels if g != s]}
        for name, fn in (('eq18_cm', eq18_error), ('mpjpe_cm', mpjpe),
                         ('bone_dir_deg', bone_direction_error)):
            a, b = fn(raw, ref)[1], fn(fixed, ref)[1]
            r[f'raw_{name}'], r[f'corr_{name}'] = a, b
            tot.setdefault(name, [0.0, 0.0, 0])
            tot[name][0] += a * len(raw)
            tot[name][1] += b * len(raw)
            tot[name][2] += len(raw)
        rows[s] = r
    overall = {}
    for name, (a, b, n) in tot.items():
        overall[f'raw_{name}'] = a / n
        overall[f'corr_{name}'] = b / n
        overall[f'change_{name}_pct'] = 100.0 * (b - a) / a if a else float('nan')
    return {'subjects': labels, 'per_subject': rows, 'overall': overall, 'tracker': tracker}


def report_markdown(rep: Dict, extra: Optional[List[str]] = None) -> str:
    lines = [f"# Sensor correction for {rep.get('tracker', '?')}: leave-one-subject-out", '']
    lines += list(extra or [])
    if 'per_subject' not in rep:
        return '\n'.join(lines + [rep.get('note', '')]) + '\n'
    lines += ['', '| held out | frames | ridge alpha | Eq. 18 raw -> corr (cm) | MPJPE raw -> corr '
              '(cm) | bone dir raw -> corr (deg) |', '|---|---|---|---|---|---|']
    for s, r in rep['per_subject'].items():
        lines.append(f"| {s} | {r['frames']} | {r['ridge_alpha']} | {r['raw_eq18_cm']:.2f} -> "
                     f"{r['corr_eq18_cm']:.2f} | {r['raw_mpjpe_cm']:.2f} -> {r['corr_mpjpe_cm']:.2f}"
                     f" | {r['raw_bone_dir_deg']:.2f} -> {r['corr_bone_dir_deg']:.2f} |")
    o = rep['overall']
    lines.append(f"| overall | | | {o['raw_eq18_cm']:.2f} -> {o['corr_eq18_cm']:.2f} "
                 f"({o['change_eq18_cm_pct']:+.1f} %) | {o['raw_mpjpe_cm']:.2f} -> "
                 f"{o['corr_mpjpe_cm']:.2f} ({o['change_mpjpe_cm_pct']:+.1f} %) | "
                 f"{o['raw_bone_dir_deg']:.2f} -> {o['corr_bone_dir_deg']:.2f} "
                 f"({o['change_bone_dir_deg_pct']:+.1f} %) |")
    return '\n'.join(lines) + '\n'


def _write_report(path: Path, rep: Dict, extra: List[str]) -> Path:
    md = Path(str(path) + '.report.md')
    md.write_text(report_markdown(rep, extra))
    Path(str(path) + '.report.json').write_text(json.dumps(rep, indent=2, default=float))
    return md


def read_manifest(path) -> List[Dict]:
    path = Path(path)
    try:
        with open(path, newline='', encoding='utf-8') as f:
            rows = [r for r in csv.DictReader(f)]
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise ValueError(f'{path}: cannot read ({e})') from None
    out = []
    for k, r in enumerate(rows, 2):
        r = {a.strip(): (b or '').strip() for a, b in r.items() if a}
        for need in ('bag', 'reference', 'subject'):
            if not r.get(need):
                raise ValueError(f'{path}:{k}: column {need!r} is empty or missing')
        for key in ('bag', 'reference', 'joint_map'):
            if r.get(key) and not Path(r[key]).is_absolute():
                r[key] = str(path.parent / r[key])
        out.append(r)
    if not out:
        raise ValueError(f'{path}: no rows')
    return out


def load_pairs(rows: Sequence[Dict], topic: str = '/kinect/skeletons', log=None):
    """:class:`skeleton_eval.pairing.Pair` per manifest row, and the trackers the bags declare."""
    from skeleton_data.reference import load_reference
    from skeleton_eval.pairing import Pair
    from skeleton_core.bagio import BagError
    pairs, trackers = [], []
    for r in rows:
        try:
            t, pos, tracker = read_tracker_bag(r['bag'], topic)
            ref = load_reference(r['reference'], r.get('joint_map') or None,
                                 r.get('units') or 'm')
        except (BagError, ValueError, OSError) as e:   # one bad pair: skipped, said, the rest go on
            if log is not None:
                log(f'skipped {Path(r["bag"]).name}: {e}')
            continue
        p = Pair(name=Path(r['bag']).stem, subject=r['subject'], tracker_times=t, tracker=pos,
                 ref_times=ref.times, ref=ref.positions, session=r.get('session', ''))
        if r.get('offset_s'):
            p.offset_s, p.offset_score = float(r['offset_s']), float('nan')
        pairs.append(p)
        trackers.append(tracker)
    return pairs, trackers


def build_from_pairs(pairs, tracker: str, out=None, posture: bool = True, meta=None, log=None):
    """Align, register, fit on every subject, save, report; (correction, path, report)."""
    from skeleton_eval.pairing import register
    log = log or (lambda m: None)
    fits = register(pairs)
    lines = ['Clock offsets (cross-correlation) and registration residuals:', '',
             '| recording | subject | session | offset (s) | xcorr peak | residual (cm) |',
             '|---|---|---|---|---|---|']
    for p in pairs:
        lines.append(f'| {p.name} | {p.subject} | {p.session or p.subject} | {p.offset_s:.3f} | '
                     f'{p.offset_score:.3f} | {100 * p.residual_m:.1f} |')
        log(f'{p.name}: clock offset {p.offset_s:.3f} s (xcorr peak {p.offset_score:.2f}), '
            f'registration residual {100 * p.residual_m:.1f} cm')
    K = [p.tracker for p in pairs]
    R = [p.reference for p in pairs]
    G = [p.subject for p in pairs]
    corr = C.fit(K, R, tracker, groups=G, posture=posture,
                 meta={'subjects': sorted(set(G)), 'clips': len(pairs),
                       'source': 'pairs', 'sessions': {k: v.pairs for k, v in fits.items()},
                       **(meta or {})})
    path = corr.save(out if out is not None else C.default_path(tracker))
    rep = loso_report(K, R, G, tracker, posture)
    rep['offsets_s'] = {p.name: p.offset_s for p in pairs}
    md = _write_report(path, rep, lines)
    return corr, path, rep, md


def build_uiprmd(src, out=None, subjects=None, posture: bool = True):
    """The UI-PRMD adapter: its clips, paired its own way, through the same fit and report."""
    from skeleton_eval.paired import load_dataset
    src = Path(src)
    clips, skipped, _ = load_dataset(src, subjects=subjects)
    K, R, G, N = C.paired_sequences(clips, subjects)
    if not K:
        raise ValueError('no clip with a registered marker reference to learn from')
    corr = C.fit(K, R, C.UIPRMD_TRACKER, groups=G, posture=posture,
                 meta={'subjects': sorted(set(G)), 'clips': len(N), 'source': str(src.resolve()),
                       'source_digest': C._source_digest(src), 'skipped_files': len(skipped)})
    path = corr.save(out if out is not None else C.default_path(corr.tracker))
    rep = loso_report(K, R, G, C.UIPRMD_TRACKER, posture)
    md = _write_report(path, rep, [f'UI-PRMD layout {src}: {len(N)} clips (per-clip lag, one '
                                   f'transform per setup: skeleton_eval.paired).'])
    return corr, path, rep, md


def main(argv=None) -> int:
    """``build_correction``: learn a sensor correction from paired recordings into a file."""
    import argparse
    from skeleton_core.tracker import TRACKERS
    ap = argparse.ArgumentParser(prog='build_correction', description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--src', default=None, help='paired recordings in the UI-PRMD layout '
                    '(Kinect/Positions, Kinect/Angles, Vicon/Positions; the default when no '
                    'pairs are given: <shared>/kinect/ui-prmd)')
    ap.add_argument('--pairs', default=None, help='manifest CSV: bag, reference, subject '
                    '[, session, joint_map, units, offset_s]')
    ap.add_argument('--bag', action='append', default=[], help='a recording of the input topic '
                    '(repeat; with --reference and --subject in the same order)')
    ap.add_argument('--reference', action='append', default=[], help='its mocap reference '
                    '(.csv joint positions, .bvh, .c3d or marker text with --joint-map)')
    ap.add_argument('--subject', action='append', default=[], help='its subject')
    ap.add_argument('--joint-map', default='', help='joint map for BVH / C3D / marker references')
    ap.add_argument('--units', default='m', choices=('m', 'cm', 'mm'),
                    help='units of CSV references (default m)')
    ap.add_argument('--tracker', default='', choices=('',) + TRACKERS,
                    help="the bags' skeleton tracker (default: the one they declare)")
    ap.add_argument('--topic', default='/kinect/skeletons')
    ap.add_argument('--out', default=None, help='output file (default '
                    'cache/sensor_correction_<tracker>.npz)')
    ap.add_argument('--subjects', default='', help='UI-PRMD: comma-separated subject numbers')
    ap.add_argument('--offset-only', action='store_true',
                    help='posture-independent per-joint offset only')
    args = ap.parse_args(argv)

    def fail(msg, code=1):
        print(f'build_correction: {msg}', file=sys.stderr)
        return code

    try:
        if args.pairs or args.bag:
            if args.pairs:
                rows = read_manifest(args.pairs)
            else:
                if not (len(args.bag) == len(args.reference) == len(args.subject)):
                    return fail('give one --reference and one --subject per --bag', 2)
                rows = [{'bag': b, 'reference': r, 'subject': s, 'joint_map': args.joint_map,
                         'units': args.units} for b, r, s in zip(args.bag, args.reference,
                                                                  args.subject)]
            for r in rows:
                r.setdefault('joint_map', args.joint_map)
                r['units'] = r.get('units') or args.units
            pairs, declared = load_pairs(
                rows, args.topic, log=lambda m: print(f'build_correction: warning: {m}',
                                                      file=sys.stderr))
            if not pairs:
                return fail('no usable pair')
            found = sorted({t for t in declared if t})
            tracker = args.tracker
            if not tracker:
                if len(found) != 1 or not all(declared):
                    return fail('the bags declare tracker(s) '
                                f'{", ".join(found) or "none"} (on /kinect/tracker); name the '
                                'one they come from with --tracker', 2)
                tracker = found[0]
            elif found and found != [tracker]:
                print(f'build_correction: warning: --tracker {tracker} overrides the bags\' '
                      f'{", ".join(found)}', file=sys.stderr)
            corr, path, rep, md = build_from_pairs(
                pairs, tracker, args.out, posture=not args.offset_only,
                log=lambda m: print(f'  {m}'))
        else:
            src = Path(args.src) if args.src else C.default_source()
            if src is None or not src.is_dir():
                return fail(f'no paired recordings at {args.src or "<shared>/kinect/ui-prmd"} '
                            '(give --src DIR, --pairs CSV or --bag/--reference/--subject)')
            try:
                subjects = [int(s.strip().lstrip('s')) for s in args.subjects.split(',')
                            if s.strip()]
            except ValueError:
                return fail(f'bad --subjects {args.subjects!r}', 2)
            corr, path, rep, md = build_uiprmd(src, args.out, subjects or None,
                                               posture=not args.offset_only)
    except (FileNotFoundError, ValueError) as e:
        return fail(str(e))
    m = corr.meta
    print(f'{path}: {corr.describe()}; {m["clips"]} recordings, ridge alpha {m["ridge_alpha"]} '
          f'(chosen by leave-one-subject-out on the training subjects)')
    o = rep.get('overall')
    if o:
        print(f"  leave-one-subject-out ({', '.join(rep['subjects'])}): Eq. 18 "
              f"{o['raw_eq18_cm']:.2f} -> {o['corr_eq18_cm']:.2f} cm "
              f"({o['change_eq18_cm_pct']:+.1f} %), MPJPE {o['raw_mpjpe_cm']:.2f} -> "
              f"{o['corr_mpjpe_cm']:.2f} cm ({o['change_mpjpe_cm_pct']:+.1f} %), bone direction "
              f"{o['raw_bone_dir_deg']:.2f} -> {o['corr_bone_dir_deg']:.2f} deg "
              f"({o['change_bone_dir_deg_pct']:+.1f} %)")
    print(f'  report: {md}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
