"""Bone-direction error on the segments a confident failure touches (class d), per failure mode.

The class-d rows of ``evaluate`` average over every segment and frame, most of which no failure
touches; this scores only the segments with an end inside an episode of each mode
(``hand_snap``, ``limb_swap``, ``foot_slide``, ``person_jump``; the sensor model's event records),
for raw and for C with the given parameter overrides.

    python -m skeleton_eval.failure_segments --seeds 1,2 \\
        --config after='{}' --config before='{"plausibility": false}'
"""
from __future__ import annotations

import argparse
import json
import sys
from typing import Dict, List, Sequence

import numpy as np

from skeleton_core.model import SEGMENT_CHILDREN, SEGMENT_PARENTS

from . import evaluation as E
from .clips import load_clips
from .evaluation import run_method
from .registry import load_plugins, make_method
from .sensor_params import CONFIDENT_FAILURES
from .sensor_stream import KinectStream

_SC = np.array(SEGMENT_CHILDREN)
_SP = np.array(SEGMENT_PARENTS)


def failure_masks(stream: KinectStream) -> Dict[str, np.ndarray]:
    """Per mode, (T, 20) bool: the joints inside an episode of that mode."""
    out = {}
    for mode in CONFIDENT_FAILURES:
        m = np.zeros(stream.tracking_state.shape, bool)
        for e in stream.events:
            if e['type'] == mode:
                m[e['frame']:e['frame'] + e['duration'], e['joints']] = True
        out[mode] = m
    return out


def segment_angles(pred: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(T, 19) angle (deg) between estimated and true segment directions."""
    a = pred[:, _SC] - pred[:, _SP]
    b = truth[:, _SC] - truth[:, _SP]
    with np.errstate(invalid='ignore', divide='ignore'):
        c = (a * b).sum(-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def score(methods: Sequence, streams: List[KinectStream]) -> Dict[str, Dict[str, tuple]]:
    """{label: {mode: (mean deg, segment-frames), 'all': ...}} for (label, factory) pairs."""
    res = {}
    for label, factory in methods:
        m = factory()
        acc: Dict[str, list] = {k: [] for k in CONFIDENT_FAILURES}
        every = []
        for s in streams:
            out, _ = run_method(m, s)
            ang = segment_angles(out, s.truth)
            every.append(ang.ravel())
            for k, mask in failure_masks(s).items():
                acc[k].append(ang[mask[:, _SC] | mask[:, _SP]])
        row = {k: (float(np.nanmean(np.concatenate(v))) if sum(map(len, v)) else float('nan'),
                   int(sum(map(len, v)))) for k, v in acc.items()}
        row['all'] = (float(np.nanmean(np.concatenate(every))), int(sum(map(len, every))))
        res[label] = row
    return res


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog='failure_segments', description=__doc__.split('\n\n')[0])
    p.add_argument('--seeds', default='1,2')
    p.add_argument('--max-frames', type=int, default=300)
    p.add_argument('--config', action='append', default=[], metavar='LABEL=JSON',
                   help='C parameter overrides under a label (repeatable; default after={})')
    args = p.parse_args(argv)
    load_plugins()
    _, dev, _ = load_clips('auto')
    configs = [c.split('=', 1) for c in (args.config or ['after={}'])]
    methods = [('raw', lambda: make_method('raw'))]
    for label, text in configs:
        params = json.loads(text)
        methods.append((label, lambda p=params: make_method('C', **p)))
    modes = list(CONFIDENT_FAILURES) + ['all']
    print('| seed | method | ' + ' | '.join(modes) + ' |')
    print('|---|---|' + '---:|' * len(modes))
    for seed in [int(s) for s in args.seeds.split(',') if s]:
        streams = E.make_streams(dev, ('d',), seed, args.max_frames or None)['d']
        for label, row in score(methods, streams).items():
            print(f'| {seed} | {label} | ' + ' | '.join(f'{row[k][0]:.1f} ({row[k][1]})'
                                                       for k in modes) + ' |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
