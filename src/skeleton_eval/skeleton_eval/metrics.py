"""Accuracy metrics between an estimated and a true joint sequence (vectorised, NaN-safe).

All functions take ``pred`` and ``truth`` of shape (T, 20, 3) in metres, in the same frame, and
return ``(per_joint, overall)``: ``per_joint`` a (20,) or (19,) array, ``overall`` a float. Frames
where either input is NaN are skipped (per joint); a quantity with no valid frame is NaN.

* :func:`eq18_error` — Shum et al. 2013, Eq. 18: the mean over frames f and parts i of
  ``|(p1_i(f) - p1_i'(f)) - (p2_i(f) - p2_i'(f))|`` with i' the parent of i, in cm. The root has
  no parent, so the sum runs over the 19 non-root parts (``i_total = 19``); the root's row is NaN.
  Being parent-relative, it ignores the global position (the paper compared Kinect with a magnetic
  mocap in different frames) and does not accumulate errors down the chains.
* :func:`mpjpe` — mean per-joint position error, cm (all 20 joints).
* :func:`mpjpe_root_relative` — MPJPE with both skeletons less their root joint, cm (the 19
  non-root joints): where a method puts the whole body apart, how well the posture matches.
* :func:`jitter` — mean magnitude of the joint acceleration by second differences, m/s^2.
* :func:`bone_length_std` — std over time of each segment length, cm (19 segments);
  :func:`bone_length_step` — its frame-to-frame part: the RMS change of each length from one
  frame to the next over sqrt(2), cm (equal to the std for white length noise, near 0 for
  lengths that change only slowly, e.g. with the pose);
  :func:`bone_length_error` — mean |length - true length|, cm.
* :func:`bone_direction_error` — mean angle between estimated and true segment directions, deg
  (length-free).
* :func:`added_latency_ms` — the delay of an output behind its input (the best-fitting shift).
* :func:`velocity_xcorr` / :func:`xcorr_latency_ms` — the delay of an output behind a reference
  motion from the peak of the cross-correlation of their joint velocities (signed, sub-frame).
"""
from __future__ import annotations

from typing import Dict, Tuple

import numpy as np

from skeleton_core.model import NUM_JOINTS, SEGMENT_CHILD_INDEX, SEGMENT_PARENT_INDEX



def _check(pred, truth=None):
    p = np.asarray(pred, float)
    if p.ndim != 3 or p.shape[1:] != (NUM_JOINTS, 3):
        raise ValueError(f'expected (T, {NUM_JOINTS}, 3), got {p.shape}')
    if truth is None:
        return p
    t = np.asarray(truth, float)
    if t.shape != p.shape:
        raise ValueError(f'shape mismatch {p.shape} vs {t.shape}')
    return p, t


def _nanmean0(x):
    """nanmean over axis 0 without warnings; NaN where no value."""
    ok = np.isfinite(x)
    n = ok.sum(axis=0)
    s = np.where(ok, x, 0.0).sum(axis=0)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(n > 0, s / np.maximum(n, 1), np.nan)


def _overall(x):
    ok = np.isfinite(x)
    return float(x[ok].mean()) if ok.any() else float('nan')


def eq18_error(pred, truth) -> Tuple[np.ndarray, float]:
    """Shum 2013 Eq. 18 in cm: per joint (20,), root NaN; overall = mean over frames and 19 parts."""
    p, t = _check(pred, truth)
    rp = p[:, 1:] - p[:, SEGMENT_PARENT_INDEX]
    rt = t[:, 1:] - t[:, SEGMENT_PARENT_INDEX]
    e = np.linalg.norm(rp - rt, axis=-1) * 100.0  # (T, 19)
    per = np.full(NUM_JOINTS, np.nan)
    per[1:] = _nanmean0(e)
    return per, _overall(e)


def mpjpe(pred, truth) -> Tuple[np.ndarray, float]:
    """Mean per-joint position error in cm."""
    p, t = _check(pred, truth)
    e = np.linalg.norm(p - t, axis=-1) * 100.0
    return _nanmean0(e), _overall(e)


def mpjpe_root_relative(pred, truth) -> Tuple[np.ndarray, float]:
    """MPJPE in cm of the postures relative to their root joints: (20,) with the root NaN."""
    p, t = _check(pred, truth)
    e = np.linalg.norm((p - p[:, :1]) - (t - t[:, :1]), axis=-1) * 100.0
    e[:, 0] = np.nan
    return _nanmean0(e), _overall(e)


def jitter(pred, fps: float = 30.0) -> Tuple[np.ndarray, float]:
    """Mean joint acceleration magnitude (m/s^2) by second differences; needs T >= 3."""
    p = _check(pred)
    if len(p) < 3:
        return np.full(NUM_JOINTS, np.nan), float('nan')
    a = np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=-1) * fps ** 2
    return _nanmean0(a), _overall(a)


def _lengths(p):
    return np.linalg.norm(p[:, SEGMENT_CHILD_INDEX] - p[:, SEGMENT_PARENT_INDEX], axis=-1)


def bone_length_std(pred) -> Tuple[np.ndarray, float]:
    """Std over time of every segment length (cm), (19,) and their mean."""
    p = _check(pred)
    L = _lengths(p) * 100.0
    mu = _nanmean0(L)
    dev = (L - mu) ** 2
    with np.errstate(invalid='ignore'):
        sd = np.sqrt(_nanmean0(dev))
    return sd, _overall(sd)


def bone_length_step(pred) -> Tuple[np.ndarray, float]:
    """The frame-to-frame part of the bone-length std (cm), (19,) and their mean: RMS of each
    segment length's change between consecutive frames, over sqrt(2)."""
    p = _check(pred)
    L = _lengths(p) * 100.0
    if len(L) < 2:
        sd = np.full(L.shape[1], np.nan)
        return sd, _overall(sd)
    with np.errstate(invalid='ignore'):
        sd = np.sqrt(_nanmean0(np.diff(L, axis=0) ** 2) / 2.0)
    return sd, _overall(sd)


def bone_length_error(pred, truth) -> Tuple[np.ndarray, float]:
    """Mean |segment length - true segment length| in cm, (19,) and overall."""
    p, t = _check(pred, truth)
    d = np.abs(_lengths(p) - _lengths(t)) * 100.0
    return _nanmean0(d), _overall(d)


def bone_direction_error(pred, truth) -> Tuple[np.ndarray, float]:
    """Mean angle (deg) between estimated and true segment directions, (19,) and overall."""
    p, t = _check(pred, truth)
    a = p[:, SEGMENT_CHILD_INDEX] - p[:, SEGMENT_PARENT_INDEX]
    b = t[:, SEGMENT_CHILD_INDEX] - t[:, SEGMENT_PARENT_INDEX]
    na = np.linalg.norm(a, axis=-1)
    nb = np.linalg.norm(b, axis=-1)
    with np.errstate(invalid='ignore', divide='ignore'):
        cos = (a * b).sum(-1) / (na * nb)
    cos = np.where((na > 1e-9) & (nb > 1e-9), cos, np.nan)
    ang = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return _nanmean0(ang), _overall(ang)


MAX_LATENCY_FRAMES = 10


def latency_curve(out: np.ndarray, raw: np.ndarray, max_frames: int = MAX_LATENCY_FRAMES):
    """``(sums, counts)`` (max_frames + 1,): per shift k >= 0 the sum and number of the finite
    distances |out(t) - raw(t-k)| (several streams pool by adding them)."""
    sums = np.zeros(max_frames + 1)
    counts = np.zeros(max_frames + 1)
    for k in range(0, min(max_frames, len(raw) - 1) + 1):
        d = np.linalg.norm(out[k:] - raw[:len(raw) - k], axis=-1)
        ok = np.isfinite(d)
        sums[k] = d[ok].sum()
        counts[k] = ok.sum()
    return sums, counts


def _argmin_subframe(errs: np.ndarray) -> float:
    """The index of the smallest of ``errs``, refined to a fraction by a parabola through it and
    its two neighbours (where they are finite and the parabola opens upwards)."""
    k = int(np.argmin(errs))
    frac = 0.0
    if 0 < k < len(errs) - 1 and np.isfinite(errs[k - 1:k + 2]).all():
        den = errs[k - 1] - 2 * errs[k] + errs[k + 1]
        if den > 1e-12:
            frac = 0.5 * (errs[k - 1] - errs[k + 1]) / den
    return k + frac


def latency_from_curve(sums, counts, fps: float = 30.0) -> float:
    """The delay (ms) of a :func:`latency_curve`: the shift of the smallest mean distance,
    refined to sub-frame by a parabola through the minimum."""
    with np.errstate(invalid='ignore', divide='ignore'):
        errs = np.where(np.asarray(counts) > 0, np.asarray(sums) / np.asarray(counts), np.inf)
    if not np.isfinite(errs).any():
        return float('nan')
    return float(_argmin_subframe(errs) * 1000.0 / fps)


def signed_latency_from_curves(behind, ahead, fps: float = 30.0) -> float:
    """The delay (ms) from two :func:`latency_curve` results, ``behind`` =
    ``latency_curve(out, raw)`` (output shifted back) and ``ahead`` = ``latency_curve(raw, out)``
    (output shifted forward): the shift of the smallest mean distance over ``-K..K``, refined to
    sub-frame by a parabola; negative when the output leads. Unlike :func:`latency_from_curve`
    (shifts >= 0 only) its error is not folded onto the positive side: where the curve is flat (the
    output differs from the input by far more than any delay moves it) the one-sided minimum
    wanders and is clamped at 0, so its mean over streams or seeds reads a delay that is not
    there."""
    with np.errstate(invalid='ignore', divide='ignore'):
        e = [np.where(np.asarray(c) > 0, np.asarray(s) / np.asarray(c), np.inf)
             for s, c in (behind, ahead)]
    K = len(e[0]) - 1
    errs = np.concatenate([e[1][:0:-1], e[0]])   # shifts -K .. K
    if not np.isfinite(errs).any():
        return float('nan')
    return float((_argmin_subframe(errs) - K) * 1000.0 / fps)


def added_latency_ms(out: np.ndarray, raw: np.ndarray, fps: float = 30.0,
                     max_frames: int = MAX_LATENCY_FRAMES) -> float:
    """Delay of ``out`` behind ``raw`` (ms): the shift k >= 0 minimising mean |out(t) - raw(t-k)|,
    refined to sub-frame by a parabola through the minimum."""
    return latency_from_curve(*latency_curve(out, raw, max_frames), fps)


def velocity_xcorr(out: np.ndarray, ref: np.ndarray, max_frames: int = MAX_LATENCY_FRAMES,
                   mask=None) -> np.ndarray:
    """(2 max_frames + 1,): for each shift k in -K..K the sum of ``v_out(t) . v_ref(t - k)`` over
    the joint-frames where both velocities (first differences) are finite (and ``mask`` (T, J),
    if given, holds at both frames of the difference). Curves of several streams pool by adding
    them; :func:`xcorr_latency_ms` reads the delay. Blind to constant offsets between ``out`` and
    ``ref`` and, where ``ref`` is a true motion, to the sensor's noise."""
    o = np.asarray(out, float)
    r = np.asarray(ref, float)
    vo, vr = np.diff(o, axis=0), np.diff(r, axis=0)
    ok = np.isfinite(vo).all(-1)
    if mask is not None:
        m = np.asarray(mask, bool)
        ok &= m[1:] & m[:-1]
    vo = np.where(ok[..., None], vo, 0.0)
    vr = np.where(np.isfinite(vr), vr, 0.0)
    K = max_frames
    xc = np.zeros(2 * K + 1)
    for i, k in enumerate(range(-K, K + 1)):
        a, b = (vo[k:], vr[:len(vr) - k]) if k >= 0 else (vo[:k], vr[-k:])
        if len(a):
            xc[i] = float(np.einsum('tjk,tjk->', a, b))
    return xc


def xcorr_latency_ms(xc, fps: float = 30.0) -> float:
    """The delay (ms) of a :func:`velocity_xcorr` curve: the shift of its peak (-K..K frames),
    refined to sub-frame by a parabola; negative when the output leads. NaN for an empty curve."""
    xc = np.asarray(xc, float)
    if not np.isfinite(xc).all() or not np.any(xc):
        return float('nan')
    K = (len(xc) - 1) // 2
    k = int(np.argmax(xc))
    frac = 0.0
    if 0 < k < len(xc) - 1:
        den = xc[k - 1] - 2 * xc[k] + xc[k + 1]
        if den < -1e-12:
            frac = 0.5 * (xc[k - 1] - xc[k + 1]) / den
    return float((k - K + frac) * 1000.0 / fps)


METRICS = ('eq18_cm', 'mpjpe_cm', 'mpjpe_rel_cm', 'jitter_ms2', 'bone_std_cm', 'bone_step_cm',
           'bone_err_cm', 'bone_dir_deg')


def compute_all(pred, truth, fps: float = 30.0) -> Dict[str, Dict]:
    """Every metric: ``{name: {'per_joint': list, 'overall': float}}`` (bone metrics per segment)."""
    out = {}
    for name, (per, tot) in (('eq18_cm', eq18_error(pred, truth)),
                             ('mpjpe_cm', mpjpe(pred, truth)),
                             ('mpjpe_rel_cm', mpjpe_root_relative(pred, truth)),
                             ('jitter_ms2', jitter(pred, fps)),
                             ('bone_std_cm', bone_length_std(pred)),
                             ('bone_step_cm', bone_length_step(pred)),
                             ('bone_err_cm', bone_length_error(pred, truth)),
                             ('bone_dir_deg', bone_direction_error(pred, truth))):
        out[name] = {'per_joint': [float(v) for v in per], 'overall': tot}
    return out


def length_rigidity(tracks, fps: float = 30.0) -> Dict:
    """Bone-length std per segment beside jitter, raw and output, from ``tracks``: a list of
    ``(raw, out)`` pairs of (T, 20, 3) sequences, one per user track (one user's frames from
    arrival to leaving: a rigid output has one set of lengths per track, a new user another).
    Per track each segment's std over time (cm, :func:`bone_length_std`) and the jitter (m/s^2,
    :func:`jitter`), averaged over the tracks weighted by their frames (tracks of fewer than 3
    frames skipped). Returns ``{'tracks', 'frames', 'raw_std_cm' (19,), 'out_std_cm' (19,),
    'raw_std_mean_cm', 'out_std_mean_cm', 'std_reduction_pct', 'raw_jitter_ms2',
    'out_jitter_ms2', 'out_nan_frames'}``."""
    rs, os_, rj, oj, w = [], [], [], [], []
    nan_frames = 0
    frames = 0
    for raw, out in tracks:
        raw, out = _check(raw), _check(out)
        if len(raw) != len(out):
            raise ValueError('each track needs as many raw as output frames')
        nan_frames += int((~np.isfinite(out)).any(axis=(1, 2)).sum())
        frames += len(out)
        if len(out) < 3:
            continue
        rs.append(bone_length_std(raw)[0])
        os_.append(bone_length_std(out)[0])
        rj.append(jitter(raw, fps)[1])
        oj.append(jitter(out, fps)[1])
        w.append(float(len(out)))

    ntracks = len(w)
    if not w:   # no track long enough
        rs, os_, rj, oj, w = ([np.full(len(SEGMENT_CHILD_INDEX), np.nan)],) * 2 + (
            [float('nan')],) * 2 + ([1.0],)

    def avg(x):
        a = np.asarray(x, float)
        wt = np.asarray(w)[:, None] if a.ndim == 2 else np.asarray(w)
        ok = np.isfinite(a)
        with np.errstate(invalid='ignore'):
            return (np.where(ok, a, 0.0) * wt).sum(axis=0) / (ok * wt).sum(axis=0)
    r, o = avg(rs), avg(os_)
    rm, om = _overall(r), _overall(o)
    return {'tracks': ntracks, 'frames': frames,
            'raw_std_cm': [float(v) for v in r], 'out_std_cm': [float(v) for v in o],
            'raw_std_mean_cm': rm, 'out_std_mean_cm': om,
            'std_reduction_pct': 100.0 * (rm - om) / rm if rm > 0 else float('nan'),
            'raw_jitter_ms2': float(avg(rj)), 'out_jitter_ms2': float(avg(oj)),
            'out_nan_frames': nan_frames}
