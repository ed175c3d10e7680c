"""Evaluation harness: run reconstruction methods on sensor-model streams and tabulate accuracy.

Plug-in interface
-----------------
A method is any object with ``name``, ``reset()`` and ``process(frame: SkeletonFrame) ->
SkeletonFrame`` (streaming, one user, frames in the sensor frame as the driver publishes them;
returning ``None`` means "no output yet" and counts as a missing frame). Factories are registered with
:func:`register_method` (``factory(**params) -> Method``); :func:`available_methods` lists them.
Registered here: ``raw`` (the Kinect skeleton as is), ``holt`` (Kinect SDK v1 joint filter) and
``one_euro``. ``pose_reconstruction.methods`` registers A, B, C and ``physics_sim.methods`` its
physics variants when imported (:func:`load_plugins`).

Experiments (Shum et al. 2013 Sec. VIII, Shum & Ho 2012 Sec. 8.4)
-----------------------------------------------------------------
* :func:`evaluate` / Table IV — every method on scenario classes a-c, Eq. 18 error and more.
* :func:`table3` — reconstruction from joint subsets (a) left hand + foot ... (e) all parts: the
  other joints are NOT_TRACKED (reliability 0, frozen at the first frame) on a noise-only stream.
  ``calibration='tpose'`` (the paper's protocol: a calibrated user) first shows each method a
  short, unscored segment of the same user standing in a T-pose (or ``'standing'``, arms down)
  with every joint tracked; ``'none'`` hides the other joints from the very first frame.
* :func:`fig5` — PCA dimensions 1..60 vs nearest-posture matching error (Shum & Ho Eq. 5-6) and
  search time, on the motion database.
* :func:`fig8` — a method's error and frame time vs one parameter (database size, K, PCA
  dimensions, optimisation steps, samples), through factory keyword overrides.
"""
from __future__ import annotations

import importlib
import json
import os
import platform
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Dict, Iterable, List, Optional, Protocol, Sequence, runtime_checkable

import numpy as np

from . import metrics as M
from . import no_harm as NH
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.filters import HOLT_DEFAULTS, ONE_EURO_DEFAULTS, HoltFilter, OneEuroFilter
from skeleton_core.model import (ELBOW_LEFT, ELBOW_RIGHT, FOOT_LEFT, FOOT_RIGHT, HAND_LEFT,
                    HAND_RIGHT, JOINT_NAMES, KNEE_LEFT, KNEE_RIGHT, NOT_TRACKED, NUM_JOINTS,
                    TRACKED, standard_body)
from .sensor_model import KinectStream, SensorModel, format_statistics, statistics
from skeleton_data.motions import builtin_split
from skeleton_data.mocap import MotionClip
from skeleton_core.model import (ELBOW_LEFT as EL, ELBOW_RIGHT as ER, SHOULDER_LEFT as SL,
                                 SHOULDER_RIGHT as SR, WRIST_LEFT as WL, WRIST_RIGHT as WR)
from skeleton_core.geometry import normalize, retarget

FRAME_ID = 'kinect_depth'


# ------------------------------------------------------------------------------------------
# Plug-in interface and registry
# ------------------------------------------------------------------------------------------
@runtime_checkable
class Method(Protocol):
    name: str

    def reset(self) -> None: ...

    def process(self, frame: SkeletonFrame) -> Optional[SkeletonFrame]: ...


@dataclass
class _Entry:
    factory: Callable[..., Method]
    description: str
    defaults: Dict


_REGISTRY: Dict[str, _Entry] = {}


def register_method(name: str, factory: Callable[..., Method], description: str = '',
                    defaults: Optional[Dict] = None) -> None:
    """Register (or replace) a method factory under ``name``."""
    if not name or not callable(factory):
        raise ValueError('register_method needs a name and a callable factory')
    _REGISTRY[name] = _Entry(factory, description, dict(defaults or {}))


def available_methods() -> List[str]:
    return list(_REGISTRY)


def method_info(name: str) -> Dict:
    e = _REGISTRY[name]
    return {'description': e.description, 'defaults': e.defaults}


def make_method(name: str, **params) -> Method:
    if name not in _REGISTRY:
        raise KeyError(f'unknown method {name!r}; available: {", ".join(available_methods())}')
    return _REGISTRY[name].factory(**params)


PLUGIN_MODULES = ('pose_reconstruction.methods', 'physics_sim.methods')


def load_plugins(modules: Sequence[str] = PLUGIN_MODULES) -> Dict[str, str]:
    """Import plug-in modules that register methods; returns {module: 'ok' | reason skipped}."""
    status = {}
    for mod in modules:
        try:
            importlib.import_module(mod)
            status[mod] = 'ok'
        except ImportError as exc:
            status[mod] = f'skipped ({exc})'
        except Exception as exc:  # a broken plug-in must not take the harness down
            status[mod] = f'failed ({type(exc).__name__}: {exc})'
    return status


class RawMethod:
    """The Kinect skeleton unchanged."""

    name = 'raw'

    def reset(self):
        pass

    def process(self, frame: SkeletonFrame) -> SkeletonFrame:
        return frame


class HoltMethod:
    """Kinect SDK v1 double exponential joint filter (filters.HoltFilter)."""

    name = 'holt'

    def __init__(self, **params):
        self.params = {**HOLT_DEFAULTS, **params}
        self.filter = HoltFilter(**self.params)

    def reset(self):
        self.filter.reset()

    def process(self, frame: SkeletonFrame) -> SkeletonFrame:
        return frame.copy(positions=self.filter.update(frame.positions, frame.tracking_state))


class OneEuroMethod:
    """One Euro filter per joint (filters.OneEuroFilter)."""

    name = 'one_euro'

    def __init__(self, **params):
        self.params = {**ONE_EURO_DEFAULTS, **params}
        self.filter = OneEuroFilter(**self.params)

    def reset(self):
        self.filter.reset()

    def process(self, frame: SkeletonFrame) -> SkeletonFrame:
        return frame.copy(positions=self.filter.update(frame.positions, frame.tracking_state,
                                                       frame.stamp_ns))


register_method('raw', RawMethod, 'Kinect skeleton as reported (no processing)')
register_method('holt', HoltMethod, 'Kinect SDK v1 joint filter (Holt double exponential)',
                HOLT_DEFAULTS)
register_method('one_euro', OneEuroMethod, 'One Euro filter (Casiez et al. 2012)',
                ONE_EURO_DEFAULTS)


# ------------------------------------------------------------------------------------------
# Clips
# ------------------------------------------------------------------------------------------
def shared_dir() -> Path:
    env = os.environ.get('KP_SHARED')
    if env:
        return Path(env)
    here = Path(__file__).resolve()
    for parent in here.parents:
        if (parent / 'src').is_dir() and (parent.parent / 'shared').is_dir():
            return parent.parent / 'shared'
    return Path('/nonexistent-shared')


def load_clips(source: str = 'auto', seed: int = 0):
    """(database_clips, dev_clips, source_used) from CMU (``../shared/mocap/cmu``) or built-ins."""
    if source not in ('auto', 'cmu', 'builtin'):
        raise ValueError(f"source must be auto, cmu or builtin, got {source!r}")
    cmu = shared_dir() / 'mocap' / 'cmu'
    if source in ('auto', 'cmu') and cmu.is_dir():
        from skeleton_data.mocap import cmu_split
        db, dev = cmu_split(cmu)
        return db, dev, f'cmu:{cmu}'
    if source == 'cmu':
        raise FileNotFoundError(f'no CMU mocap at {cmu}')
    db, dev = builtin_split(seed)
    return db, dev, f'builtin:seed={seed}'


def toy_clip(seconds: float = 10.0, fps: float = 30.0, name: str = 'toy_arm_swing'):
    """The standard body standing with both arms swinging up and down (for tests and smoke runs)."""
    body = standard_body()
    rest = body.rest_positions()
    n = int(round(seconds * fps))
    t = np.arange(n) / fps
    pos = np.repeat(rest[None], n, axis=0)
    for sh, chain, sign in ((SL, (EL, WL, HAND_LEFT), 1.0), (SR, (ER, WR, HAND_RIGHT), -1.0)):
        elev = -1.1 + 0.7 * np.sin(2 * np.pi * 0.4 * t + (0.0 if sign > 0 else np.pi))
        fwd = 0.3 * (1 + np.sin(2 * np.pi * 0.25 * t))
        d = np.stack([np.sin(fwd) * np.cos(elev), sign * np.cos(fwd) * np.cos(elev),
                      np.sin(elev)], axis=1)
        for j in chain:
            r = np.linalg.norm(rest[j] - rest[sh])
            pos[:, j] = rest[sh] + r * d
    quats = np.zeros((n, NUM_JOINTS, 4))
    quats[..., 3] = 1.0
    return MotionClip(name=name, motion_class='test', fps=fps, positions=pos, orientations=quats,
                      source='evaluation.toy_clip')


# ------------------------------------------------------------------------------------------
# Running methods
# ------------------------------------------------------------------------------------------
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


def _meta(clips, seed, sensor: SensorModel, max_frames, data_source, extra=None) -> Dict:
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
    res['meta'] = _meta(clips, seed, sensor, max_frames, data_source,
                        {'scenarios': list(scenarios), 'repeats': int(repeats)})
    res['sensor_statistics'] = statistics([s for lst in streams.values() for s in lst])
    return res


# ------------------------------------------------------------------------------------------
# Table III: joint subsets
# ------------------------------------------------------------------------------------------
TABLE3_SUBSETS = {
    'a': ('Left Hand, Left Foot', (HAND_LEFT, FOOT_LEFT)),
    'b': ('Hands', (HAND_LEFT, HAND_RIGHT)),
    'c': ('Hands, Feet', (HAND_LEFT, HAND_RIGHT, FOOT_LEFT, FOOT_RIGHT)),
    'd': ('Hands, Feet, Elbows, Knees', (HAND_LEFT, HAND_RIGHT, FOOT_LEFT, FOOT_RIGHT, ELBOW_LEFT,
                                         ELBOW_RIGHT, KNEE_LEFT, KNEE_RIGHT)),
    'e': ('All Parts', tuple(range(NUM_JOINTS))),
}


def subset_frames(stream: KinectStream, joints: Sequence[int]) -> List[SkeletonFrame]:
    """Frames where only ``joints`` are TRACKED (reliability 1); the others are NOT_TRACKED,
    reliability 0 and frozen at their first-frame position."""
    keep = np.zeros(NUM_JOINTS, bool)
    keep[list(joints)] = True
    frames = []
    for f in stream_frames(stream):
        f.positions[~keep] = stream.positions[0][~keep]
        f.tracking_state[~keep] = NOT_TRACKED
        f.tracking_state[keep] = TRACKED
        f.reliability = np.where(keep, 1.0, 0.0).astype(np.float32)
        frames.append(f)
    return frames


CALIBRATIONS = ('tpose', 'standing', 'none')
CALIBRATION_SECONDS = 1.0


def calibration_pose(clip, pose: str = 'tpose', cmu_dir=None):
    """The clip's own user standing in a calibration pose, in the clip's world frame (REP-103,
    floor at z = 0): ``(positions (20, 3), description)``.

    * CMU clips (``source`` 'cmu:<file>'): frame 0 of the cgspeed BVH file, a synthetic T-pose of
      that subject (``mocap.load_cmu_clip`` drops it from the motion);
    * built-in motions (``source`` 'builtin:...'): the T-pose of the standard body they are
      driven on;
    * any other clip: the standard body's T-pose at the height of the clip's first frame.

    ``pose='standing'``: the same skeleton with both arms hanging straight down from the
    shoulders (the reliability estimator's second reference posture)."""
    from skeleton_core.model import (ELBOW_LEFT as EL, ELBOW_RIGHT as ER, SHOULDER_LEFT as SL,
                        SHOULDER_RIGHT as SR, WRIST_LEFT as WL, WRIST_RIGHT as WR, estimate_height)
    if pose not in ('tpose', 'standing'):
        raise ValueError(f"calibration pose must be 'tpose' or 'standing', got {pose!r}")
    src = str(getattr(clip, 'source', '') or '')
    p = None
    if src.startswith('cmu:'):
        from skeleton_data.mocap import load_cmu_clip
        folder = Path(cmu_dir) if cmu_dir is not None else shared_dir() / 'mocap' / 'cmu'
        path = folder / src[4:]
        if path.is_file():
            full = load_cmu_clip(path, getattr(clip, 'motion_class', None), drop_first=False)
            p, desc = full.positions[0].copy(), f'{path.name} frame 0 (BVH T-pose)'
    if p is None and src.startswith('builtin:'):
        p, desc = standard_body().rest_positions(), 'standard body T-pose (built-in motions)'
    if p is None:
        h = float(np.clip(estimate_height(np.asarray(clip.positions[0], float)), 1.0, 2.4))
        p, desc = standard_body(h).rest_positions(), f'standard body T-pose at {h:.2f} m'
    if pose == 'standing':
        p = p.copy()
        for chain in ((SL, EL, WL, HAND_LEFT), (SR, ER, WR, HAND_RIGHT)):
            lengths = [np.linalg.norm(p[b] - p[a]) for a, b in zip(chain[:-1], chain[1:])]
            for a, b, length in zip(chain[:-1], chain[1:], lengths):
                p[b] = p[a] + (0.0, 0.0, -length)
        desc += ', arms down'
    return p, desc


def calibration_stream(sensor: SensorModel, clip, pose: str = 'tpose', seed: int = 0,
                       seconds: float = CALIBRATION_SECONDS, cmu_dir=None,
                       start_ns: int = 0) -> KinectStream:
    """``seconds`` of the clip's user standing still in :func:`calibration_pose`, through the
    sensor model's 'clean' path (same placement and noise model as the clip's stream). It is the
    same session as ``sensor.corrupt(clip, 'clean', seed)``: the same systematic joint-centre
    offsets, with independent jitter and drift. Stamps end one frame before ``start_ns``."""
    pos, desc = calibration_pose(clip, pose, cmu_dir)
    fps = sensor.fps
    n = max(1, int(round(float(seconds) * fps)))
    quats = np.zeros((n, NUM_JOINTS, 4))
    quats[..., 3] = 1.0
    cal = MotionClip(name=str(getattr(clip, 'name', '')), motion_class='calibration', fps=fps,
                     positions=np.repeat(pos[None], n, axis=0), orientations=quats,
                     source=desc)
    cs = sensor.corrupt(cal, 'clean', seed, seed_tag=f'clean/calibration/{pose}',
                        sys_offset=sensor.session_offsets(clip, 'clean', seed))
    stamps = start_ns - np.round(np.arange(n, 0, -1) * 1e9 / fps).astype(np.int64)
    return replace(cs, stamps_ns=stamps, clip_name=f'{cal.name} ({desc})')


def calibration_frames(stream: KinectStream) -> List[SkeletonFrame]:
    """A calibration stream as frames with every joint TRACKED and reliability 1."""
    frames = []
    for f in stream_frames(stream):
        f.tracking_state[:] = TRACKED
        f.reliability = np.ones(NUM_JOINTS, np.float32)
        frames.append(f)
    return frames


def table3(methods, clips, seed: int = 0, max_frames: Optional[int] = None, sensor_params=None,
           data_source: str = '', subsets=tuple(TABLE3_SUBSETS), progress=None,
           repeats: int = 1, reference: str = 'input', calibration: str = 'tpose',
           calibration_seconds: float = CALIBRATION_SECONDS, cmu_dir=None) -> Dict:
    """Shum 2013 Table III: each method given only a subset of joints of a noise-only ('clean')
    stream. ``reference='input'`` (the paper's choice) scores against the full input skeleton,
    ``'truth'`` against the true motion. Results keyed by subset letter instead of scenario.

    ``calibration``: 'tpose' / 'standing' — before each clip's subset frames the method sees
    ``calibration_seconds`` of the same user in that pose with every joint tracked
    (:func:`calibration_stream`, not scored; the subset frames are the same as without it), as
    a user calibrated at the start of a session (the paper's protocol); 'none' — no calibration,
    the other joints are hidden from the first frame."""
    if reference not in ('input', 'truth'):
        raise ValueError("reference must be 'input' or 'truth'")
    if calibration not in CALIBRATIONS:
        raise ValueError(f'calibration must be one of {CALIBRATIONS}, got {calibration!r}')
    if calibration != 'none' and not float(calibration_seconds) > 0:
        raise ValueError('calibration_seconds must be > 0')
    sensor = SensorModel(sensor_params, seed=seed)
    base = make_streams(clips, ('clean',), seed, max_frames, sensor, repeats)['clean']
    if reference == 'input':
        base = [replace(s, truth=s.positions.copy()) for s in base]
    warmup = None
    cal_meta: Dict = {'pose': calibration, 'seconds': 0.0, 'frames': 0, 'scored': False}
    if calibration != 'none':
        # the same order as make_streams: repeats outer, clips inner
        pairs = [(c, seed + r) for r in range(max(1, int(repeats))) for c in clips]
        cal_streams = [calibration_stream(sensor, c, calibration, sd, calibration_seconds,
                                          cmu_dir, int(s.stamps_ns[0]))
                       for s, (c, sd) in zip(base, pairs)]
        cal = {id(s): calibration_frames(cs) for s, cs in zip(base, cal_streams)}
        cal_meta.update(seconds=float(calibration_seconds),
                        frames=len(cal_streams[0]) if cal_streams else 0,
                        sources=sorted({cs.clip_name for cs in cal_streams}))

        def warmup(s, cal=cal):
            return [f.copy() for f in cal[id(s)]]
    results: Dict = {}
    params: Dict = {}
    for key in subsets:
        label, joints = TABLE3_SUBSETS[key]
        r = evaluate_streams(methods, {key: base},
                             frame_transform=lambda s, j=joints: subset_frames(s, j),
                             progress=progress, warmup=warmup)
        params.update(r['method_params'])
        for m, v in r['results'].items():
            results.setdefault(m, {})[key] = v[key]
    return {'experiment': 'table3', 'results': results, 'method_params': params,
            'reference': reference, 'calibration': cal_meta,
            'subsets': {k: {'parts': TABLE3_SUBSETS[k][0],
                            'joints': [JOINT_NAMES[j] for j in TABLE3_SUBSETS[k][1]]}
                        for k in subsets},
            'meta': _meta(clips, seed, sensor, max_frames, data_source,
                          {'scenarios': ['clean'], 'calibration': cal_meta})}


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


# ------------------------------------------------------------------------------------------
# Fig. 5 (Shum & Ho 2012 Sec. 8.4): PCA dimensions vs matching error and search time
# ------------------------------------------------------------------------------------------
def _database_postures(database=None, clips=None) -> np.ndarray:
    """(N, 20, 3) normalised postures of a MotionDatabase (several attribute names tried) or of
    clips (normalised and retargeted to the standard body here, as the database does)."""
    if database is not None:
        for attr in ('positions', 'postures', 'normalized_positions', 'poses'):
            arr = getattr(database, attr, None)
            if arr is not None:
                arr = np.asarray(arr, float)
                if arr.ndim == 2 and arr.shape[1] == 3 * NUM_JOINTS:
                    arr = arr.reshape(-1, NUM_JOINTS, 3)
                if arr.ndim == 3 and arr.shape[1:] == (NUM_JOINTS, 3):
                    return arr
    if clips is None:
        raise ValueError('fig5 needs a database with a positions array or clips')
    pos = np.concatenate([np.asarray(c.positions, float) for c in clips])
    return retarget(normalize(pos)[0], standard_body())


def fig5(database_postures: np.ndarray, query_postures: np.ndarray,
         dims: Sequence[int] = tuple(range(1, 61)), repeats: int = 3) -> Dict:
    """Shum & Ho 2012 Eq. 5-6: nearest database posture found in r PCA dimensions; the full-space
    squared error of the match e_r, its excess over the 60-D match in %, and the search time."""
    db = np.asarray(database_postures, float).reshape(len(database_postures), -1)
    q = np.asarray(query_postures, float).reshape(len(query_postures), -1)
    mean = db.mean(axis=0)
    _, _, vt = np.linalg.svd(db - mean, full_matrices=False)
    full_dim = db.shape[1]
    rows = []
    errs = {}
    for r in sorted(set(int(d) for d in dims if 1 <= d <= full_dim)):
        basis = vt[:r].T
        dbr = (db - mean) @ basis
        best_t = np.inf
        for _ in range(max(1, repeats)):
            t0 = time.perf_counter()
            qr = (q - mean) @ basis
            d2 = (qr ** 2).sum(1)[:, None] - 2 * qr @ dbr.T + (dbr ** 2).sum(1)[None]
            idx = np.argmin(d2, axis=1)
            best_t = min(best_t, time.perf_counter() - t0)
        e = ((q - db[idx]) ** 2).sum(axis=1)  # Eq. 5 (squared error in the full space)
        errs[r] = e
        rows.append({'dims': r, 'error_m2': float(e.mean()),
                     'search_ms_per_query': best_t * 1e3 / len(q)})
    e_full = errs[max(errs)].sum()
    for row in rows:
        row['error_pct'] = float((errs[row['dims']].sum() - e_full) / max(e_full, 1e-12) * 100)
    return {'experiment': 'fig5', 'rows': rows, 'database_size': len(db), 'queries': len(q)}


# ------------------------------------------------------------------------------------------
# Fig. 8: parameter sweeps
# ------------------------------------------------------------------------------------------
FIG8_SWEEPS = {
    'db_size': (250, 500, 1000, 2000, 4000),
    'k': (5, 10, 20, 30, 50, 80),
    'pca_dims': (2, 5, 10, 15, 20, 30, 40),
    'steps': (1, 5, 10, 20, 30, 40),
    'samples': (10, 25, 50, 100, 200),
}


def fig8(method: str, clips, params: Sequence[str] = tuple(FIG8_SWEEPS), seed: int = 0,
         max_frames: Optional[int] = 300, scenario: str = 'a', sensor_params=None,
         sweeps: Optional[Dict] = None, data_source: str = '', progress=None) -> Dict:
    """Error (Eq. 18) and frame time of ``method`` as each parameter varies (others at defaults).
    A value the factory rejects (TypeError/ValueError) is recorded as skipped with the reason."""
    sweeps = {**FIG8_SWEEPS, **(sweeps or {})}
    sensor = SensorModel(sensor_params, seed=seed)
    streams = make_streams(clips, (scenario,), seed, max_frames, sensor)
    out: Dict[str, List] = {}
    for param in params:
        rows = []
        for v in sweeps[param]:
            try:
                make_method(method, **{param: v})
            except (TypeError, ValueError) as exc:
                rows.append({'value': v, 'skipped': str(exc)})
                continue
            r = evaluate_streams([(method, {param: v})], streams, progress=progress)
            res = r['results'][method][scenario]
            rows.append({'value': v, 'eq18_cm': res['metrics']['eq18_cm']['overall'],
                         'mpjpe_cm': res['metrics']['mpjpe_cm']['overall'],
                         'frame_ms': res['time']['mean_ms']})
        out[param] = rows
    return {'experiment': 'fig8', 'method': method, 'scenario': scenario, 'sweeps': out,
            'meta': _meta(clips, seed, sensor, max_frames, data_source)}


# ------------------------------------------------------------------------------------------
# Reports
# ------------------------------------------------------------------------------------------
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
