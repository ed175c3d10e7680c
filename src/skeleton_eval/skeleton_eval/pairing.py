"""Pairing a lab's tracker recording with its mocap reference: clock offset, rigid registration.

A lab records the graph's input topic (a bag of ``/kinect/skeletons`` from any tracker) and, at
the same time, a reference with its mocap system (:mod:`skeleton_data.reference`), each on its
own clock and in its own frame. To learn the tracker's error we need, for every tracker frame,
the reference at the same instant in the tracker's frame:

* **Clock offset** (:func:`clock_offset`): the reference time of a tracker frame is
  ``t_tracker - t0_tracker + offset``. The offset maximises the normalised cross-correlation of
  rigid-motion-invariant signals (the distances of the limb joints from the pelvis, the same
  features as :func:`skeleton_eval.registration.estimate_lag`) of the two streams, both resampled
  to 100 Hz, over every shift that leaves at least ``min_overlap`` of the shorter recording
  overlapping (or within ``max_offset_s`` of ``guess_s``); the peak is refined by a parabola
  (sub-sample). The curve's peak value is reported as the confidence (1 = identical shapes).
* **Rigid registration** (:func:`register`): one rotation + translation (Kabsch, no scaling) per
  *session* (the recordings made in one lab setup; by default one per subject), fitted on every
  paired frame of the session's recordings on the joints both streams have (hands excluded, as
  the UI-PRMD path does, :mod:`skeleton_eval.registration`).

A tracker stream's frames are its (T, 20, 3) positions with their stamps; a reference is
:class:`skeleton_data.reference.Reference`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence

import numpy as np
from scipy.signal import correlate

from . import registration as reg

GRID_HZ = 100.0


@dataclass
class Pair:
    """One tracker recording with its reference (inputs), and what pairing found."""

    name: str
    subject: str
    tracker_times: np.ndarray          # (T,) s (the bag's stamps)
    tracker: np.ndarray                # (T, 20, 3) m, sensor frame
    ref_times: np.ndarray              # (N,) s, mocap clock
    ref: np.ndarray                    # (N, 20, 3) m, mocap frame
    session: str = ''
    offset_s: float = float('nan')     # reference time = tracker time - tracker t0 + offset
    offset_score: float = float('nan')
    reference: Optional[np.ndarray] = None   # (T, 20, 3) registered, NaN outside
    residual_m: float = float('nan')


def _features(pos: np.ndarray) -> np.ndarray:
    f = reg._lag_features(pos)
    out = np.empty_like(f)
    idx = np.arange(len(f))
    for k in range(f.shape[1]):   # gaps (missing markers) bridged linearly
        ok = np.isfinite(f[:, k])
        out[:, k] = np.interp(idx, idx[ok], f[ok, k]) if ok.sum() >= 2 else 0.0
    return out


def _grid(times: np.ndarray, feats: np.ndarray):
    t = np.asarray(times, float) - float(times[0])
    g = np.arange(0.0, t[-1] + 1e-9, 1.0 / GRID_HZ)
    return np.stack([np.interp(g, t, feats[:, k]) for k in range(feats.shape[1])], axis=1)


def _sliding(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    c = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x, axis=0)])
    return c[hi] - c[lo]


def xcorr_curve(a: np.ndarray, b: np.ndarray, min_count: int):
    """Normalised cross-correlation of (Na, F) ``a`` and (Nb, F) ``b`` for every lag L (a[i]
    pairs with b[i + L]) with at least ``min_count`` overlapping samples: (lags, scores)."""
    na, nb = len(a), len(b)
    lags = np.arange(-(na - 1), nb)
    lo_a = np.maximum(0, -lags)
    hi_a = np.minimum(na, nb - lags)
    n = hi_a - lo_a
    keep = n >= max(min_count, 2)
    lags, lo_a, hi_a, n = lags[keep], lo_a[keep], hi_a[keep], n[keep]
    lo_b, hi_b = lo_a + lags, hi_a + lags
    num = np.zeros(len(lags))
    va = np.zeros(len(lags))
    vb = np.zeros(len(lags))
    for k in range(a.shape[1]):
        x, y = a[:, k], b[:, k]
        sab = correlate(y, x, mode='full', method='fft' if na * nb > 1e6 else 'direct')[
            lags + na - 1]   # FFT for long recordings (minutes at 100 Hz)
        sa, sb = _sliding(x, lo_a, hi_a), _sliding(y, lo_b, hi_b)
        saa, sbb = _sliding(x * x, lo_a, hi_a), _sliding(y * y, lo_b, hi_b)
        num += sab - sa * sb / n
        va += np.maximum(saa - sa * sa / n, 0.0)
        vb += np.maximum(sbb - sb * sb / n, 0.0)
    den = np.sqrt(va * vb)
    score = np.where(den > 1e-12, num / np.maximum(den, 1e-12), -np.inf)
    return lags, score


def clock_offset(tracker_times, tracker, ref_times, ref, min_overlap: float = 0.5,
                 guess_s: Optional[float] = None, max_offset_s: Optional[float] = None):
    """(offset s, peak score): reference time = tracker time - tracker_times[0] + offset, where
    the offset is measured from the reference's first sample time (module docstring)."""
    a = _grid(tracker_times, _features(np.asarray(tracker, float)))
    b = _grid(ref_times, _features(np.asarray(ref, float)))
    if len(a) < 10 or len(b) < 10:
        raise ValueError('too short to align the clocks (fewer than 0.1 s of data)')
    lags, score = xcorr_curve(a, b, int(min_overlap * min(len(a), len(b))))
    if guess_s is not None and max_offset_s is not None:
        sec = lags / GRID_HZ + float(ref_times[0])
        score = np.where(np.abs(sec - guess_s) <= max_offset_s, score, -np.inf)
    if not np.isfinite(score).any():
        raise ValueError('the recordings do not overlap enough to align their clocks')
    i = int(np.argmax(score))
    frac = 0.0
    if 0 < i < len(score) - 1 and np.isfinite(score[i - 1]) and np.isfinite(score[i + 1]):
        y0, y1, y2 = score[i - 1], score[i], score[i + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            frac = float(np.clip(0.5 * (y0 - y2) / den, -0.5, 0.5))
    return float((lags[i] + frac) / GRID_HZ + float(ref_times[0])), float(score[i])


def paired(p: Pair) -> np.ndarray:
    """The reference at the tracker's frames (mocap frame), NaN outside."""
    t = np.asarray(p.tracker_times, float) - float(p.tracker_times[0]) + p.offset_s
    return reg.resample(p.ref, p.ref_times, t)


@dataclass
class SessionFit:
    rotation: np.ndarray
    translation: np.ndarray
    residual_m: float
    pairs: List[str] = field(default_factory=list)


def register(pairs: Sequence[Pair], joints: Sequence[int] = reg.FIT_JOINTS) -> Dict[str, SessionFit]:
    """Align every pair's clock, then one rigid transform per session (module docstring); fills
    ``offset_s``, ``offset_score``, ``reference`` and ``residual_m`` of each pair."""
    joints = list(joints)
    for p in pairs:
        if not np.isfinite(p.offset_s):
            p.offset_s, p.offset_score = clock_offset(p.tracker_times, p.tracker, p.ref_times,
                                                      p.ref)
    fits: Dict[str, SessionFit] = {}
    sessions: Dict[str, List[Pair]] = {}
    for p in pairs:
        sessions.setdefault(p.session or p.subject, []).append(p)
    for name, members in sessions.items():
        src = np.concatenate([paired(p)[:, joints] for p in members]).reshape(-1, 3)
        dst = np.concatenate([np.asarray(p.tracker, float)[:, joints] for p in members]
                             ).reshape(-1, 3)
        rot, tr = reg.kabsch(src, dst)
        res = []
        for p in members:
            p.reference = reg.apply_transform(rot, tr, paired(p))
            d = np.linalg.norm(p.reference[:, joints] - np.asarray(p.tracker)[:, joints], axis=-1)
            p.residual_m = float(np.nanmean(d)) if np.isfinite(d).any() else float('nan')
            res.append(d[np.isfinite(d)])
        allres = np.concatenate(res) if res else np.zeros(0)
        fits[name] = SessionFit(rot, tr, float(allres.mean()) if allres.size else float('nan'),
                                [p.name for p in members])
    return fits


__all__ = ['Pair', 'clock_offset', 'register', 'paired', 'xcorr_curve', 'SessionFit']
