"""Pairing Kinect streams with the marker reference: resampling, lag search, rigid registration.

* :func:`resample` — linear interpolation of a (N, ...) trajectory onto other times (NaN outside).
* :func:`kabsch` — least-squares rotation + translation (no scaling), Kabsch 1976 / Umeyama 1991
  with the reflection fix, ignoring rows with NaN.
* :func:`estimate_lag` — clock offset between a Kinect clip (30 Hz) and its reference (100 Hz):
  the two recordings were cut separately (median 0.08 s, up to ~0.3 s). The coarse search maximises
  the correlation of rotation- and translation-invariant features (joint distances from the
  pelvis), so it works before any spatial registration.
* :func:`register_session` — one rigid transform per subject session (all clips of one subject
  share the sensor and the lab) and a lag per clip: coarse lags, Kabsch on all paired frames, then
  each lag refined by the residual under that transform and Kabsch refitted.
* :func:`split_setups` — a subject's recordings are not always one rigid setup: in UI-PRMD the
  Vicon of s05's m07 and m09 sits 0.77 m away from the rest of that subject's movements (a moved
  lab origin; a single session transform leaves 65 cm on those clips and 15-18 cm on the
  others). Each movement's clips get their own fit first; movements whose fits agree (translation
  within ``tol_m``, heading within ``tol_deg``) are grouped into one setup, which then gets one
  transform (:func:`register_session`). A movement that agrees with no other is its own setup.

Convention: ``lag`` (s) means Kinect frame at time t pairs with the reference at time t + lag;
the transform maps the reference into the Kinect frame: ``kinect ~= ref @ R.T + t``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import List, Optional, Sequence, Tuple

import numpy as np

from skeleton_core.model import (ANKLE_LEFT, ANKLE_RIGHT, ELBOW_LEFT, ELBOW_RIGHT, FOOT_LEFT, FOOT_RIGHT,
                    HAND_LEFT, HAND_RIGHT, HEAD, HIP_CENTER, KNEE_LEFT, KNEE_RIGHT, NUM_JOINTS,
                    WRIST_LEFT, WRIST_RIGHT)

KINECT_RATE = 30.0
REFERENCE_RATE = 100.0
# Joints used for the fit: all but the hands (extrapolated in the Kinect import, NOT_TRACKED)
FIT_JOINTS: Tuple[int, ...] = tuple(j for j in range(NUM_JOINTS) if j not in (HAND_LEFT,
                                                                              HAND_RIGHT))
_LAG_FEATURE_JOINTS = (HEAD, ELBOW_LEFT, ELBOW_RIGHT, WRIST_LEFT, WRIST_RIGHT, KNEE_LEFT,
                       KNEE_RIGHT, ANKLE_LEFT, ANKLE_RIGHT, FOOT_LEFT, FOOT_RIGHT)


def resample(values: np.ndarray, times_src: np.ndarray, times_dst: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``values`` (N, ...) sampled at ``times_src`` onto ``times_dst``;
    rows outside [times_src[0], times_src[-1]] are NaN."""
    values = np.asarray(values, dtype=float)
    ts = np.asarray(times_src, dtype=float)
    td = np.asarray(times_dst, dtype=float)
    flat = values.reshape(len(ts), -1)
    out = np.full((len(td), flat.shape[1]), np.nan)
    ok = (td >= ts[0] - 1e-9) & (td <= ts[-1] + 1e-9)
    if ok.any() and len(ts) > 1:
        idx = np.clip(np.searchsorted(ts, td[ok], side='right') - 1, 0, len(ts) - 2)
        w = ((td[ok] - ts[idx]) / (ts[idx + 1] - ts[idx]))[:, None]
        out[ok] = (1.0 - w) * flat[idx] + w * flat[idx + 1]
    elif ok.any():
        out[ok] = flat[0]
    return out.reshape((len(td),) + values.shape[1:])


def kabsch(src: np.ndarray, dst: np.ndarray, weights: Optional[np.ndarray] = None
           ) -> Tuple[np.ndarray, np.ndarray]:
    """Rotation R (3, 3) and translation t (3,) minimising sum w |R src + t - dst|^2.

    ``src``, ``dst``: (..., 3) corresponding points; rows with NaN in either are ignored.
    """
    a = np.asarray(src, dtype=float).reshape(-1, 3)
    b = np.asarray(dst, dtype=float).reshape(-1, 3)
    w = np.ones(len(a)) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    ok = np.isfinite(a).all(1) & np.isfinite(b).all(1) & (w > 0)
    if ok.sum() < 3:
        raise ValueError('kabsch needs at least 3 finite point pairs')
    a, b, w = a[ok], b[ok], w[ok]
    w = w / w.sum()
    ca, cb = w @ a, w @ b
    h = ((a - ca) * w[:, None]).T @ (b - cb)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, cb - r @ ca


def apply_transform(r: np.ndarray, t: np.ndarray, points: np.ndarray) -> np.ndarray:
    return np.asarray(points, dtype=float) @ np.asarray(r).T + np.asarray(t)


def _lag_features(pos: np.ndarray) -> np.ndarray:
    """(N, F) rigid-motion-invariant features: distances of limb joints from the pelvis."""
    d = pos[:, list(_LAG_FEATURE_JOINTS)] - pos[:, [HIP_CENTER]]
    return np.linalg.norm(d, axis=-1)


def _times(n: int, rate: float) -> np.ndarray:
    return np.arange(n) / rate


def estimate_lag(kinect: np.ndarray, reference: np.ndarray, max_lag: float = 0.5,
                 step: float = 0.01, kinect_rate: float = KINECT_RATE,
                 reference_rate: float = REFERENCE_RATE) -> float:
    """Coarse lag (s) maximising the correlation of invariant features; see module docstring."""
    fk = _lag_features(kinect)
    fr = _lag_features(reference)
    tk = _times(len(kinect), kinect_rate)
    tr = _times(len(reference), reference_rate)
    best, best_lag = -np.inf, 0.0
    for lag in np.arange(-max_lag, max_lag + 1e-9, step):
        rr = resample(fr, tr, tk + lag)
        ok = np.isfinite(rr).all(1)
        if ok.sum() < max(10, len(tk) // 2):
            continue
        a = fk[ok] - fk[ok].mean(0)
        b = rr[ok] - rr[ok].mean(0)
        den = np.sqrt((a ** 2).sum(0) * (b ** 2).sum(0))
        good = den > 1e-12
        if not good.any():
            continue
        # weight features by their motion so still joints do not dominate
        score = float(((a * b).sum(0)[good]).sum() / np.sqrt(((a ** 2).sum(0)[good]).sum()
                                                               * ((b ** 2).sum(0)[good]).sum()))
        if score > best:
            best, best_lag = score, float(lag)
    return best_lag


def paired_reference(reference: np.ndarray, n_kinect: int, lag: float,
                     kinect_rate: float = KINECT_RATE,
                     reference_rate: float = REFERENCE_RATE) -> np.ndarray:
    """The reference resampled at the Kinect frame times + lag, (n_kinect, 20, 3), NaN outside."""
    return resample(reference, _times(len(reference), reference_rate),
                    _times(n_kinect, kinect_rate) + lag)


@dataclass
class SessionRegistration:
    rotation: np.ndarray                # (3, 3) reference -> Kinect
    translation: np.ndarray             # (3,)
    lags: List[float]                   # s, per clip
    residual_per_joint: np.ndarray      # (20,) mean distance after the fit, m (NaN: no data)
    mean_offset: np.ndarray = field(default=None)  # (20, 3) mean Kinect - reference, m

    def to_kinect(self, reference: np.ndarray) -> np.ndarray:
        return apply_transform(self.rotation, self.translation, reference)


def _fit(pairs_k, pairs_r, joints):
    src = np.concatenate([r[:, joints] for r in pairs_r]).reshape(-1, 3)
    dst = np.concatenate([k[:, joints] for k in pairs_k]).reshape(-1, 3)
    return kabsch(src, dst)


def register_session(kinect_clips: Sequence[np.ndarray], reference_clips: Sequence[np.ndarray],
                     max_lag: float = 0.5, refine: float = 0.1, refine_step: float = 0.01,
                     joints: Sequence[int] = FIT_JOINTS,
                     kinect_rate: float = KINECT_RATE,
                     reference_rate: float = REFERENCE_RATE) -> SessionRegistration:
    """One rigid transform for a session and a lag per clip (see module docstring)."""
    joints = list(joints)
    if len(kinect_clips) != len(reference_clips) or not kinect_clips:
        raise ValueError('need the same, non-zero number of Kinect and reference clips')
    lags = [estimate_lag(k, r, max_lag, 0.01, kinect_rate, reference_rate)
            for k, r in zip(kinect_clips, reference_clips)]
    paired = [paired_reference(r, len(k), lag, kinect_rate, reference_rate)
              for k, r, lag in zip(kinect_clips, reference_clips, lags)]
    rot, tr = _fit(kinect_clips, paired, joints)
    # refine each lag by the residual under the session transform, then refit
    for i, (k, r) in enumerate(zip(kinect_clips, reference_clips)):
        best, best_lag = np.inf, lags[i]
        for lag in np.arange(lags[i] - refine, lags[i] + refine + 1e-9, refine_step):
            if abs(lag) > max_lag + 1e-9:
                continue
            pr = apply_transform(rot, tr, paired_reference(r, len(k), lag, kinect_rate,
                                                           reference_rate))
            d = np.linalg.norm(pr[:, joints] - k[:, joints], axis=-1)
            ok = np.isfinite(d).all(1)
            if ok.sum() < len(k) // 2:
                continue
            err = float(d[ok].mean())
            if err < best:
                best, best_lag = err, float(lag)
        lags[i] = best_lag
        paired[i] = paired_reference(r, len(k), best_lag, kinect_rate, reference_rate)
    rot, tr = _fit(kinect_clips, paired, joints)
    diffs = np.concatenate([k - apply_transform(rot, tr, p)
                            for k, p in zip(kinect_clips, paired)])
    dist = np.linalg.norm(diffs, axis=-1)
    with np.errstate(invalid='ignore'):
        res = np.nanmean(dist, axis=0)
        off = np.nanmean(diffs, axis=0)
    return SessionRegistration(rotation=rot, translation=tr, lags=lags,
                               residual_per_joint=res, mean_offset=off)


def _heading_deg(rot: np.ndarray) -> float:
    return float(np.degrees(np.arctan2(rot[1, 0], rot[0, 0])))


def split_setups(groups: Sequence[Sequence[int]], kinect_clips: Sequence[np.ndarray],
                 reference_clips: Sequence[np.ndarray], tol_m: float = 0.10,
                 tol_deg: float = 10.0) -> List[List[int]]:
    """Group clip indices into rigid setups (module docstring). ``groups``: clip indices per
    movement (the unit that was recorded in one go); returns lists of clip indices, one per
    setup, largest first. Grouping is greedy, largest movement group first, each joining the
    first setup whose first member's transform agrees within ``tol_m`` / ``tol_deg``."""
    fits = []
    for g in groups:
        try:
            sr = register_session([kinect_clips[i] for i in g], [reference_clips[i] for i in g])
            fits.append((list(g), sr.translation, _heading_deg(sr.rotation)))
        except (ValueError, np.linalg.LinAlgError):
            fits.append((list(g), None, None))
    def agree(a, b):
        if a[1] is None or b[1] is None:
            return False
        dyaw = abs((a[2] - b[2] + 180.0) % 360.0 - 180.0)
        return np.linalg.norm(a[1] - b[1]) <= tol_m and dyaw <= tol_deg

    # the movement that agrees with most others anchors the first setup (the consensus)
    support = [sum(agree(f, o) for o in fits) for f in fits]
    order = sorted(range(len(fits)), key=lambda i: (-support[i], -len(fits[i][0])))
    setups: List[tuple] = []
    for g, t, yaw in (fits[i] for i in order):
        for s in setups:
            if agree((g, t, yaw), s):
                s[0].extend(g)
                break
        else:
            setups.append((list(g), t, yaw))
    return sorted((s[0] for s in setups), key=len, reverse=True)
