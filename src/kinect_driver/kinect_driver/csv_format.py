"""CSV skeleton files (replay input, and an export format).

Format: UTF-8 text, comma separated, one row per joint of one user in one sensor frame::

    stamp_ns,user_id,joint,x,y,z,tracking_state
    1700000000000000000,1,HipCenter,2.512,0.031,0.093,2
    1700000000000000000,1,Spine,2.520,0.030,0.380,2
    ...

* ``stamp_ns``: capture time, integer nanoseconds (any epoch; replay timing uses differences).
* ``user_id``: unsigned integer.
* ``joint``: a Kinect v1 joint name (``skeleton_core.model.JOINT_NAMES``, e.g. ``HandLeft``) or its
  index 0-19.
* ``x, y, z``: metres, REP-103 sensor frame (x forward out of the lens, y left, z up).
* ``tracking_state``: 0 NOT_TRACKED, 1 INFERRED, 2 TRACKED. Optional column: missing -> 2.
* An optional ``reliability`` column (0-1, empty = unknown) may follow.

Every (stamp_ns, user_id) must list all 20 joints exactly once; rows of one sensor frame share
``stamp_ns`` and frames appear in time order. Lines starting with ``#`` and blank lines are
ignored. The header line is required (columns may be in any order).
"""
from __future__ import annotations

import csv
from pathlib import Path
from typing import Dict, Iterable, List, Tuple

import numpy as np

from skeleton_core.conversions import SkeletonFormatError, SkeletonFrame, validate_arrays
from skeleton_core.model import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS

REQUIRED_COLUMNS = ('stamp_ns', 'user_id', 'joint', 'x', 'y', 'z')
COLUMNS = ('stamp_ns', 'user_id', 'joint', 'x', 'y', 'z', 'tracking_state')


class CsvFormatError(ValueError):
    """A CSV skeleton file that cannot be read (message names the file and line)."""


def _joint(value: str) -> int:
    v = value.strip()
    if v in JOINT_INDEX:
        return JOINT_INDEX[v]
    if v.isdigit() and int(v) < NUM_JOINTS:
        return int(v)
    raise ValueError(f'unknown joint {value!r}')


def read_csv(path, frame_id: str = '') -> List[Tuple[int, List[SkeletonFrame]]]:
    """[(stamp_ns, [SkeletonFrame per user])] in file order."""
    p = Path(path)
    try:
        text = p.read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError) as e:
        raise CsvFormatError(f'cannot read CSV skeleton file {p}: {getattr(e, "strerror", None) or e}'
                             ) from None
    lines = [(n, ln) for n, ln in enumerate(text.splitlines(), 1)
             if ln.strip() and not ln.lstrip().startswith('#')]
    if not lines:
        raise CsvFormatError(f'{p}: empty CSV skeleton file (expected a header '
                             f'{",".join(COLUMNS)})')
    header = [h.strip() for h in next(csv.reader([lines[0][1]]))]
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise CsvFormatError(f'{p}:{lines[0][0]}: header lacks column(s) {missing} '
                             f'(expected {",".join(COLUMNS)})')
    col = {h: i for i, h in enumerate(header)}
    # (stamp, user) -> arrays, keeping first-seen order
    order: List[Tuple[int, int]] = []
    data: Dict[Tuple[int, int], dict] = {}
    for (lineno, row) in zip((n for n, _ in lines[1:]), csv.reader([ln for _, ln in lines[1:]])):
        try:
            if len(row) < len(header):
                raise ValueError(f'{len(row)} columns, header has {len(header)}')
            stamp = int(row[col['stamp_ns']])
            uid = int(row[col['user_id']])
            if uid < 0:
                raise ValueError('negative user_id')
            j = _joint(row[col['joint']])
            xyz = [float(row[col[c]]) for c in ('x', 'y', 'z')]
            ts = int(row[col['tracking_state']]) if 'tracking_state' in col and \
                row[col['tracking_state']].strip() != '' else 2
            rel = float('nan')
            if 'reliability' in col and row[col['reliability']].strip() != '':
                rel = float(row[col['reliability']])
        except ValueError as e:
            raise CsvFormatError(f'{p}:{lineno}: {e}') from None
        key = (stamp, uid)
        d = data.get(key)
        if d is None:
            d = {'pos': np.full((NUM_JOINTS, 3), np.nan), 'ts': np.zeros(NUM_JOINTS, np.int64),
                 'rel': np.full(NUM_JOINTS, np.nan, np.float32), 'seen': np.zeros(NUM_JOINTS, bool),
                 'line': lineno}
            data[key] = d
            order.append(key)
        if d['seen'][j]:
            raise CsvFormatError(f'{p}:{lineno}: joint {JOINT_NAMES[j]} listed twice for '
                                 f'stamp {stamp} user {uid}')
        d['seen'][j] = True
        d['pos'][j] = xyz
        d['ts'][j] = ts
        d['rel'][j] = rel
    out: List[Tuple[int, List[SkeletonFrame]]] = []
    last_stamp = None
    for key in order:
        d = data[key]
        stamp, uid = key
        if not d['seen'].all():
            lack = [JOINT_NAMES[j] for j in np.flatnonzero(~d['seen'])]
            raise CsvFormatError(f'{p}:{d["line"]}: stamp {stamp} user {uid} lacks joints {lack}')
        try:
            pos, ts, rel, _ = validate_arrays(d['pos'], d['ts'], d['rel'])
        except SkeletonFormatError as e:
            raise CsvFormatError(f'{p}:{d["line"]}: stamp {stamp} user {uid}: {e}') from None
        fr = SkeletonFrame(positions=pos, tracking_state=ts, reliability=rel, user_id=uid,
                           stamp_ns=stamp, frame_id=frame_id)
        if last_stamp is not None and stamp == last_stamp:
            out[-1][1].append(fr)
        else:
            if last_stamp is not None and stamp < last_stamp:
                raise CsvFormatError(f'{p}:{d["line"]}: stamp {stamp} goes back in time')
            out.append((stamp, [fr]))
            last_stamp = stamp
    return out


def write_csv(path, frames: Iterable[Tuple[int, Iterable[SkeletonFrame]]]) -> int:
    """Write [(stamp_ns, frames)] in the format above; returns the number of skeletons written."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    n = 0
    with open(p, 'w', newline='', encoding='utf-8') as f:
        w = csv.writer(f)
        w.writerow(COLUMNS + ('reliability',))
        for stamp, frs in frames:
            for fr in frs:
                n += 1
                for j in range(NUM_JOINTS):
                    r = fr.reliability[j] if fr.reliability is not None else np.nan
                    w.writerow([int(stamp), int(fr.user_id), JOINT_NAMES[j],
                                *(f'{v:.6f}' for v in fr.positions[j]),
                                int(fr.tracking_state[j]), '' if not np.isfinite(r) else f'{r:.4f}'])
    return n
