"""Where the fused raw Eq. 18 error comes from: every segment of every frame by
whether each of the two views tracks it (both ends TRACKED), with the mean error of view 1, view 2,
the fusion and the per-segment oracle (the better view), and each category's share of the fused
mean; then per joint the share of frames each view (and both) does not track.

    python -m kinect_experiments.fusion_breakdown --seeds 1 --scenarios b,c --layout front-side

``--oracle`` prints instead what no fusion of the two views' raw observations can beat:
Eq. 18 of the fused raw skeleton and of oracles that know the truth, against the front
sensor alone:

* joint select: per joint and frame, the view whose joint is nearer the truth;
* joint convex: per joint and frame, the point of the segment between the two views' joints
  nearest the truth (the best per-joint convex weight);
* tree convex: per frame, the per-joint convex weights that minimise Eq. 18 itself (a convex
  problem over the 20 weights, L-BFGS-B): the best any per-joint weighting of the two views'
  raw joints can do;
* segment select: per segment of Eq. 18, the better of the two views' segment vectors (both ends
  from one view; a joint may then take a different view for each of its segments: no skeleton
  has that, and it is no bound either, a per-joint choice can mix the views along a segment);
* segment convex: per segment, the best convex combination of the two views' segment vectors
  (the same weight at both ends: not a bound of tree convex, whose ends' weights differ).
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


def _nearest_on_segment(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The point of the segment [a, b] nearest ``t`` (arrays (..., 3))."""
    d = b - a
    dd = np.einsum('...k,...k->...', d, d)
    w = np.einsum('...k,...k->...', t - a, d) / np.maximum(dd, 1e-18)
    return a + np.clip(w, 0.0, 1.0)[..., None] * d


def _tree_convex(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(T, J, 3): per frame, ``w a + (1 - w) b`` with the per-joint weights w in [0, 1] that
    minimise the sum of Eq. 18's segment errors (convex; L-BFGS-B over all frames at once)."""
    from scipy.optimize import minimize
    d = a - b
    ts = t[:, _CH] - t[:, _PA]
    bs = b[:, _CH] - b[:, _PA] - ts
    shape = a.shape[:2]

    def f(x):
        w = x.reshape(shape)
        e = w[:, _CH, None] * d[:, _CH] - w[:, _PA, None] * d[:, _PA] + bs
        n = np.linalg.norm(e, axis=-1)
        u = e / np.maximum(n, 1e-12)[..., None]
        g = np.zeros(shape)
        g[:, _CH] += np.einsum('tsk,tsk->ts', u, d[:, _CH])
        np.add.at(g, (slice(None), _PA), -np.einsum('tsk,tsk->ts', u, d[:, _PA]))
        return float(n.sum()), g.ravel()

    x0 = np.clip(np.einsum('tjk,tjk->tj', t - b, d) / np.maximum(np.einsum('tjk,tjk->tj', d, d),
                                                                 1e-18), 0.0, 1.0)
    r = minimize(f, x0.ravel(), jac=True, method='L-BFGS-B', bounds=[(0.0, 1.0)] * x0.size,
                 options={'maxiter': 2000})
    w = r.x.reshape(shape)[..., None]
    return w * a + (1.0 - w) * b


def oracle(seed: int, scenario: str, layout: str = 'front-side', max_frames: int = 200,
           sensor_params=None) -> dict:
    """Mean Eq. 18 (cm) over the dev clips: the front sensor alone, view 1, view 2, the fused raw
    skeleton and the oracles of the module docstring."""
    _, dev, _ = load_clips('auto', seed)
    sensor = SensorModel(sensor_params, seed=seed)
    poses = view_poses(sensor, 2, layout)
    front = poses[0] if layout == 'front-side' else None
    acc: dict = {}
    cats: dict = {}
    n = 0
    for clip in dev:
        views = [sensor.corrupt(clip, scenario, seed=seed, max_frames=max_frames, view=p)
                 for p in poses]
        if front is None:
            from skeleton_core.tf import Transform
            one = sensor.corrupt(clip, scenario, seed=seed, max_frames=max_frames,
                                 view=Transform.identity())
        else:
            one = views[0]
        truth = poses[0].apply(views[0].truth)
        a, b = (poses[k].apply(v.positions) for k, v in enumerate(views))
        fused = np.stack([f.positions for f in fused_frames(views, poses)])
        da, db = np.linalg.norm(a - truth, axis=-1), np.linalg.norm(b - truth, axis=-1)
        sel = np.where((da <= db)[..., None], a, b)
        # per segment: the error vectors of the two views' segment vectors
        ea = (a[:, _CH] - a[:, _PA]) - (truth[:, _CH] - truth[:, _PA])
        eb = (b[:, _CH] - b[:, _PA]) - (truth[:, _CH] - truth[:, _PA])
        rows = {'single': segment_error_cm(one.positions, one.truth),
                'view 1': segment_error_cm(a, truth), 'view 2': segment_error_cm(b, truth),
                'fused raw': segment_error_cm(fused, truth),
                'joint select': segment_error_cm(sel, truth),
                'joint convex': segment_error_cm(_nearest_on_segment(a, b, truth), truth),
                'tree convex': segment_error_cm(_tree_convex(a, b, truth), truth)}
        rows['segment select'] = np.minimum(rows['view 1'], rows['view 2'])
        rows['segment convex'] = np.linalg.norm(
            _nearest_on_segment(ea, eb, np.zeros_like(ea)), axis=-1) * 100.0
        for k, e in rows.items():
            acc[k] = acc.get(k, 0.0) + float(e.sum())
        # where the error is: segments both views track, one view, neither (share of the mean)
        seg_t = [(v.tracking_state[:, _CH] == TRACKED) & (v.tracking_state[:, _PA] == TRACKED)
                 for v in views]
        cat = seg_t[0].astype(int) + seg_t[1]
        for c, name in ((2, 'both'), (1, 'one'), (0, 'neither')):
            m = cat == c
            cats['n ' + name] = cats.get('n ' + name, 0) + int(m.sum())
            for k in ('fused raw', 'joint convex', 'tree convex'):
                cats[f'{k} {name}'] = cats.get(f'{k} {name}', 0.0) + float(rows[k][m].sum())
        n += rows['view 1'].size
    out = {k: v / n for k, v in acc.items()}
    out['categories'] = {k: (v / n if not k.startswith('n ') else 100.0 * v / n)
                         for k, v in cats.items()}
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--seeds', default='1')
    p.add_argument('--scenarios', default='b,c')
    p.add_argument('--layout', default='front-side', choices=LAYOUTS)
    p.add_argument('--max-frames', type=int, default=200)
    p.add_argument('--sensor-params', default=None, help='sensor-model YAML (overrides)')
    p.add_argument('--oracle', action='store_true',
                   help='the oracle bounds against the front sensor alone (module docstring)')
    a = p.parse_args(argv)
    for seed in (int(s) for s in a.seeds.split(',') if s):
        for sc in (s for s in a.scenarios.split(',') if s):
            if a.oracle:
                r = oracle(seed, sc, a.layout, a.max_frames, a.sensor_params)
                cats = r.pop('categories')
                base = r['single']
                print(f'seed {seed} class {sc} layout {a.layout} params {a.sensor_params}: '
                      + ', '.join(f'{k} {v:.2f} cm ({100 * (v - base) / base:+.1f} %)'
                                  for k, v in r.items()), flush=True)
                print('  segments tracked by both / one / neither view: share %, then each '
                      'row\'s cm of the mean from them: ' + ', '.join(
                          f'{k} {v:.2f}' for k, v in cats.items()), flush=True)
                continue
            print('\n'.join(breakdown(seed, sc, a.layout, a.max_frames, a.sensor_params)))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
