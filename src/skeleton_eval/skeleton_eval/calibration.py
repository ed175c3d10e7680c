"""Sensor-model calibration against the real UI-PRMD Kinect recordings.

``ros2 run skeleton_eval import_uiprmd --src ../shared/kinect/ui-prmd --calibrate`` measures, on the
real Kinect streams:

* **high-frequency jitter** per joint: RMS (per axis) of the trajectory minus its own
  Savitzky-Golay smoothing (9 frames, order 2, at 30 Hz) — reference-free;
* **random error** per joint against the marker reference: std of (Kinect - reference) about its
  per-clip mean, RMS over axes (the definition of ``sensor_statistics.statistics()['jitter_mm']``; on
  real data it also holds pose-dependent joint-centre differences, so it is an upper bound);
* **systematic offset** per joint: RMS over clips of the per-clip mean error, per axis (as
  ``offset_mm``), and the mean offset vector per session in the sensor frame (x towards the
  sensor's view direction, i.e. into the body; y the sensor's left; z up);
* **bone-length variation** per segment: std of the length within a clip (pooled, as
  ``bone_length_std_mm``) and RMS of the frame-to-frame length change;
* **tracking failures**: the fraction of frames whose core segments (no hands/feet) deviate more
  than ``FAIL_REL`` (and more than ``FAIL_ABS``) from the subject's median lengths (the median
  over the subject's other clips),
  per movement, with m03_s01 (the known failure) separately.

and puts the same quantities computed on synthetic streams next to them: the marker reference of
the same clips (the true motion) run through :class:`skeleton_eval.sensor_model.SensorModel`
('clean' scenario, unoccluded) — same motion, same measuring code, so the comparison is like for
like. Hands are excluded (not in the recordings).
"""
from __future__ import annotations

import copy
import json
from pathlib import Path
from types import SimpleNamespace
from typing import Dict, List, Optional, Sequence

import numpy as np
from scipy.signal import savgol_filter

from skeleton_core.geometry import retarget
from skeleton_data.vicon import load_reference, vicon_path_for
from skeleton_core.model import (HAND_LEFT, HAND_RIGHT, JOINT_NAMES, NUM_JOINTS, SEGMENT_CHILDREN,
                                 SEGMENT_NAMES, segment_lengths, standard_body)
from .sensor_model import SensorModel
from .sensor_params import JOINT_GROUP
from .sensor_statistics import statistics as model_statistics

SG_WINDOW, SG_ORDER = 9, 2
FAIL_REL = 0.25
FAIL_ABS = 0.05  # m: short segments (hips) must also be this far off
TOLERANCE = 0.30  # model within +-30 % of real
HAND_JOINTS = (HAND_LEFT, HAND_RIGHT)
COMPARE_JOINTS = tuple(j for j in range(NUM_JOINTS) if j not in HAND_JOINTS)
COMPARE_SEGMENTS = tuple(k for k, c in enumerate(SEGMENT_CHILDREN) if c not in HAND_JOINTS)
CORE_SEGMENTS = tuple(k for k, n in enumerate(SEGMENT_NAMES)
                      if not any(x in n.split('-')[1] for x in ('Hand', 'Foot')))


# ------------------------------------------------------------------------------------------
# Measurements (same code for real and synthetic streams)
# ------------------------------------------------------------------------------------------
def hf_residual(positions: np.ndarray) -> np.ndarray:
    """Trajectory minus its Savitzky-Golay smoothing, (T, J, 3); NaN rows when T < window."""
    p = np.asarray(positions, dtype=float)
    if len(p) < SG_WINDOW:
        return np.full_like(p, np.nan)
    return p - savgol_filter(p, SG_WINDOW, SG_ORDER, axis=0)


class _Acc:
    """Pooled sums for per-joint / per-segment statistics over many clips."""

    def __init__(self, n):
        self.s = np.zeros(n)
        self.n = np.zeros(n)

    def add(self, sq_sum, count):
        sq_sum = np.nan_to_num(np.asarray(sq_sum, float))
        self.s += sq_sum
        self.n += count

    def rms(self):
        with np.errstate(invalid='ignore', divide='ignore'):
            return np.where(self.n > 0, np.sqrt(self.s / np.maximum(self.n, 1)), np.nan)


def measure(streams: Sequence[np.ndarray], references: Optional[Sequence[np.ndarray]] = None,
            groups: Optional[Sequence[str]] = None) -> Dict[str, np.ndarray]:
    """Noise measurements of a set of (T, 20, 3) streams (m), optionally against references
    (same shape, NaN where missing). Returns arrays in mm (see module docstring). ``groups`` (a
    session key per stream) adds ``offset_clip_mm``: RMS per axis of the per-clip mean error about
    its session's mean (the part of the systematic offset that changes from clip to clip, as the
    model draws it per stream)."""
    means: Dict[str, List[np.ndarray]] = {}
    hf = _Acc(NUM_JOINTS)
    hfx = _Acc(NUM_JOINTS)
    hfyz = _Acc(NUM_JOINTS)
    rnd = _Acc(NUM_JOINTS)
    off = _Acc(NUM_JOINTS)
    bl = _Acc(len(SEGMENT_CHILDREN))
    f2f = _Acc(len(SEGMENT_CHILDREN))
    for i, p in enumerate(streams):
        r = hf_residual(p)
        ok = np.isfinite(r).all(axis=(1, 2))
        hf.add((r[ok] ** 2).sum(axis=(0, 2)) / 3, ok.sum())
        hfx.add((r[ok, :, 0] ** 2).sum(axis=0), ok.sum())
        hfyz.add((r[ok, :, 1:] ** 2).sum(axis=(0, 2)) / 2, ok.sum())
        lengths = segment_lengths(p)
        if len(lengths) >= 3:
            bl.add(((lengths - lengths.mean(0)) ** 2).sum(0), len(lengths) - 1)
            f2f.add((np.diff(lengths, axis=0) ** 2).sum(0), len(lengths) - 1)
        if references is not None and references[i] is not None:
            e = p - references[i]
            okr = np.isfinite(e).all(axis=(1, 2))
            if okr.sum() >= 3:
                mu = e[okr].mean(0)
                rnd.add(((e[okr] - mu) ** 2).sum(axis=(0, 2)) / 3, okr.sum() - 1)
                off.add((mu ** 2).sum(-1) / 3, 1)
                means.setdefault(groups[i] if groups else '', []).append(mu)
    out = {'hf_jitter_mm': hf.rms() * 1e3, 'hf_jitter_depth_mm': hfx.rms() * 1e3,
           'hf_jitter_lateral_mm': hfyz.rms() * 1e3, 'bone_length_std_mm': bl.rms() * 1e3,
           'bone_length_f2f_mm': f2f.rms() * 1e3}
    if references is not None:
        out['random_error_mm'] = rnd.rms() * 1e3
        out['offset_mm'] = off.rms() * 1e3
        oc = _Acc(NUM_JOINTS)
        for lst in means.values():
            if len(lst) >= 2:
                a = np.array(lst)
                oc.add(((a - a.mean(0)) ** 2).sum(axis=(0, 2)) / 3, len(a) - 1)
        out['offset_clip_mm'] = oc.rms() * 1e3
    return out


def tracking_failures(clips, fail_rel: float = FAIL_REL) -> Dict:
    """Frames whose core segment lengths deviate > ``fail_rel`` from the subject's median."""
    by_subject: Dict[int, List] = {}
    for rc in clips:
        by_subject.setdefault(rc.clip.subject, []).append(rc)
    rows = {}
    for subj, items in by_subject.items():
        lens = {rc.clip.name: segment_lengths(rc.kinect.positions) for rc in items}
        base_set = [lens[rc.clip.name] for rc in items if not rc.clip.is_tracking_failure]
        base = np.median(np.concatenate(base_set or list(lens.values())), axis=0)
        for rc in items:
            cs = list(CORE_SEGMENTS)
            dev = np.abs(lens[rc.clip.name][:, cs] - base[cs])
            rel = dev / base[cs]
            bad = ((rel > fail_rel) & (dev > FAIL_ABS)).any(axis=1)
            v = np.linalg.norm(np.diff(rc.kinect.positions[:, list(COMPARE_JOINTS)], axis=0),
                               axis=-1) * 30.0
            key = 'm03_s01' if rc.clip.is_tracking_failure else f'm{rc.clip.movement:02d}'
            d = rows.setdefault(key, {'clips': 0, 'frames': 0, 'failed_frames': 0,
                                      'max_rel_dev': [], 'median_rel_dev': [], 'max_speed': []})
            d['clips'] += 1
            d['frames'] += len(bad)
            d['failed_frames'] += int(bad.sum())
            d['max_rel_dev'].append(float(rel.max()))
            d['median_rel_dev'].append(float(np.median(rel)))
            d['max_speed'].append(float(v.max()) if len(v) else 0.0)
    out = {}
    for k, d in sorted(rows.items()):
        out[k] = {'clips': d['clips'], 'frames': d['frames'],
                  'failed_fraction': d['failed_frames'] / max(d['frames'], 1),
                  'median_rel_dev': float(np.median(d['median_rel_dev'])),
                  'max_rel_dev': float(np.max(d['max_rel_dev'])),
                  'max_joint_speed_m_s': float(np.max(d['max_speed']))}
    return out


def _reference_clips(with_ref, src, max_clips):
    """(name, rigid reference motion, fps) for the model side: the clip's marker reference with
    constant segment lengths (Shum & Ho Eq. 3-4 retargeting to its median lengths), so the model
    output's bone-length variation is the model's alone. Clips whose reference has gaps inside
    are left out; gaps at the ends are trimmed."""
    pick = with_ref[:: max(1, len(with_ref) // max_clips)] if with_ref else []
    out = []
    for rc in pick:
        r, fps = None, 100.0
        if src is not None:
            try:
                r = load_reference(vicon_path_for(src, rc.clip.name))
            except Exception:
                r = None
        if r is None:
            r, fps = rc.reference, 30.0
        good = np.flatnonzero(np.isfinite(r).all(axis=(1, 2)))
        if len(good) < 30 or len(good) != good[-1] - good[0] + 1:
            continue
        r = r[good[0]:good[-1] + 1]
        r = retarget(r, standard_body(), np.median(segment_lengths(r), axis=0))
        out.append((rc.clip.name, r, fps))
    return out


def model_measure(ref_clips, params=None, seed: int = 0):
    """Run the sensor model ('clean') on the reference motions and measure its output."""
    model = SensorModel(params, seed=seed)
    streams = [model.corrupt(SimpleNamespace(name=n, positions=p, fps=fps), 'clean')
               for n, p, fps in ref_clips]
    if not streams:
        return None, None, model, []
    return (measure([s.positions for s in streams], [s.truth for s in streams]),
            measure([s.truth for s in streams]), model, streams)


def _group_ratio(real, model, idx):
    with np.errstate(invalid='ignore', divide='ignore'):
        r = np.asarray(real, float)[idx] / np.asarray(model, float)[idx]
    r = r[np.isfinite(r)]
    return float(np.mean(r)) if len(r) else 1.0


def fit_params(result, ref_clips, params, iterations: int = 3) -> Dict:
    """Multiplicative fit of the model's noise numbers to the real measurements.

    Per joint group g: ``jitter.base_mm[g]`` scales with real/model lateral (y, z) hf jitter,
    ``jitter.depth_coeff_mm`` with real/model depth-axis hf jitter (mean over joints), and
    ``slow_drift.sigma_mm[g]`` with real/model within-clip bone-length std of the segments
    ending in group g; the model is re-run after every step. Returns the fitted values and the
    model's measurements with them."""
    real = result['real']
    p = copy.deepcopy(params)
    cj = list(COMPARE_JOINTS)
    groups = sorted({JOINT_GROUP[j] for j in cj})
    m = result['model']
    history = []
    for it in range(iterations):
        qd = _group_ratio(real['hf_jitter_depth_mm'], m['hf_jitter_depth_mm'], cj)
        p['jitter']['depth_coeff_mm'] = round(float(p['jitter']['depth_coeff_mm'])
                                              * float(np.clip(qd, 0.2, 5.0)), 3)
        for g in groups:
            js = [j for j in cj if JOINT_GROUP[j] == g]
            q = _group_ratio(real['hf_jitter_lateral_mm'], m['hf_jitter_lateral_mm'], js)
            p['jitter']['base_mm'][g] = round(float(p['jitter']['base_mm'][g])
                                              * float(np.clip(q, 0.2, 5.0)), 2)
            segs = [k for k in COMPARE_SEGMENTS if JOINT_GROUP[SEGMENT_CHILDREN[k]] == g]
            if segs:
                qb = _group_ratio(real['bone_length_std_mm'], m['bone_length_std_mm'], segs)
                p['slow_drift']['sigma_mm'][g] = round(
                    float(p['slow_drift']['sigma_mm'][g]) * float(np.clip(qb, 0.2, 5.0)), 2)
        mm, _, _, _ = model_measure(ref_clips, p)
        m = {k: v.tolist() for k, v in mm.items()}
        history.append({'iteration': it + 1,
                        'hf_ratio_model_over_real': _group_ratio(m['hf_jitter_mm'],
                                                                 real['hf_jitter_mm'], cj),
                        'bone_std_ratio_model_over_real': _group_ratio(
                            m['bone_length_std_mm'], real['bone_length_std_mm'],
                            list(COMPARE_SEGMENTS))})
    return {'params': {'jitter': p['jitter'], 'slow_drift': p['slow_drift']},
            'model': m, 'history': history}


def calibrate(clips, registrations=None, src=None, max_model_clips: int = 60,
              params=None, fit_iterations: int = 3) -> Dict:
    """Real-vs-model statistics. ``clips``: :func:`skeleton_eval.paired.load_dataset` output.

    The model side needs the raw 100 Hz reference of clips with Vicon; ``src`` (the UI-PRMD folder)
    is used to re-read it, else the reference at 30 Hz in the sensor frame is used (fps=30)."""
    ok = [rc for rc in clips if not rc.clip.is_tracking_failure]
    with_ref = [rc for rc in ok if rc.reference is not None]
    real_all = measure([rc.kinect.positions for rc in ok])
    real_ref = measure([rc.kinect.positions for rc in with_ref],
                       [rc.reference for rc in with_ref],
                       [rc.clip.session for rc in with_ref]) if with_ref else None
    result = {'real': {k: v.tolist() for k, v in real_all.items()},
              'real_with_reference': None if real_ref is None
              else {k: v.tolist() for k, v in real_ref.items()},
              'clips': len(ok), 'clips_with_reference': len(with_ref),
              'failures': tracking_failures(clips)}
    if registrations:
        result['session_offsets_mm'] = {
            s: (r.mean_offset * 1e3).round(1).tolist() for s, r in registrations.items()}
    # model side
    try:
        ref_clips = _reference_clips(with_ref, src, max_model_clips)
        model_m, truth_m, model, streams = model_measure(ref_clips, params)
        if streams:
            result['model'] = {k: v.tolist() for k, v in model_m.items()}
            result['model_truth_hf_jitter_mm'] = truth_m['hf_jitter_mm'].tolist()
            result['model_truth_bone_length_std_mm'] = truth_m['bone_length_std_mm'].tolist()
            st = model_statistics(streams)
            result['model_statistics'] = {k: st[k] for k in ('jitter_mm', 'offset_mm',
                                                              'bone_length_std_mm',
                                                              'mean_depth_m')}
            result['model_clips'] = len(streams)
            result['model_params'] = {'jitter': model.params['jitter'],
                                      'slow_drift': model.params['slow_drift'],
                                      'systematic': model.params['systematic']}
            if fit_iterations:
                result['fit'] = fit_params(result, ref_clips, model.params, fit_iterations)
    except ImportError as e:
        result['model_error'] = f'sensor model not available ({e})'
    result['proposal'] = propose(result)
    return result


def propose(result) -> Dict:
    """YAML changes: the fitted values (:func:`fit_params`) that differ from the current ones."""
    fit = result.get('fit')
    cur = result.get('model_params')
    if not fit or not cur:
        return {}
    out = {}
    old, new = cur['jitter']['depth_coeff_mm'], fit['params']['jitter']['depth_coeff_mm']
    if abs(new / old - 1) > 0.05:
        out['jitter.depth_coeff_mm'] = {'current': old, 'proposed': new}
    for sec, key in (('jitter', 'base_mm'), ('slow_drift', 'sigma_mm')):
        for g, old in cur[sec][key].items():
            new = fit['params'][sec][key].get(g, old)
            if old and abs(new / old - 1) > 0.05:
                out[f'{sec}.{key}.{g}'] = {'current': old, 'proposed': new}
    return out


def _f(x):
    return 'n/a' if x is None or not np.isfinite(x) else f'{x:.1f}'


def format_report(result) -> str:
    real = result['real']
    rr = result.get('real_with_reference') or {}
    model = result.get('model')
    lines = ['## Sensor model vs real Kinect (UI-PRMD)', '',
             f'Real: {result["clips"]} clips (m03_s01 excluded), {result["clips_with_reference"]} '
             f'with the marker reference. Model: '
             + (f'{result["model_clips"]} synthetic streams — the marker reference of the same '
                f'clips through SensorModel, scenario "clean".' if model else
                result.get('model_error', 'not available')), '',
             'Per joint (mm, per-axis RMS). hf = high-frequency jitter (minus 9-frame '
             'Savitzky-Golay); random = std of the error against the reference about its '
             'per-clip mean; offset = RMS of per-clip mean error. "!" = model outside +-30 % '
             'of real.', '',
             'offset clip = the part of it that changes between clips of one session (what the '
             'model draws per stream). "fit" = the model with the proposed numbers.', '',
             '| joint | hf real | hf model | ratio | hf fit | random real | random model | '
             'offset real | offset clip real | offset model |',
             '|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|']
    fit = (result.get('fit') or {}).get('model')
    for j in COMPARE_JOINTS:
        hr = real['hf_jitter_mm'][j]
        hm = model['hf_jitter_mm'][j] if model else np.nan
        ratio = hm / hr if model else np.nan
        flag = ' !' if model and abs(ratio - 1) > TOLERANCE else ''
        lines.append(
            f'| {JOINT_NAMES[j]} | {_f(hr)} | {_f(hm)} | '
            f'{_f(ratio) if not model else f"{ratio:.2f}"}'
            f'{flag} | {_f(fit["hf_jitter_mm"][j]) if fit else "n/a"} | '
            f'{_f(rr.get("random_error_mm", [np.nan] * 20)[j])} | '
            f'{_f(model["random_error_mm"][j]) if model else "n/a"} | '
            f'{_f(rr.get("offset_mm", [np.nan] * 20)[j])} | '
            f'{_f(rr.get("offset_clip_mm", [np.nan] * 20)[j])} | '
            f'{_f(model["offset_mm"][j]) if model else "n/a"} |')
    cj = list(COMPARE_JOINTS)
    lines += ['', 'High-frequency jitter by axis, mean over joints (mm): depth (x, along the '
              'line of sight) real {:.1f} / model {}; lateral+vertical (y, z) real {:.1f} / '
              'model {}.'.format(
                  float(np.nanmean(np.asarray(real['hf_jitter_depth_mm'])[cj])),
                  _f(float(np.nanmean(np.asarray(model['hf_jitter_depth_mm'])[cj])))
                  if model else 'n/a',
                  float(np.nanmean(np.asarray(real['hf_jitter_lateral_mm'])[cj])),
                  _f(float(np.nanmean(np.asarray(model['hf_jitter_lateral_mm'])[cj])))
                  if model else 'n/a')]
    lines += ['', 'Per segment (mm): within-clip std of the length, and RMS frame-to-frame change.',
              '', '| segment | std real | std model | ratio | std fit | f2f real | f2f model |',
              '|---|---:|---:|---:|---:|---:|---:|']
    for k in COMPARE_SEGMENTS:
        br = real['bone_length_std_mm'][k]
        bm = model['bone_length_std_mm'][k] if model else np.nan
        ratio = bm / br if model else np.nan
        flag = ' !' if model and abs(ratio - 1) > TOLERANCE else ''
        lines.append(f'| {SEGMENT_NAMES[k]} | {_f(br)} | {_f(bm)} | '
                     f'{"n/a" if not model else f"{ratio:.2f}"}{flag} | '
                     f'{_f(fit["bone_length_std_mm"][k]) if fit else "n/a"} | '
                     f'{_f(real["bone_length_f2f_mm"][k])} | '
                     f'{_f(model["bone_length_f2f_mm"][k]) if model else "n/a"} |')
    lines += ['', 'Tracking failures: frames with a core segment (no hands/feet) > '
              f'{FAIL_REL:.0%} and '
              f'> {FAIL_ABS * 100:.0f} cm off the subject\'s median length; dev = relative '
              'length deviation.', '',
              '| movement | clips | frames | failed frames | median dev | max dev | '
              'max joint speed (m/s) |', '|---|---:|---:|---:|---:|---:|---:|']
    for k, d in result['failures'].items():
        lines.append(f'| {k} | {d["clips"]} | {d["frames"]} | {100 * d["failed_fraction"]:.1f} % | '
                     f'{100 * d["median_rel_dev"]:.1f} % | {100 * d["max_rel_dev"]:.0f} % | '
                     f'{d["max_joint_speed_m_s"]:.1f} |')
    prop = result.get('proposal') or {}
    if prop:
        lines += ['', 'Proposed config/sensor_model.yaml changes (fitted by re-running the model, '
                  f'{len(result["fit"]["history"])} iterations):', '']
        for key, d in prop.items():
            lines.append(f'- `{key}`: {d["current"]} -> {d["proposed"]}')
        h = result['fit']['history'][-1]
        lines.append(f'- after the fit, model/real mean ratio: hf jitter '
                     f'{h["hf_ratio_model_over_real"]:.2f}, bone-length std '
                     f'{h["bone_std_ratio_model_over_real"]:.2f}')
    elif model:
        lines += ['', 'No change proposed.']
    return '\n'.join(lines)


def write_report(result, out) -> str:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    md = format_report(result)
    (out / 'calibration.md').write_text(md + '\n')
    (out / 'calibration.json').write_text(json.dumps(result, indent=1, default=float))
    return md
