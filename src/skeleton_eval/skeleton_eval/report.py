"""Results of the evaluation (:mod:`.evaluation`, :mod:`.table3`, :mod:`.figures`) as JSON and
Markdown tables."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Dict, List

import numpy as np

from . import no_harm as NH
from skeleton_core.model import JOINT_NAMES, NUM_JOINTS, SEGMENT_CHILDREN, SEGMENT_PARENTS
from .sensor_statistics import format_statistics


def json_safe(o):
    """``o`` with numpy numbers and arrays as Python ones and non-finite numbers as None (JSON)."""
    if isinstance(o, dict):
        return {str(k): json_safe(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [json_safe(v) for v in o]
    if isinstance(o, (np.floating, float)):
        return None if not np.isfinite(o) else float(o)
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.ndarray):
        return json_safe(o.tolist())
    return o


def calibration_text(results: Dict) -> str:
    """One line naming a Table III result's protocol (results without the key: 'none')."""
    cal = results.get('calibration') or {'pose': 'none'}
    if cal.get('pose', 'none') == 'none':
        return ('calibration: none (no calibration; the other joints are hidden from the first '
                'frame, so the user\'s segment lengths are never observed)')
    what = 'a T-pose' if cal['pose'] == 'tpose' else 'a standing pose, arms down'
    return (f'calibration: {cal["pose"]} (before each clip, {cal["seconds"]:g} s = '
            f'{cal["frames"]} frames of the same user in {what} with every joint tracked, '
            f'reliability 1, not scored)')


def to_json(results: Dict, path=None) -> str:
    text = json.dumps(json_safe(results), indent=1)
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(text)
    return text


def _fmt(v, nd=2):
    return 'n/a' if v is None or not np.isfinite(v) else f'{v:.{nd}f}'


def _meta_lines(meta: Dict) -> List[str]:
    if not meta:
        return []
    clips = meta['data']['clips']
    frames = sum(min(c['frames'], 10 ** 9) for c in clips)
    sp = meta.get('sensor_params', {})
    pl = sp.get('placement', {})
    return [f'- data: {meta["data"]["source"]}; {len(clips)} clips ({frames} frames at source '
            f'rate), max {meta.get("max_frames_per_clip")} frames per clip at 30 Hz, each run '
            f'{meta.get("repeats", 1)}x with independent sensor noise/events',
            f'- clips: {", ".join(c["name"] for c in clips)}',
            f'- seed {meta["seed"]}; sensor model: distance {pl.get("distance_m")} m, sensor height '
            f'{pl.get("sensor_height_m")} m (full parameters in the JSON)',
            f'- {meta["machine"]}; {meta["date_utc"]} UTC']


def no_harm_lines(res: Dict, method: str = 'C', reference: str = 'raw') -> List[str]:
    """The per-segment "no harm" table (:mod:`.no_harm`) of a table4 result, when it holds
    ``method`` and ``reference``."""
    if method not in res or reference not in res:
        return []
    per = {k: {method: res[method][k].get('no_harm'), reference: res[reference][k].get('no_harm')}
           for k in res[method] if k in res[reference]}
    per = {k: v for k, v in per.items() if all(v.values())}
    md = NH.to_markdown(per, method, reference)
    return [md] if md else []


GAIN_METRICS = (('eq18_cm', 'Eq. 18'), ('bone_dir_deg', 'bone direction'),
                ('mpjpe_rel_cm', 'root-relative MPJPE'))


def gain_lines(res: Dict, reference: str = 'raw') -> List[str]:
    """Per class, each method's gain over ``reference`` (%, positive = below it) in Eq. 18, the
    length-free bone direction and the root-relative MPJPE; a negative gain in bold."""
    if reference not in res or len(res) < 2:
        return []
    keys = list(res[reference])
    lines = [f'### Gain over {reference} per class (%): ' + ' / '.join(n for _, n in GAIN_METRICS),
             '', '| method | ' + ' | '.join(keys) + ' |', '|---|' + '---:|' * len(keys)]
    for m, per in res.items():
        if m == reference:
            continue
        cells = []
        for k in keys:
            vals = []
            for name, _ in GAIN_METRICS:
                r = res[reference][k]['metrics'][name]['overall']
                v = per[k]['metrics'][name]['overall'] if k in per else None
                g = 100 * (r - v) / r if r and v is not None and np.isfinite(v) else float('nan')
                vals.append(f'**{_fmt(g, 1)}**' if np.isfinite(g) and g < 0 else _fmt(g, 1))
            cells.append(' / '.join(vals))
        lines.append(f'| {m} | ' + ' | '.join(cells) + ' |')
    return lines + ['']


def bone_length_lines(res: Dict) -> List[str]:
    """A table of the bone-length std per segment (cm, each clip's std over time, pooled over
    the classes weighted by frames) of every method, beside its jitter (m/s²)."""
    if not res:
        return []
    names = [f'{JOINT_NAMES[p]}-{JOINT_NAMES[c]}' for p, c in zip(SEGMENT_PARENTS,
                                                                  SEGMENT_CHILDREN)]
    cols = {}
    for m, per in res.items():
        keys = list(per)
        w = np.array([per[k]['frames'] for k in keys], float)
        v = np.array([per[k]['metrics']['bone_std_cm']['per_joint'] for k in keys], float)
        j = np.array([per[k]['metrics']['jitter_ms2']['overall'] for k in keys], float)
        ok = np.isfinite(v)
        with np.errstate(invalid='ignore'):
            seg = (np.where(ok, v, 0.0) * w[:, None]).sum(0) / (ok * w[:, None]).sum(0)
        okj = np.isfinite(j)
        jit = float((j[okj] * w[okj]).sum() / w[okj].sum()) if okj.any() else float('nan')
        cols[m] = (seg, jit)
    lines = ['### Bone-length std per segment (cm), all classes pooled, beside jitter', '',
             '| segment | ' + ' | '.join(cols) + ' |', '|---|' + '---:|' * len(cols)]
    for i, n in enumerate(names):
        lines.append(f'| {n} | ' + ' | '.join(_fmt(c[0][i], 3) for c in cols.values()) + ' |')
    lines.append('| **mean** | ' + ' | '.join(_fmt(float(np.nanmean(c[0])), 3)
                                               for c in cols.values()) + ' |')
    lines.append('| jitter m/s² | ' + ' | '.join(_fmt(c[1], 1) for c in cols.values()) + ' |')
    lines.append('')
    return lines


def to_markdown(results: Dict) -> str:
    exp = results.get('experiment', 'table4')
    lines: List[str] = []
    if exp in ('table4', 'table3'):
        res = results['results']
        keys = list(next(iter(res.values())).keys()) if res else []
        if exp == 'table4':
            lines += ['## Accuracy per scenario class (Shum et al. 2013 Table IV style)', '',
                      'Eq. 18 error (cm, parent-relative, 19 parts) against the true motion; '
                      '"enh." = improvement over raw.', '']
        else:
            ref = ('the full input skeleton (as in the paper)'
                   if results.get('reference', 'input') == 'input' else 'the true motion')
            cal = (results.get('calibration') or {}).get('pose', 'none')
            lines += ['## Reconstruction from joint subsets (Shum et al. 2013 Table III style), '
                      f'calibration: {cal}', '',
                      'Only the listed joints are TRACKED (others NOT_TRACKED, frozen); '
                      f'noise-only stream; Eq. 18 error (cm) against {ref}.', '',
                      f'**Protocol — {calibration_text(results)}.**', '']
            for k, v in results.get('subsets', {}).items():
                lines.append(f'- ({k}) {v["parts"]}')
            lines.append('')
        first = 'method'
        if exp == 'table3':
            first = f'method (calibration: {(results.get("calibration") or {}).get("pose", "none")})'
        head = f'| {first} | ' + ' | '.join(f'{k} Eq.18 cm' for k in keys)
        if exp == 'table4' and 'raw' in res:
            head += ' | ' + ' | '.join(f'{k} enh.' for k in keys)
        head += ' | MPJPE cm | jitter m/s² | bone std cm | bone dir ° | ms/frame |'
        lines += [head, '|' + '---|' * (head.count('|') - 1)]
        for m, per in res.items():
            row = [m] + [_fmt(per[k]['metrics']['eq18_cm']['overall']) for k in keys]
            if exp == 'table4' and 'raw' in res:
                for k in keys:
                    raw = res['raw'][k]['metrics']['eq18_cm']['overall']
                    val = per[k]['metrics']['eq18_cm']['overall']
                    row.append(_fmt(100 * (raw - val) / raw, 1) + '%' if raw else 'n/a')
            w = np.array([per[k]['frames'] for k in keys], float)

            def avg(name, w=w, per=per):
                v = np.array([per[k]['metrics'][name]['overall'] for k in keys], float)
                ok = np.isfinite(v)
                return float((v[ok] * w[ok]).sum() / w[ok].sum()) if ok.any() else float('nan')
            tm = np.array([per[k]['time']['mean_ms'] for k in keys], float)
            row += [_fmt(avg('mpjpe_cm')), _fmt(avg('jitter_ms2'), 1), _fmt(avg('bone_std_cm')),
                    _fmt(avg('bone_dir_deg'), 1), _fmt(float(np.nanmean(tm)), 3)]
            lines.append('| ' + ' | '.join(row) + ' |')
        lines.append('')
        if exp == 'table4' and res:
            lines += ['### Eq. 18 error per joint (cm), all classes pooled', '',
                      '| joint | ' + ' | '.join(res) + ' |', '|---|' + '---:|' * len(res)]
            for j in range(1, NUM_JOINTS):
                vals = []
                for m in res:
                    v = [res[m][k]['metrics']['eq18_cm']['per_joint'][j] for k in keys]
                    w = [res[m][k]['frames'] for k in keys]
                    vals.append(_fmt(float(np.average(v, weights=w)) if np.all(np.isfinite(v))
                                     else float('nan')))
                lines.append(f'| {JOINT_NAMES[j]} | ' + ' | '.join(vals) + ' |')
            lines.append('')
            lines += gain_lines(res)
            lines += bone_length_lines(res)
            lines += no_harm_lines(res)
    elif exp == 'fig5':
        lines += ['## PCA dimensions vs matching error and search time (Shum & Ho 2012 Fig. 5)', '',
                  f'database {results["database_size"]} postures, {results["queries"]} queries', '',
                  '| dims | error % over 60-D (Eq. 6) | mean e (m², Eq. 5) | search ms/query |',
                  '|---:|---:|---:|---:|']
        for r in results['rows']:
            lines.append(f'| {r["dims"]} | {_fmt(r["error_pct"])} | {_fmt(r["error_m2"], 4)} | '
                         f'{_fmt(r["search_ms_per_query"], 4)} |')
        lines.append('')
    elif exp == 'fig8':
        lines += [f'## Parameter sweeps of method {results["method"]} (Shum et al. 2013 Fig. 8 '
                  f'style), class {results["scenario"]}', '']
        for p, rows in results['sweeps'].items():
            lines += [f'### {p}', '', '| value | Eq.18 cm | MPJPE cm | ms/frame |', '|---:|---:|---:|---:|']
            for r in rows:
                if 'skipped' in r:
                    lines.append(f'| {r["value"]} | skipped: {r["skipped"]} | | |')
                else:
                    lines.append(f'| {r["value"]} | {_fmt(r["eq18_cm"])} | {_fmt(r["mpjpe_cm"])} | '
                                 f'{_fmt(r["frame_ms"], 2)} |')
            lines.append('')
    lines += _meta_lines(results.get('meta', {}))
    if results.get('method_params'):
        lines.append('- method parameters: ' + '; '.join(
            f'{m}: {json.dumps(json_safe(p))}' for m, p in results['method_params'].items()))
    if 'sensor_statistics' in results:
        lines += ['', format_statistics(results['sensor_statistics'])]
    return '\n'.join(lines) + '\n'
