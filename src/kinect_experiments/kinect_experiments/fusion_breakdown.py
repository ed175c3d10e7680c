"""Where the fused raw Eq. 18 error comes from (issue 31 (a)): every segment of every frame by
whether each of the two views tracks it (both ends TRACKED), with the mean error of view 1, view 2,
the fusion and the per-segment oracle (the better view), and each category's share of the fused
mean; then per joint the share of frames each view (and both) does not track.

    python -m kinect_experiments.fusion_breakdown --seeds 1 --scenarios b,c --layout front-side
"""
from __future__ import annotations

import argparse
from typing import List

import numpy as np

from skeleton_core.model import JOINT_NAMES, SEGMENT_PARENT_INDEX, TRACKED
from skeleton_eval.clips import load_clips
from skeleton_eval.sensor_model import SensorModel

from .fusion_eval import LAYOUTS, fused_frames, view_poses

_CH = np.arange(1, len(JOINT_NAMES))
_PA = np.asarray(SEGMENT_PARENT_INDEX)


def segment_error_cm(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(T, 19) Eq. 18's per-segment error (cm)."""
    return np.linalg.norm((p[:, _CH] - p[:, _PA]) - (t[:, _CH] - t[:, _PA]), axis=-1) * 100.0


def breakdown(seed: int, scenario: str, layout: str = 'front-side', max_frames: int = 200,
              sensor_params=None) -> List[str]:
    _, dev, _ = load_clips('auto', seed)
    sensor = SensorModel(sensor_params, seed=seed)
    poses = view_poses(sensor, 2, layout)
    cats = {k: {'n': 0, 'v1': 0.0, 'v2': 0.0, 'fused': 0.0, 'oracle': 0.0, 'single': 0.0}
            for k in ('TT', 'TI', 'IT', 'II')}
    lost = np.zeros((3, len(JOINT_NAMES)))
    frames = 0
    for clip in dev:
        views = [sensor.corrupt(clip, scenario, seed=seed, max_frames=max_frames, view=p)
                 for p in poses]
        truth = poses[0].apply(views[0].truth)
        vw = [poses[k].apply(v.positions) for k, v in enumerate(views)]
        fused = np.stack([f.positions for f in fused_frames(views, poses)])
        err = {'v1': segment_error_cm(vw[0], truth), 'v2': segment_error_cm(vw[1], truth),
               'fused': segment_error_cm(fused, truth)}
        err['oracle'] = np.minimum(err['v1'], err['v2'])
        seg_t = [(v.tracking_state[:, _CH] == TRACKED) & (v.tracking_state[:, _PA] == TRACKED)
                 for v in views]
        key = np.array(['II', 'IT', 'TI', 'TT'])[seg_t[0] * 2 + seg_t[1]]
        for k, c in cats.items():
            m = key == k
            c['n'] += int(m.sum())
            for name in ('v1', 'v2', 'fused', 'oracle'):
                c[name] += float(err[name][m].sum())
        nt = [v.tracking_state != TRACKED for v in views]
        lost += np.stack([nt[0].sum(0), nt[1].sum(0), (nt[0] & nt[1]).sum(0)])
        frames += len(nt[0])
    n_all = sum(c['n'] for c in cats.values())
    lines = [f'seed {seed} class {scenario} layout {layout}: segments by (view 1, view 2) TRACKED '
             '(T) or not (I) | share | mean Eq. 18 (cm) view 1, view 2, fused, oracle | share of '
             'the fused mean (cm)']
    total = 0.0
    for k, c in cats.items():
        n = max(c['n'], 1)
        total += c['fused'] / n_all
        lines.append(f'  {k} | {100 * c["n"] / n_all:5.1f} % | {c["v1"] / n:6.2f} {c["v2"] / n:6.2f} '
                     f'{c["fused"] / n:6.2f} {c["oracle"] / n:6.2f} | {c["fused"] / n_all:.2f}')
    lines.append(f'  fused mean {total:.2f} cm')
    lines.append('  not TRACKED % of frames, view 1 / view 2 / both: ' + ', '.join(
        f'{JOINT_NAMES[j]} {100 * lost[0, j] / frames:.0f}/{100 * lost[1, j] / frames:.0f}/'
        f'{100 * lost[2, j] / frames:.0f}' for j in range(len(JOINT_NAMES))))
    return lines


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--seeds', default='1')
    p.add_argument('--scenarios', default='b,c')
    p.add_argument('--layout', default='front-side', choices=LAYOUTS)
    p.add_argument('--max-frames', type=int, default=200)
    p.add_argument('--sensor-params', default=None, help='sensor-model YAML (overrides)')
    a = p.parse_args(argv)
    for seed in (int(s) for s in a.seeds.split(',') if s):
        for sc in (s for s in a.scenarios.split(',') if s):
            print('\n'.join(breakdown(seed, sc, a.layout, a.max_frames, a.sensor_params)))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
