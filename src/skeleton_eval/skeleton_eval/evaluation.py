"""Evaluation harness: run reconstruction methods on sensor-model streams and score them.

* :func:`run_method` feeds one stream through one method (a :class:`~.registry.Method`);
  :func:`evaluate_streams` every method on every stream, with the metrics (:mod:`.metrics`), the
  "no harm" sums (:mod:`.no_harm`), the added latency and the processing time per class.
* :func:`evaluate` — Shum et al. 2013 Table IV: every method on the scenario classes, Eq. 18 error
  and more, with the sensor model's noise statistics.

The other experiments build on these: :mod:`.table3` (joint subsets, Table III), :mod:`.figures`
(Fig. 5 and Fig. 8); the methods come from :mod:`.registry`, the clips from :mod:`.clips`, and
:mod:`.report` writes the results as JSON and Markdown.
"""
from __future__ import annotations

import os
import platform
import time
from typing import Callable, Dict, Iterable, List, Optional

import numpy as np

from . import metrics as M
from . import no_harm as NH
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS
from .registry import Method, make_method, method_info
from .sensor_model import SensorModel
from .sensor_statistics import statistics
from .sensor_stream import KinectStream

FRAME_ID = 'kinect_depth'


def stream_frames(stream: KinectStream, user_id: int = 1) -> Iterable[SkeletonFrame]:
    for i in range(len(stream)):
        yield SkeletonFrame(positions=stream.positions[i].copy(),
                            tracking_state=stream.tracking_state[i].copy(),
                            user_id=user_id, stamp_ns=int(stream.stamps_ns[i]), frame_id=FRAME_ID)


def run_method(method: Method, stream: KinectStream, frames: Optional[Iterable[SkeletonFrame]] = None,
               warmup: Optional[Iterable[SkeletonFrame]] = None):
    """Feed a stream through a method: (positions (T,20,3) with NaN for missing, times_ms (T,)).
    ``warmup``: frames fed after ``reset()`` and before the stream (e.g. a calibration segment);
    their outputs and times are discarded."""
    method.reset()
    for f in (warmup or ()):
        method.process(f)
    frames = stream_frames(stream) if frames is None else frames
    out = np.full((len(stream), NUM_JOINTS, 3), np.nan)
    times = np.empty(len(stream))
    for i, f in enumerate(frames):
        t0 = time.perf_counter()
        r = method.process(f)
        times[i] = (time.perf_counter() - t0) * 1e3
        if r is not None:
            p = np.asarray(r.positions, float)
            if p.shape == (NUM_JOINTS, 3):
                out[i] = p
    return out, times


def _combine(parts: List[Dict], weights: List[int]) -> Dict:
    """Frame-weighted NaN-aware average of compute_all() results."""
    out = {}
    for name in parts[0]:
        per = np.array([p[name]['per_joint'] for p in parts], float)
        tot = np.array([p[name]['overall'] for p in parts], float)
        w = np.asarray(weights, float)[:, None]
        ok = np.isfinite(per)
        with np.errstate(invalid='ignore'):
            pj = np.where(ok, per, 0).__mul__(w).sum(0) / np.where(ok, w, 0).sum(0)
        okt = np.isfinite(tot)
        ov = float((tot[okt] * w[okt, 0]).sum() / w[okt, 0].sum()) if okt.any() else float('nan')
        out[name] = {'per_joint': [float(v) for v in pj], 'overall': ov}
    return out


def _time_summary(times: np.ndarray) -> Dict:
    if len(times) == 0:
        return {'mean_ms': float('nan'), 'p50_ms': float('nan'), 'p95_ms': float('nan')}
    return {'mean_ms': float(np.mean(times)), 'p50_ms': float(np.percentile(times, 50)),
            'p95_ms': float(np.percentile(times, 95)), 'max_ms': float(np.max(times))}


def _method_list(methods) -> List[tuple]:
    """Normalise ``methods`` to [(label, factory)]: names, (name, params) pairs or factories."""
    out = []
    for m in methods:
        if isinstance(m, str):
            out.append((m, (lambda n=m: make_method(n)), method_info(m)['defaults']))
        elif isinstance(m, tuple):
            name, params = m[0], dict(m[1])
            label = m[2] if len(m) > 2 else name
            out.append((label, (lambda n=name, p=params: make_method(n, **p)),
                        {**method_info(name)['defaults'], **params}))
        elif callable(m):
            label = getattr(m, 'name', None)
            if not isinstance(label, str) or not label:
                label = getattr(m(), 'name', None) or getattr(m, '__name__', 'method')
            out.append((label, m, dict(getattr(m, 'params', {}) or {})))
        else:
            raise TypeError(f'cannot use {m!r} as a method')
    return out


def make_streams(clips, scenarios=('a', 'b', 'c'), seed: int = 0,
                 max_frames: Optional[int] = None, sensor: Optional[SensorModel] = None,
                 repeats: int = 1) -> Dict[str, List[KinectStream]]:
    """Sensor-model streams per scenario; ``repeats`` > 1 runs every clip again with independent
    noise and events (seeds ``seed``, ``seed + 1``, ...), for more events from short clips."""
    sensor = SensorModel(seed=seed) if sensor is None else sensor
    return {sc: [sensor.corrupt(c, sc, seed=seed + r, max_frames=max_frames)
                 for r in range(max(1, int(repeats))) for c in clips]
            for sc in scenarios}


def reliable_latency_curve(out: np.ndarray, stream: KinectStream):
    """:func:`metrics.latency_curve` of the latency a method adds on the joints the sensor
    reported correctly: the delay of ``out`` behind the raw input (the shift that fits best)
    over the joint-frames the sensor model marks clean (no occlusion, false positive, turn or
    confident failure), the others left out. Root-relative (both less their root joint): the
    smoothing's delay, not where a method puts an occluded root (in class c the table hides
    the hips and the raw root is a stale INFERRED position; such frames are left out). The curves of a class's streams
    are added before the best shift is taken (short, slow clips alone have no clear minimum)."""
    raw = np.array(stream.positions, float)
    raw -= raw[:, :1]
    if stream.clean is not None:
        raw[~stream.clean] = np.nan
        raw[~stream.clean[:, 0]] = np.nan   # relative to a wrong root: the whole frame
    rel = np.asarray(out, float) - np.asarray(out, float)[:, :1]
    return M.latency_curve(rel, raw)


def reliable_xcorr(out: np.ndarray, stream: KinectStream) -> np.ndarray:
    """:func:`metrics.velocity_xcorr` of ``out`` against the true motion on the joint-frames the
    sensor model marks clean (root-relative, as :func:`reliable_latency_curve`): the delay read
    from it (:func:`metrics.xcorr_latency_ms`) resolves less than a frame and is signed, and is
    blind to the offsets between output and input that flatten the one-sided curve."""
    raw = np.array(stream.positions, float)
    raw -= raw[:, :1]
    mask = np.isfinite(raw).all(-1)
    if stream.clean is not None:
        mask &= stream.clean & stream.clean[:, :1]
    rel = np.asarray(out, float) - np.asarray(out, float)[:, :1]
    tru = np.array(stream.truth, float)
    tru -= tru[:, :1]
    return M.velocity_xcorr(rel, tru, M.MAX_LATENCY_FRAMES, mask)


def evaluate_streams(methods, streams: Dict[str, List[KinectStream]],
                     frame_transform: Optional[Callable] = None, progress=None,
                     warmup: Optional[Callable] = None) -> Dict:
    """Run every method on every stream; per method x scenario: metrics and processing time.
    ``frame_transform(stream)``: the frames to feed instead of the stream's own; ``warmup(stream)``:
    unscored frames fed before them (see :func:`run_method`)."""
    results: Dict[str, Dict] = {}
    params: Dict[str, Dict] = {}
    for label, factory, p in _method_list(methods):
        params[label] = p
        method = factory()
        results[label] = {}
        for sc, lst in streams.items():
            parts, weights, times, missing, lats = [], [], [], 0, []
            nh = NH.empty()
            xc = np.zeros(2 * M.MAX_LATENCY_FRAMES + 1)
            xc_raw = np.zeros(2 * M.MAX_LATENCY_FRAMES + 1)
            for s in lst:
                frames = None if frame_transform is None else frame_transform(s)
                out, t = run_method(method, s, frames,
                                    None if warmup is None else warmup(s))
                missing += int(np.isnan(out).any(axis=(1, 2)).sum())
                parts.append(M.compute_all(out, s.truth, s.fps))
                NH.add(nh, *NH.direction_sums(out, s.truth,
                                              NH.segment_mask(s.tracking_state, s.clean)))
                lats.append(reliable_latency_curve(out, s))
                xc += reliable_xcorr(out, s)
                xc_raw += reliable_xcorr(s.positions, s)
                weights.append(len(s))
                times.append(t)
                if progress:
                    progress(label, sc, s.clip_name)
            results[label][sc] = {'frames': int(sum(weights)), 'missing_frames': missing,
                                  'metrics': _combine(parts, weights),
                                  'no_harm': nh,
                                  'latency_ms': (M.xcorr_latency_ms(xc, lst[0].fps)
                                                 - M.xcorr_latency_ms(xc_raw, lst[0].fps))
                                  if lats else float('nan'),
                                  'latency_one_sided_ms': M.latency_from_curve(
                                      sum(c[0] for c in lats), sum(c[1] for c in lats),
                                      lst[0].fps) if lats else float('nan'),
                                  'time': _time_summary(np.concatenate(times) if times else
                                                        np.zeros(0))}
    return {'results': results, 'method_params': params}


def run_meta(clips, seed, sensor: SensorModel, max_frames, data_source, extra=None) -> Dict:
    return {
        'data': {'source': data_source,
                 'clips': [{'name': c.name, 'class': getattr(c, 'motion_class', ''),
                            'frames': len(c.positions), 'fps': float(c.fps)} for c in clips]},
        'seed': seed, 'max_frames_per_clip': max_frames,
        'sensor_params': sensor.params,
        'machine': f'{platform.machine()} {platform.python_implementation()} '
                   f'{platform.python_version()}, {os.cpu_count()} CPUs (shared; timings indicative)',
        'date_utc': time.strftime('%Y-%m-%d %H:%M:%S', time.gmtime()),
        **(extra or {}),
    }


def evaluate(methods, clips, scenarios=('a', 'b', 'c'), seed: int = 0,
             max_frames: Optional[int] = None, sensor_params=None, data_source: str = '',
             progress=None, repeats: int = 1) -> Dict:
    """Table IV style evaluation. ``methods``: names, (name, params[, label]) or factories."""
    sensor = SensorModel(sensor_params, seed=seed)
    streams = make_streams(clips, scenarios, seed, max_frames, sensor, repeats)
    res = evaluate_streams(methods, streams, progress=progress)
    res['experiment'] = 'table4'
    res['meta'] = run_meta(clips, seed, sensor, max_frames, data_source,
                           {'scenarios': list(scenarios), 'repeats': int(repeats)})
    res['sensor_statistics'] = statistics([s for lst in streams.values() for s in lst])
    return res


