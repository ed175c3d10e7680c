""""No harm" per segment: a method against the raw sensor where the sensor is right.

A reconstruction fills what the sensor misses or gets wrong; where the sensor reports both ends
of a segment TRACKED and nothing is known to be wrong with them, its output should be at least as
good as the sensor's own segment. This module scores exactly those segment-frames:

* :func:`segment_mask` — (T, 19): both ends TRACKED and, where the stream knows it (the sensor
  model's ``clean`` mask: no occlusion, false positive, turn, confident failure or tracked
  error), both ends fault-free;
* :func:`direction_sums` — per segment the sum and count of the length-free direction error (deg)
  over the masked segment-frames (sums pool over streams by adding);
* :func:`compare` / :func:`violations` — a method's per-segment mean against a reference's (the
  raw sensor, or raw + correction on real data), with the no-harm tolerance (0.5 deg);
* :func:`to_markdown` — the per-segment table of ``make evaluate`` (classes as columns).

The mask depends only on the input stream, so every method is scored on the same segment-frames
and the difference of two methods' means is a paired comparison.
"""
from __future__ import annotations

from typing import Dict, List, Optional, Sequence

import numpy as np

from skeleton_core.model import (JOINT_NAMES, NUM_SEGMENTS, SEGMENT_CHILD_INDEX,
                                 SEGMENT_PARENT_INDEX, TRACKED)

TOLERANCE_DEG = 0.5   # C's direction error <= raw's + 0.5 deg on every segment
SEGMENT_NAMES = tuple(f'{JOINT_NAMES[p]}-{JOINT_NAMES[c]}'
                      for p, c in zip(SEGMENT_PARENT_INDEX, SEGMENT_CHILD_INDEX))


def segment_mask(tracking_state, clean=None) -> np.ndarray:
    """(T, 19) bool: both ends of the segment TRACKED (and ``clean``, (T, 20), at both ends when
    given)."""
    st = np.asarray(tracking_state)
    ok = st == TRACKED
    if clean is not None:
        ok = ok & np.asarray(clean, bool)
    return ok[:, SEGMENT_PARENT_INDEX] & ok[:, SEGMENT_CHILD_INDEX]


def direction_sums(pred, truth, mask) -> tuple:
    """``(sums (19,), counts (19,))``: the sum (deg) and number of the direction errors of
    ``pred`` against ``truth`` (both (T, 20, 3)) over the segment-frames of ``mask`` (T, 19)
    where both segments are finite and non-degenerate."""
    p = np.asarray(pred, float)
    t = np.asarray(truth, float)
    a = p[:, SEGMENT_CHILD_INDEX] - p[:, SEGMENT_PARENT_INDEX]
    b = t[:, SEGMENT_CHILD_INDEX] - t[:, SEGMENT_PARENT_INDEX]
    na = np.linalg.norm(a, axis=-1)
    nb = np.linalg.norm(b, axis=-1)
    ok = np.asarray(mask, bool) & np.isfinite(na) & np.isfinite(nb) & (na > 1e-9) & (nb > 1e-9)
    with np.errstate(invalid='ignore', divide='ignore'):
        cos = np.einsum('tsk,tsk->ts', a, b) / (na * nb)
    ang = np.degrees(np.arccos(np.clip(np.where(ok, cos, 1.0), -1.0, 1.0)))
    return np.where(ok, ang, 0.0).sum(axis=0), ok.sum(axis=0).astype(int)


def empty() -> Dict:
    """An accumulator for :func:`add` (JSON-able)."""
    return {'sum_deg': [0.0] * NUM_SEGMENTS, 'count': [0] * NUM_SEGMENTS}


def add(acc: Dict, sums, counts) -> Dict:
    """``acc`` (from :func:`empty`) plus one stream's :func:`direction_sums`, in place."""
    acc['sum_deg'] = [float(a + b) for a, b in zip(acc['sum_deg'], sums)]
    acc['count'] = [int(a + b) for a, b in zip(acc['count'], counts)]
    return acc


def merge(accs: Sequence[Dict]) -> Dict:
    out = empty()
    for a in accs:
        if a:
            add(out, a['sum_deg'], a['count'])
    return out


def means(acc: Dict) -> np.ndarray:
    """(19,) mean direction error (deg) per segment; NaN where no segment-frame."""
    s = np.asarray(acc['sum_deg'], float)
    n = np.asarray(acc['count'], float)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(n > 0, s / np.maximum(n, 1), np.nan)


def overall(acc: Dict) -> float:
    n = float(np.sum(acc['count']))
    return float(np.sum(acc['sum_deg']) / n) if n > 0 else float('nan')


def compare(method: Dict, reference: Dict, tol: float = TOLERANCE_DEG,
            min_count: int = 1) -> List[Dict]:
    """Per segment: ``{'segment', 'method', 'reference', 'diff', 'count', 'harm'}`` with the
    means of the two accumulators (scored on the same segment-frames), ``harm`` when the method
    is more than ``tol`` deg worse than the reference on at least ``min_count`` segment-frames."""
    m, r = means(method), means(reference)
    n = np.minimum(np.asarray(method['count']), np.asarray(reference['count']))
    rows = []
    for i in range(NUM_SEGMENTS):
        d = m[i] - r[i]
        rows.append({'segment': SEGMENT_NAMES[i], 'method': float(m[i]),
                     'reference': float(r[i]), 'diff': float(d), 'count': int(n[i]),
                     'harm': bool(n[i] >= min_count and np.isfinite(d) and d > tol)})
    return rows


def violations(method: Dict, reference: Dict, tol: float = TOLERANCE_DEG,
               min_count: int = 1) -> List[Dict]:
    """The rows of :func:`compare` where the method harms."""
    return [r for r in compare(method, reference, tol, min_count) if r['harm']]


def worst(method: Dict, reference: Dict) -> Optional[Dict]:
    """The row of :func:`compare` with the largest difference (None without data)."""
    rows = [r for r in compare(method, reference) if np.isfinite(r['diff'])]
    return max(rows, key=lambda r: r['diff']) if rows else None


def _f(v, nd=1):
    return 'n/a' if v is None or not np.isfinite(v) else f'{v:.{nd}f}'


def to_markdown(per_class: Dict[str, Dict[str, Dict]], method: str = 'C',
                reference: str = 'raw', tol: float = TOLERANCE_DEG,
                title: str = '') -> str:
    """The per-segment table: ``per_class`` ``{class: {method name: accumulator}}``; one row per
    segment, per class ``method / reference (difference)`` in deg, a difference above ``tol``
    in bold; then the count of harmed segments, each with its number of segment-frames (a
    cell seen on a few dozen frames, e.g. a limb the class's object hides, is a few events)."""
    classes = [k for k, v in per_class.items() if method in v and reference in v]
    if not classes:
        return ''
    lines = [title or f'### No harm: {method} against {reference} on TRACKED, fault-free segments',
             '',
             f'Direction error (deg, length-free) per segment, only on the segment-frames whose '
             f'two ends the sensor reports TRACKED with no fault; per class `{method} / '
             f'{reference} (difference)`; **bold**: {method} more than {tol:g} deg worse.', '',
             '| segment | ' + ' | '.join(classes) + ' |', '|---|' + '---:|' * len(classes)]
    cmp = {k: compare(per_class[k][method], per_class[k][reference], tol) for k in classes}
    for i, name in enumerate(SEGMENT_NAMES):
        cells = []
        for k in classes:
            r = cmp[k][i]
            cell = f'{_f(r["method"])} / {_f(r["reference"])} ({_f(r["diff"])})'
            cells.append(f'**{cell}**' if r['harm'] else cell)
        lines.append(f'| {name} | ' + ' | '.join(cells) + ' |')
    tot = []
    for k in classes:
        mo, ro = overall(per_class[k][method]), overall(per_class[k][reference])
        tot.append(f'{_f(mo)} / {_f(ro)} ({_f(mo - ro)})')
    lines.append('| all | ' + ' | '.join(tot) + ' |')
    harmed = [(k, r) for k in classes for r in cmp[k] if r['harm']]
    lines += ['', f'{len(harmed)} of {len(classes) * NUM_SEGMENTS} segment-class cells more than '
              f'{tol:g} deg worse than {reference}' + (': ' + ', '.join(
                  f'{k} {r["segment"]} +{r["diff"]:.1f} ({r["count"]} frames)'
                  for k, r in harmed) if harmed else '.')]
    return '\n'.join(lines) + '\n'
