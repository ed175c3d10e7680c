"""Noise statistics of sensor-model streams (:func:`statistics`, for the evaluation report and the
calibration against real recordings) and their Markdown summary."""
from __future__ import annotations

from typing import Dict, Sequence

import numpy as np

from skeleton_core.model import (INFERRED, JOINT_NAMES, NOT_TRACKED, NUM_JOINTS, SEGMENT_CHILDREN,
                                 SEGMENT_NAMES, SEGMENT_PARENTS, TRACKED, segment_lengths)
from .sensor_params import GROUPS, JOINT_GROUP
from .sensor_stream import KinectStream


def statistics(streams: Sequence[KinectStream]) -> Dict:
    """Noise statistics of corrupted streams, for the report and the calibration test.

    * ``jitter_mm`` (20,): std of the random error (reported - truth, less its per-stream mean, i.e.
      less the systematic offset), RMS over axes, on clean frames only;
    * ``offset_mm`` (20,): RMS of the per-stream mean error (the systematic joint-centre offsets);
    * ``bone_length_std_mm`` (19,): std over time of each segment length on clean frames;
    * ``occluded_fraction``: per scenario, the fraction of joint-frames not TRACKED, and per joint
      group; ``false_positive_fraction``: per scenario, joint-frames latched but TRACKED;
    * ``events_per_min``: per scenario and event type/cause.
    """
    streams = list(streams)
    res_sq = np.zeros(NUM_JOINTS)
    res_n = np.zeros(NUM_JOINTS)
    off_sq = np.zeros(NUM_JOINTS)
    off_n = np.zeros(NUM_JOINTS)
    bl_var = np.zeros(len(SEGMENT_CHILDREN))
    bl_n = np.zeros(len(SEGMENT_CHILDREN))
    per_sc: Dict[str, Dict] = {}
    depth = []
    for s in streams:
        err = s.positions - s.truth
        cl = s.clean if s.clean is not None else np.ones(s.tracking_state.shape, bool)
        for j in range(NUM_JOINTS):
            e = err[cl[:, j], j]
            if len(e) >= 3:
                mu = e.mean(axis=0)
                res_sq[j] += ((e - mu) ** 2).sum() / 3
                res_n[j] += len(e) - 1
                off_sq[j] += (mu ** 2).sum() / 3
                off_n[j] += 1
        depth.append(s.truth[..., 0][cl])
        lengths = segment_lengths(s.positions)
        for k, (a, b) in enumerate(zip(SEGMENT_PARENTS, SEGMENT_CHILDREN)):
            m = cl[:, a] & cl[:, b]
            if m.sum() >= 3:
                bl_var[k] += lengths[m, k].var() * (m.sum() - 1)
                bl_n[k] += m.sum() - 1
        d = per_sc.setdefault(s.scenario, {'frames': 0, 'not_tracked': 0, 'inferred': 0,
                                           'joint_frames': 0, 'events': {}, 'group_nt': {},
                                           'fp_frames': 0})
        T = len(s)
        d['frames'] += T
        d['joint_frames'] += T * NUM_JOINTS
        d['not_tracked'] += int((s.tracking_state == NOT_TRACKED).sum())
        d['inferred'] += int((s.tracking_state == INFERRED).sum())
        for g in GROUPS:
            idx = [j for j in range(NUM_JOINTS) if JOINT_GROUP[j] == g]
            gd = d['group_nt'].setdefault(g, [0, 0])
            gd[0] += int((s.tracking_state[:, idx] != TRACKED).sum())
            gd[1] += T * len(idx)
        for e in s.events:
            key = f'{e["type"]}:{e["cause"]}'
            d['events'][key] = d['events'].get(key, 0) + 1
            if e['type'] == 'false_positive':
                d['fp_frames'] += e['duration'] * len(e['joints'])
    out = {
        'jitter_mm': (np.sqrt(res_sq / np.maximum(res_n, 1)) * 1e3).tolist(),
        'offset_mm': (np.sqrt(off_sq / np.maximum(off_n, 1)) * 1e3).tolist(),
        'bone_length_std_mm': (np.sqrt(bl_var / np.maximum(bl_n, 1)) * 1e3).tolist(),
        'mean_depth_m': float(np.concatenate(depth).mean()) if depth else float('nan'),
        'scenarios': {},
    }
    for sc, d in per_sc.items():
        minutes = d['frames'] / (streams[0].fps * 60.0)
        out['scenarios'][sc] = {
            'frames': d['frames'],
            'minutes': minutes,
            'not_tracked_fraction': d['not_tracked'] / d['joint_frames'],
            'inferred_fraction': d['inferred'] / d['joint_frames'],
            'occluded_fraction': (d['not_tracked'] + d['inferred']) / d['joint_frames'],
            'occluded_fraction_by_group': {g: v[0] / max(v[1], 1) for g, v in d['group_nt'].items()},
            'false_positive_fraction': d['fp_frames'] / d['joint_frames'],
            'events_per_min': {k: v / max(minutes, 1e-9) for k, v in sorted(d['events'].items())},
        }
    return out


def format_statistics(stats: Dict) -> str:
    """Markdown summary of :func:`statistics`."""
    lines = ['### Sensor model noise statistics', '',
             f'mean depth of clean joints: {stats["mean_depth_m"]:.2f} m', '',
             '| joint | jitter (mm) | systematic offset (mm) |', '|---|---:|---:|']
    for j, n in enumerate(JOINT_NAMES):
        lines.append(f'| {n} | {stats["jitter_mm"][j]:.1f} | {stats["offset_mm"][j]:.1f} |')
    lines += ['', '| segment | length std (mm) |', '|---|---:|']
    for k, n in enumerate(SEGMENT_NAMES):
        lines.append(f'| {n} | {stats["bone_length_std_mm"][k]:.1f} |')
    lines += ['', '| scenario | minutes | not tracked | inferred | false positive | events/min |',
              '|---|---:|---:|---:|---:|---|']
    for sc, d in stats['scenarios'].items():
        ev = ', '.join(f'{k} {v:.2f}' for k, v in d['events_per_min'].items())
        lines.append(f'| {sc} | {d["minutes"]:.2f} | {100 * d["not_tracked_fraction"]:.1f}% | '
                     f'{100 * d["inferred_fraction"]:.1f}% | '
                     f'{100 * d["false_positive_fraction"]:.1f}% | {ev} |')
    return '\n'.join(lines)
