"""A lab's mocap reference for learning a sensor correction: joint centres of the 20 model joints
over time, on the mocap system's own clock and in its own frame (no rclpy).

Formats (:func:`load_reference`, chosen by the file name):

* **CSV joint positions** (``.csv``): a header row, then one row per frame. Columns: ``time_s``
  (seconds on the mocap clock; or ``frame`` with ``--reference-rate``) and ``<Joint>_x``,
  ``<Joint>_y``, ``<Joint>_z`` for any of the 20 model joints of :mod:`skeleton_core.model`
  (``HipCenter_x``, ...). Missing joints or empty cells are NaN (a joint never given is not
  learned: its correction is zero). Units: metres unless ``units`` says otherwise; the frame is
  free (a rigid registration maps it onto the tracker's).
* **BVH** (``.bvh``) through a joint map (``config/joint_maps``, :mod:`skeleton_data.joint_map`):
  the map's joint centres, at the file's frame time.
* **Marker text** (``.txt``/``.csv.gz``/...) or **C3D** (``.c3d``) through a ``markers`` joint
  map (Plug-in-Gait rules, :mod:`skeleton_data.vicon`); C3D through the small reader
  :mod:`skeleton_data.c3d` (POINT data, float or integer, Intel byte order).

Returns :class:`Reference` (times (N,), positions (N, 20, 3) metres). Errors are ``ValueError``
with one line naming the file.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from skeleton_core.model import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS

UNITS = {'m': 1.0, 'cm': 0.01, 'mm': 0.001}


@dataclass
class Reference:
    times: np.ndarray        # (N,) s, the mocap clock
    positions: np.ndarray    # (N, 20, 3) m, the mocap frame; NaN where not given
    source: str = ''


def read_csv(path, units: str = 'm', rate: Optional[float] = None) -> Reference:
    path = Path(path)
    if units not in UNITS:
        raise ValueError(f'{path}: units must be one of {", ".join(UNITS)}, got {units!r}')
    try:
        with open(path, newline='', encoding='utf-8') as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f'{path}: cannot read ({e})') from None
    rows = [r for r in rows if r and not r[0].lstrip().startswith('#')]
    if len(rows) < 3:
        raise ValueError(f'{path}: needs a header row and at least 2 frames')
    head = [h.strip() for h in rows[0]]
    cols = {}
    for i, h in enumerate(head):
        if h in ('time_s', 'frame'):
            continue
        name, _, axis = h.rpartition('_')
        if name not in JOINT_INDEX or axis not in ('x', 'y', 'z'):
            raise ValueError(f'{path}: column {h!r} is not time_s, frame or <Joint>_x|y|z of a '
                             f'model joint ({", ".join(JOINT_NAMES)})')
        cols[i] = (JOINT_INDEX[name], 'xyz'.index(axis))
    if 'time_s' not in head and ('frame' not in head or not rate):
        raise ValueError(f'{path}: needs a time_s column (or frame with a reference rate)')
    if not cols:
        raise ValueError(f'{path}: no joint columns (<Joint>_x, <Joint>_y, <Joint>_z)')
    n = len(rows) - 1
    pos = np.full((n, NUM_JOINTS, 3), np.nan)
    t = np.zeros(n)
    ti = head.index('time_s') if 'time_s' in head else head.index('frame')
    for k, r in enumerate(rows[1:]):
        if len(r) != len(head):
            raise ValueError(f'{path}:{k + 2}: {len(r)} fields, the header has {len(head)}')
        try:
            t[k] = float(r[ti])
            for i, (j, a) in cols.items():
                v = r[i].strip()
                pos[k, j, a] = float(v) if v else np.nan
        except ValueError:
            raise ValueError(f'{path}:{k + 2}: non-numeric value') from None
    if 'time_s' not in head:
        t = t / float(rate)
    if not np.all(np.diff(t) > 0):
        raise ValueError(f'{path}: time_s must increase from row to row')
    return Reference(t, pos * UNITS[units], str(path))


def write_csv(path, times, positions, joints=JOINT_NAMES) -> Path:
    """Write a reference CSV (metres) of (N, 20, 3) positions; NaN as empty cells."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, 'w', newline='') as f:
        w = csv.writer(f)
        w.writerow(['time_s'] + [f'{j}_{a}' for j in joints for a in 'xyz'])
        for t, p in zip(times, positions):
            w.writerow([f'{t:.6f}'] + ['' if not np.isfinite(v) else f'{v:.5f}'
                                       for j in joints for v in p[JOINT_INDEX[j]]])
    return path


def load_reference(path, joint_map=None, units: str = 'm',
                   rate: Optional[float] = None) -> Reference:
    """Any supported reference file (module docstring); ``joint_map`` (path or JointMap) for
    BVH, marker text and C3D files."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f'reference {path}: no such file')
    suffix = path.suffix.lower()
    if suffix == '.csv' and joint_map is None:
        return read_csv(path, units, rate)
    from .joint_map import JointMap, load_joint_map
    if joint_map is None:
        raise ValueError(f'reference {path}: a {suffix} file needs a joint map (--joint-map)')
    jm = joint_map if isinstance(joint_map, JointMap) else load_joint_map(joint_map)
    if suffix == '.bvh':
        from .bvh import load_bvh
        from .joint_map import bvh_frames
        bvh = load_bvh(str(path))
        kin, _ = bvh_frames(bvh, jm)
        return Reference(np.arange(len(kin)) * float(bvh.frame_time), kin, str(path))
    from .joint_map import marker_joint_centres, read_markers
    if suffix == '.c3d':
        from .c3d import read_c3d_markers
        markers, fps = read_c3d_markers(path, jm)
    else:
        markers, fps = read_markers(path, jm), jm.frame_rate
    return Reference(np.arange(len(markers)) / float(fps), marker_joint_centres(markers, jm),
                     str(path))


__all__ = ['Reference', 'read_csv', 'write_csv', 'load_reference']
