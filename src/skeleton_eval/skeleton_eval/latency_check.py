"""How well the synthetic added-latency figure resolves a delay (docs/research/2026-11-28-robustness.md).

For C on the dev clips, per sensor-model variant and seed and per class a-d: the one-sided delay the
evaluation table reports (:func:`.evaluation.reliable_latency_curve`, shifts >= 0), the signed delay
over shifts -K..K (:func:`.metrics.signed_latency_from_curves`, negative = the output leads), the
mean distance at shift 0 and how much one frame of shift changes it (the depth of the minimum the
delay is read from), and the delay behind the *true* motion from the peak of the cross-correlation
of root-relative joint velocities (output against truth, clean joint-frames): blind to static and
slowly turning offsets between output and input, and to the sensor noise (absent from the truth).
Frame-weighted means over the classes as in the perturbation table.

    python -m skeleton_eval.latency_check --variants nominal,noise:0.5,offset:1.5 --seeds 0,1,2
"""
from __future__ import annotations

import argparse
import json
import sys
from typing import Dict

import numpy as np

from . import evaluation as E
from .clips import load_clips
from .registry import load_plugins, make_method
from .report import json_safe
from . import metrics as M
from . import perturb as P
from .sensor_model import SensorModel


def check(method, clips, group, factor, seed, scenarios='abcd', max_frames=300) -> Dict:
    """Per class: frames, one-sided and signed delay (ms), distance at shift 0 and the change
    from shift 0 to 1 (mm); and their frame-weighted means (key ``'all'``)."""
    params = P.load_params(None) if group is None else P.perturbed_params(group, factor, None)
    sensor = SensorModel(params, seed=seed)
    out: Dict[str, Dict] = {}
    for sc in scenarios:
        behind = [np.zeros(M.MAX_LATENCY_FRAMES + 1), np.zeros(M.MAX_LATENCY_FRAMES + 1)]
        ahead = [np.zeros(M.MAX_LATENCY_FRAMES + 1), np.zeros(M.MAX_LATENCY_FRAMES + 1)]
        frames = 0
        jit = 0.0
        K = M.MAX_LATENCY_FRAMES
        xc = np.zeros(2 * K + 1)
        for s in E.make_streams(clips, (sc,), seed, max_frames, sensor)[sc]:
            pred, _ = E.run_method(method, s)
            raw = np.array(s.positions, float)
            raw -= raw[:, :1]
            raw[~s.clean] = np.nan
            raw[~s.clean[:, 0]] = np.nan
            rel = pred - pred[:, :1]
            tru = np.array(s.truth, float)
            tru -= tru[:, :1]
            # v_out(t) . v_truth(t - k) over the clean joint-frames
            xc += M.velocity_xcorr(rel, tru, K, np.isfinite(raw).all(-1))
            jit += M.jitter(pred, s.fps)[1] * len(s)
            for acc, c in ((behind, M.latency_curve(rel, raw)), (ahead, M.latency_curve(raw, rel))):
                acc[0] += c[0]
                acc[1] += c[1]
            frames += len(s)
        d = behind[0] / np.maximum(behind[1], 1) * 1000.0
        out[sc] = {'frames': frames,
                   'one_sided_ms': M.latency_from_curve(*behind, 30.0),
                   'signed_ms': M.signed_latency_from_curves(behind, ahead, 30.0),
                   'dist0_mm': float(d[0]), 'step_mm': float(d[1] - d[0]),
                   'xcorr_ms': M.xcorr_latency_ms(xc), 'jitter_ms2': jit / max(frames, 1)}
    w = np.array([v['frames'] for v in out.values()], float)
    out['all'] = {k: float(np.dot(w, [v[k] for v in out.values()]) / w.sum())
                  for k in ('one_sided_ms', 'signed_ms', 'dist0_mm', 'step_mm', 'xcorr_ms',
                            'jitter_ms2')}
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    p.add_argument('--variants', default='nominal,noise:0.5,offset:1.5',
                   help='comma list of nominal or group:factor (groups of skeleton_eval.perturb)')
    p.add_argument('--seeds', default='0,1,2')
    p.add_argument('--method', default='C')
    p.add_argument('--method-params', default='', help='JSON parameter overrides of the method')
    p.add_argument('--max-frames', type=int, default=300)
    p.add_argument('--json', default='', help='also write the results here')
    a = p.parse_args(argv)
    load_plugins()
    try:
        variants = []
        for v in a.variants.split(','):
            if v == 'nominal':
                variants.append((v, None, 1.0))
            else:
                g, f = v.split(':')
                if g not in P.GROUPS:
                    raise ValueError(f'unknown group {g!r}')
                variants.append((v, g, float(f)))
        seeds = [int(s) for s in a.seeds.split(',') if s]
    except ValueError as exc:
        print(f'latency_check: {exc}', file=sys.stderr)
        return 2
    _, dev, _ = load_clips('auto', 0)
    try:
        over = json.loads(a.method_params) if a.method_params else {}
        method = make_method(a.method, **over)
    except (ValueError, TypeError) as exc:
        print(f'latency_check: --method-params: {exc}', file=sys.stderr)
        return 2
    res = {}
    for label, g, f in variants:
        for seed in seeds:
            r = check(method, dev, g, f, seed, max_frames=a.max_frames)
            res[f'{label} seed {seed}'] = r
            al = r['all']
            print(f'{label:12s} seed {seed}: one-sided {al["one_sided_ms"]:5.1f} ms, signed '
                  f'{al["signed_ms"]:6.1f} ms, distance at 0 {al["dist0_mm"]:5.1f} mm, '
                  f'+1 frame {al["step_mm"]:+5.2f} mm, velocity x-corr vs truth {al["xcorr_ms"]:5.1f} ms, jitter '
                  f'{al["jitter_ms2"]:5.2f} m/s2 | ' + ' '.join(
                      f'{sc}: {v["one_sided_ms"]:.1f}/{v["signed_ms"]:.1f}/{v["xcorr_ms"]:.1f}'
                      for sc, v in r.items() if sc != 'all'), flush=True)
    if a.json:
        with open(a.json, 'w') as fh:
            json.dump(json_safe(res), fh, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
