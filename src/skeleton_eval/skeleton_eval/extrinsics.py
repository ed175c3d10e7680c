"""Extrinsic calibration of one sensor against another from the skeletons themselves.

A person moves for ~10 s where both sensors see them. Both report the same joints, each in its own
frame and on its own clock. :func:`calibrate` finds

* the **time offset** ``dt`` (B's stamp = A's stamp + ``dt`` for the same instant): every
  whole-frame offset within ``MAX_OFFSET_S`` is scored by the rigid fit of the joints' motion it
  allows (below; a wrong offset leaves every moving joint off), and the best is refined to a
  fraction of a frame by a golden-section search on the inliers of its robust fit. (A
  cross-correlation of joint speeds, which do not depend on the frame, was tried first: walking
  is periodic, and its peaks a step apart were as high as the true one.)
* the **rigid transform** ``T`` with ``p_A = T p_B`` (the pose of sensor B in A's frame): B is
  interpolated at A's stamps + ``dt``; every joint both report TRACKED (weighted by the product of
  their reliabilities when the tracks carry one) is a correspondence; RANSAC over minimal sets of
  3 correspondences (from different frames and joints) rejects gross outliers (joints latched on
  the wrong place, left/right swapped in a side view), then weighted Kabsch (Umeyama without
  scale) with iterative trimming at ``TRIM_SIGMAS`` robust standard deviations of the residuals.

The transform from the world to B is then ``world->A * T``. ROS-free; the command is
``ros2 run kinect_bringup calibrate_extrinsics`` (docs/multi_sensor.md).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Dict, Optional, Sequence

import numpy as np

from skeleton_core.geometry import facing_yaw
from skeleton_core.model import HIP_CENTER, MIRROR, NUM_JOINTS, TRACKED
from skeleton_core.tf import Transform
from skeleton_data.motions import builtin_clips
from .sensor_model import SensorModel
from .sensor_params import _merge, load_params

MAX_OFFSET_S = 2.0        # the sensors' clocks agree to this much (NTP-synchronised PCs: far less)
RANSAC_ITERATIONS = 300
RANSAC_INLIER_M = 0.15    # a correspondence this close under a candidate transform is an inlier
                          # (the trackers' joint centres differ by several cm per view)
TRIM_SIGMAS = 2.5         # trimming: residuals beyond this many robust sigmas are outliers ...
TRIM_FLOOR_M = 0.02       # ... but never below this (the joints' jitter)
TRIM_ITERATIONS = 10
JOINT_NOISE_WEIGHTS = True
BODY_FRAME_OFFSETS = True
BODY_FRAME_ITERATIONS = 20    # alternations of offsets and placement
MIN_PAIRS = 60            # fewer correspondences than this: no calibration


class CalibrationError(ValueError):
    """The recordings do not allow a calibration (one line saying why)."""


@dataclass
class Track:
    """One sensor's view of one person: ``stamps_ns`` (T,), ``positions`` (T, 20, 3) in the
    sensor's frame, ``tracking_state`` (T, 20), optional ``reliability`` (T, 20)."""

    stamps_ns: np.ndarray
    positions: np.ndarray
    tracking_state: np.ndarray
    reliability: Optional[np.ndarray] = None
    frame_id: str = ''

    def __post_init__(self):
        self.stamps_ns = np.asarray(self.stamps_ns, np.int64)
        self.positions = np.asarray(self.positions, float).reshape(len(self.stamps_ns), NUM_JOINTS, 3)
        self.tracking_state = np.asarray(self.tracking_state).reshape(len(self.stamps_ns), NUM_JOINTS)
        if self.reliability is not None:
            self.reliability = np.asarray(self.reliability, float).reshape(
                len(self.stamps_ns), NUM_JOINTS)
        order = np.argsort(self.stamps_ns, kind='stable')
        if (np.diff(self.stamps_ns) <= 0).any():   # sorted, one frame per stamp
            keep = order[np.concatenate([[True], np.diff(self.stamps_ns[order]) > 0])]
            self.stamps_ns = self.stamps_ns[keep]
            self.positions = self.positions[keep]
            self.tracking_state = self.tracking_state[keep]
            if self.reliability is not None:
                self.reliability = self.reliability[keep]

    def __len__(self) -> int:
        return len(self.stamps_ns)

    def weights(self) -> np.ndarray:
        """(T, 20) per-joint weight: TRACKED and finite, times the reliability if any."""
        ok = (self.tracking_state == TRACKED) & np.isfinite(self.positions).all(axis=2)
        w = ok.astype(float)
        if self.reliability is not None:
            w *= np.clip(np.nan_to_num(self.reliability), 0.0, 1.0)
        return w


@dataclass
class Calibration:
    """``transform``: B's pose in A's frame (``p_A = transform.apply(p_B)``); ``time_offset_s``:
    B's stamps minus A's for the same instant; ``rms_m``: residual RMS of the inliers;
    ``inliers`` / ``pairs``: correspondences kept / offered."""

    transform: Transform
    time_offset_s: float
    rms_m: float
    inliers: int
    pairs: int
    frames: int
    details: Dict = field(default_factory=dict)

    def info(self) -> Dict:
        return {'time_offset_s': round(float(self.time_offset_s), 5),
                'residual_rms_m': round(float(self.rms_m), 5),
                'inliers': int(self.inliers), 'pairs': int(self.pairs),
                'frames': int(self.frames), 'method': 'skeleton (calibrate_extrinsics)'}


# ------------------------------------------------------------------ rigid fits
def kabsch(a: np.ndarray, b: np.ndarray, w: Optional[np.ndarray] = None) -> Transform:
    """The rigid ``T`` minimising ``sum w |a - T b|^2`` (weighted Kabsch / Umeyama, no scale)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    w = np.ones(len(a)) if w is None else np.asarray(w, float)
    sw = float(w.sum())
    if sw <= 0:
        raise CalibrationError('no weighted correspondences')
    ca, cb = (w[:, None] * a).sum(0) / sw, (w[:, None] * b).sum(0) / sw
    h = ((b - cb) * w[:, None]).T @ (a - ca)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return Transform.from_matrix(r, ca - r @ cb)


def _residuals(t: Transform, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.linalg.norm(a - t.apply(b), axis=1)


def robust_fit(a: np.ndarray, b: np.ndarray, w: np.ndarray, groups: np.ndarray,
               rng: np.random.Generator):
    """RANSAC (minimal sets of 3 from different ``groups``, e.g. frames) then trimmed weighted
    Kabsch. Returns (transform, inlier mask)."""
    n = len(a)
    p = w / w.sum()
    best, best_score = None, -1.0
    for _ in range(RANSAC_ITERATIONS):
        idx = rng.choice(n, 3, replace=False, p=p)
        if len(set(groups[idx].tolist())) < 3:
            continue
        tri = b[idx]
        if np.linalg.norm(np.cross(tri[1] - tri[0], tri[2] - tri[0])) < 0.01:   # ~collinear
            continue
        t = kabsch(a[idx], b[idx])
        score = float(w[_residuals(t, a, b) < RANSAC_INLIER_M].sum())
        if score > best_score:
            best, best_score = t, score
    if best is None:
        best = kabsch(a, b, w)
    inl = _residuals(best, a, b) < RANSAC_INLIER_M
    t = best
    for _ in range(TRIM_ITERATIONS):
        if inl.sum() < 3:
            break
        t = kabsch(a[inl], b[inl], w[inl])
        r = _residuals(t, a, b)
        sigma = 1.4826 * float(np.median(r[inl]))
        new = r < max(TRIM_SIGMAS * sigma, TRIM_FLOOR_M)
        if (new == inl).all():
            break
        inl = new
    return t, inl


# ------------------------------------------------------------------ time alignment
def _interp(track: Track, t_ns: np.ndarray, max_gap_s: float):
    """Positions (N, 20, 3) and weights (N, 20) of ``track`` at times ``t_ns`` (linear between the
    two frames around each time; weight 0 outside the track, across a gap or where either frame
    did not track the joint)."""
    s = track.stamps_ns
    j = np.searchsorted(s, t_ns, side='right')
    ok = (j > 0) & (j < len(s))
    j0, j1 = np.clip(j - 1, 0, len(s) - 1), np.clip(j, 0, len(s) - 1)
    gap = (s[j1] - s[j0]) * 1e-9
    ok &= gap <= max_gap_s
    frac = np.where(s[j1] > s[j0], (t_ns - s[j0]) / np.maximum(s[j1] - s[j0], 1), 0.0)
    frac = np.clip(frac, 0.0, 1.0)[:, None, None]
    p = track.positions[j0] * (1 - frac) + track.positions[j1] * frac
    tw = track.weights()
    w = np.minimum(tw[j0], tw[j1]) * ok[:, None]
    return np.nan_to_num(p), w


def _period_s(track: Track) -> float:
    d = np.diff(track.stamps_ns) * 1e-9
    d = d[d > 0]
    return float(np.median(d)) if len(d) else 1.0 / 30.0


def _consistent_labels(pa: np.ndarray, pb: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(T,) bool: the frames whose left/right labelling agrees between the two views.

    A tracker that assumes the user faces it swaps left and right when seen from the back, and a
    tracker without joint states (the Azure Kinect body tracking's ROS message) reports the
    swapped joints as TRACKED. A swap turns the body's heading (from its hip and shoulder lines)
    by 180 deg in that view only, so the heading of A minus that of B is B's yaw in A (one
    value) on the frames labelled alike and that + 180 deg where one view swapped: the majority
    of the two (the axis of the doubled angles) is kept, the others dropped. Both views swapped
    at once pair the same physical joints and are kept."""
    used = (w > 0).any(axis=1)
    if used.sum() < 3:
        return used
    d = facing_yaw(pa) - facing_yaw(pb)
    axis = 0.5 * np.arctan2(np.sin(2 * d[used]).mean(), np.cos(2 * d[used]).mean())
    near = np.abs(np.angle(np.exp(1j * (d - axis)))) < np.pi / 2
    if (near & used).sum() < (~near & used).sum():
        near = ~near
    return used & near


MIN_VOTE_S = 0.5   # unmirrored: walking time a piece needs to decide its labelling


def unmirrored(track: Track, walk_speed: float = 0.2) -> Track:
    """A stream without joint states (every joint TRACKED) with its left/right swaps undone.

    A tracker that assumes the user faces it swaps left and right while it sees the back; with
    joint states the turned-away limbs are INFERRED and left out, without them (the Azure Kinect
    body tracking's ROS message) the swapped skeleton is reported TRACKED and the calibration
    fitted mirrored walks (on the sensor model, 5 of 10 seeds beyond 3 cm, three by a half lap
    and 150 deg). A swap turns the skeleton's heading by 180 deg from one frame to the next,
    which no person does: the heading jumps cut the track into pieces of one labelling, and
    each piece's labelling is the one whose heading agrees with the walking direction (the
    root's velocity, the calibration walk goes forward) on most of its moving frames; a piece
    without enough walking flips from the one before (the first keeps its labels)."""
    if not _stateless(track) or len(track) < 3:
        return track
    p = track.positions
    h = facing_yaw(p)
    jump = np.abs(np.angle(np.exp(1j * np.diff(h)))) > np.pi / 2
    piece = np.concatenate([[0], np.cumsum(jump)])
    t = track.stamps_ns * 1e-9
    root = p[:, HIP_CENTER, :2]
    k = max(1, int(round(0.25 / _period_s(track))))   # velocity over +-0.25 s
    idx = np.arange(len(t))
    lo, hi = np.clip(idx - k, 0, len(t) - 1), np.clip(idx + k, 0, len(t) - 1)
    v = (root[hi] - root[lo]) / np.maximum(t[hi] - t[lo], 1e-6)[:, None]
    moving = np.linalg.norm(v, axis=1) > walk_speed
    agree = np.cos(h) * v[:, 0] + np.sin(h) * v[:, 1]
    swap = np.zeros(len(t), bool)
    prev = False
    for n in range(int(piece[-1]) + 1):
        sel = piece == n
        signs = np.sign(agree[sel & moving])
        # a vote needs 0.5 s of walking and a clear majority (a walk on the spot sways)
        decided = len(signs) >= MIN_VOTE_S / _period_s(track) and \
            abs(signs.sum()) >= 0.2 * len(signs)
        cur = bool(signs.sum() < 0) if decided else (not prev if n > 0 else False)
        swap[sel] = cur
        prev = cur
    if not swap.any():
        return track
    pos = p.copy()
    pos[swap] = pos[swap][:, list(MIRROR)]
    return replace(track, positions=pos)


def _stateless(track: Track) -> bool:
    """Every joint of every frame TRACKED: a tracker whose stream carries no joint states."""
    return bool((track.tracking_state == TRACKED).all())


def correspondences(a: Track, b: Track, offset_s: float):
    """Matched joints: A's positions (N, 3), B's interpolated at A's stamps + offset (N, 3),
    weights (N,), A's frame index of each (N,) and joint (N,). When neither stream carries joint
    states (every joint TRACKED), the frames the two views label left and right differently are
    left out (:func:`_consistent_labels`); with states, the turned-away views' INFERRED limbs
    already are (and on the Kinect model the heading test dropped good profile frames: seed 1
    went from 1.35 to 3.6 cm)."""
    pb, wb = _interp(b, a.stamps_ns + int(round(offset_s * 1e9)), 1.5 * _period_s(b))
    w = a.weights() * wb
    if _stateless(a) and _stateless(b):
        w = w * _consistent_labels(a.positions, pb, w)[:, None]
    f, j = np.nonzero(w > 0)
    return a.positions[f, j], pb[f, j], w[f, j], f, j


def centred_fit(a: np.ndarray, b: np.ndarray, w: np.ndarray, joint: np.ndarray,
                inliers: np.ndarray):
    """The rigid fit of the joints' *motion*: each joint's trajectory centred on its own mean in
    both sensors, so that a constant per-joint offset between the two sensors' joint centres
    (the trackers' systematic error, several cm and different per view) drops out of the
    rotation; the translation is then the weighted mean of ``a - R b``. Trimmed iteratively on
    the centred residuals. Returns (transform, inlier mask, centred residuals)."""
    inl = inliers.copy()
    t, rc = None, None
    w0, w = w, w.copy()
    for _ in range(TRIM_ITERATIONS):
        ca, cb = np.zeros_like(a), np.zeros_like(b)
        keep = inl.copy()
        for j in np.unique(joint):
            m = inl & (joint == j)
            if m.sum() < 10:   # too few frames of this joint to know its mean
                keep &= joint != j
                continue
            ww = w[m][:, None]
            sel = joint == j
            ca[sel] = a[sel] - (ww * a[m]).sum(0) / ww.sum()
            cb[sel] = b[sel] - (ww * b[m]).sum(0) / ww.sum()
        if keep.sum() < 3:
            break
        rot = kabsch(ca[keep], cb[keep], w[keep]).matrix
        tr = (w[keep][:, None] * (a[keep] - b[keep] @ rot.T)).sum(0) / w[keep].sum()
        t = Transform.from_matrix(rot, tr)
        rc = np.linalg.norm(ca - cb @ rot.T, axis=1)
        if JOINT_NOISE_WEIGHTS:
            # each joint weighted by the inverse of its noise variance (hands and feet jitter
            # three times more than the torso)
            w = w0.copy()
            for j in np.unique(joint[keep]):
                m = keep & (joint == j)
                w[joint == j] /= max(float(np.mean(rc[m] ** 2)), 1e-6)
        sigma = 1.4826 * float(np.median(rc[keep]))
        new = (rc < max(TRIM_SIGMAS * sigma, TRIM_FLOOR_M)) & (
            np.isin(joint, np.unique(joint[keep])))
        if (new == inl).all():
            inl = keep
            break
        inl = new
    return t, inl, rc


def body_frame_fit(a: np.ndarray, b: np.ndarray, w: np.ndarray, joint: np.ndarray,
                   heading: np.ndarray, start: Transform, inliers: np.ndarray):
    """The rigid fit with each joint's offset between the two trackers modelled in the *body*
    frame: ``a = T b + Rz(heading) d_j`` (the trackers' joint centres differ by a few cm per
    joint, carried with the body as it turns; ``heading``: the body's yaw in A's frame per
    correspondence). Alternates the offsets ``d_j`` (mean of the rotated residuals) and ``T``
    (weighted Kabsch of the corrected points), joints weighted by the inverse of their residual
    variance, trimmed at ``TRIM_SIGMAS``. When the user faces every way (a walk round a loop)
    the offsets separate from ``T``; when the heading hardly changes they are a constant the
    motion-centred start already removed, and ``T`` stays where it was.
    Returns (transform, inlier mask, residuals)."""
    c, sn = np.cos(heading), np.sin(heading)
    t, inl = start, inliers.copy()
    joints = np.unique(joint)
    r = None
    for _ in range(BODY_FRAME_ITERATIONS):
        e = a - t.apply(b)
        body = np.stack([c * e[:, 0] + sn * e[:, 1], -sn * e[:, 0] + c * e[:, 1], e[:, 2]], 1)
        d = np.zeros((NUM_JOINTS, 3))
        ww = w.copy()
        for j in joints:
            m = inl & (joint == j)
            if m.sum() >= 10:
                d[j] = np.average(body[m], axis=0, weights=w[m])
        off = d[joint]
        world_off = np.stack([c * off[:, 0] - sn * off[:, 1], sn * off[:, 0] + c * off[:, 1],
                              off[:, 2]], 1)
        r = np.linalg.norm(e - world_off, axis=1)
        for j in joints:   # each joint by the inverse of its noise variance
            m = inl & (joint == j)
            if m.sum() >= 10:
                ww[joint == j] /= max(float(np.mean(r[m] ** 2)), 1e-6)
        new_t = kabsch(a[inl] - world_off[inl], b[inl], ww[inl])
        sigma = 1.4826 * float(np.median(r[inl]))
        new_inl = r < max(TRIM_SIGMAS * sigma, TRIM_FLOOR_M)
        done = (new_inl == inl).all() and sum(new_t.distance(t)) < 1e-7
        t, inl = new_t, new_inl
        if done or inl.sum() < 3:
            break
    return t, inl, r


def _centred_once(a, b, w, joint):
    """One motion-centred fit of every correspondence given (see :func:`centred_fit`)."""
    ca, cb = np.empty_like(a), np.empty_like(b)
    for j in np.unique(joint):
        m = joint == j
        ww = w[m][:, None]
        ca[m] = a[m] - (ww * a[m]).sum(0) / ww.sum()
        cb[m] = b[m] - (ww * b[m]).sum(0) / ww.sum()
    rot = kabsch(ca, cb, w).matrix
    tr = (w[:, None] * (a - b @ rot.T)).sum(0) / w.sum()
    return Transform.from_matrix(rot, tr), np.linalg.norm(ca - cb @ rot.T, axis=1)


def _fit_at(a: Track, b: Track, offset_s: float, rng, robust: bool = True, only=None):
    pa, pb, w, f, j = correspondences(a, b, offset_s)
    if only is not None:   # a fixed set of (frame, joint) correspondences, no trimming
        sel = only[f, j]
        pa, pb, w, f, j = pa[sel], pb[sel], w[sel], f[sel], j[sel]
    if len(pa) < MIN_PAIRS:
        return None
    if only is not None:
        t, rc = _centred_once(pa, pb, w, j)
        q = float(np.average(rc ** 2, weights=w))
        return t, np.ones(len(pa), bool), _residuals(t, pa, pb), q, len(pa), 0, rc
    inl0 = robust_fit(pa, pb, w, f, rng)[1] if robust else np.ones(len(pa), bool)
    t, inl, rc = centred_fit(pa, pb, w, j, inl0)
    if t is None:
        return None
    if robust and BODY_FRAME_OFFSETS:
        heading = facing_yaw(a.positions, a.weights())[f]
        t, inl, _ = body_frame_fit(pa, pb, w, j, heading, t, inl)
    # the fit's quality: the trimmed mean of the squared centred residuals of every
    # correspondence (a wrong offset moves every moving joint; the fraction kept does not hide it)
    q = float(np.mean(np.sort(rc ** 2)[:max(1, int(0.8 * len(rc)))]))
    r = _residuals(t, pa, pb)
    return t, inl, r, q, len(pa), len(set(f.tolist())), rc


def calibrate(a: Track, b: Track, seed: int = 0, max_offset_s: float = MAX_OFFSET_S,
              offset_s: Optional[float] = None) -> Calibration:
    """B's pose in A's frame and B's clock offset from two tracks of the same person (see the
    module docstring). ``offset_s``: a known offset (no search). Raises
    :class:`CalibrationError` with one line when the tracks do not allow it."""
    if len(a) < 10 or len(b) < 10:
        raise CalibrationError(f'too few frames ({len(a)} and {len(b)})')
    a, b = unmirrored(a), unmirrored(b)   # streams without joint states: swaps undone
    details: Dict = {}
    if offset_s is None:
        period = max(_period_s(a), _period_s(b))
        # every whole-frame offset scored by the motion fit it allows (a quick fit without
        # RANSAC); the joint-speed correlation ranks them too, as a check
        grid = np.arange(-max_offset_s, max_offset_s + 1e-9, period)
        scores = []
        for o in grid:
            fit = _fit_at(a, b, float(o), None, robust=False)
            scores.append(np.inf if fit is None else fit[3])
        scores = np.array(scores)
        if not np.isfinite(scores).any():
            raise CalibrationError(f'fewer than {MIN_PAIRS} joints tracked by both sensors at '
                                   f'the same time (clock offsets up to {max_offset_s:.1f} s '
                                   'tried)')
        best = float(grid[int(np.argmin(scores))])
        # refine to a fraction of a frame: golden-section search of the fit's quality over the
        # inliers of the robust fit at the best whole frame (a fixed set: a smooth function)
        pa, pb, w, f, j = correspondences(a, b, best)
        inl = _fit_at(a, b, best, np.random.default_rng(seed))[1]
        only = np.zeros((len(a), NUM_JOINTS), bool)
        only[f[inl], j[inl]] = True
        lo, hi = best - period, best + period
        g = (np.sqrt(5) - 1) / 2

        def quality(o):
            fit = _fit_at(a, b, o, None, only=only)
            return np.inf if fit is None else fit[3]
        x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
        f1, f2 = quality(x1), quality(x2)
        for _ in range(14):
            if f1 < f2:
                hi, x2, f2 = x2, x1, f1
                x1 = hi - g * (hi - lo)
                f1 = quality(x1)
            else:
                lo, x1, f1 = x1, x2, f2
                x2 = lo + g * (hi - lo)
                f2 = quality(x2)
        offset_s = 0.5 * (lo + hi)
    fit = _fit_at(a, b, offset_s, np.random.default_rng(seed))
    if fit is None:
        raise CalibrationError(f'fewer than {MIN_PAIRS} joints tracked by both sensors at the '
                               'same time')
    t, inl, r, _, pairs, frames, rc = fit
    rms = float(np.sqrt(np.mean(rc[inl] ** 2))) if inl.any() else float('nan')
    details['offset_rms_m'] = round(float(np.sqrt(np.mean(r[inl] ** 2))), 4)
    if inl.sum() < MIN_PAIRS:
        raise CalibrationError(f'only {int(inl.sum())} of {pairs} correspondences agree on one '
                               'placement: is it the same person in both recordings?')
    return Calibration(transform=t, time_offset_s=float(offset_s), rms_m=rms,
                       inliers=int(inl.sum()), pairs=pairs, frames=frames, details=details)


def pick_user(tracks: Dict[int, Track]) -> int:
    """The user to calibrate on: the one with the most tracked joint-frames."""
    if not tracks:
        raise CalibrationError('no skeletons in the recording')
    return max(tracks, key=lambda u: float(tracks[u].weights().sum()))


def tracks_from_frames(frames: Sequence) -> Dict[int, Track]:
    """Per user id, the :class:`Track` of a sequence of ``SkeletonFrame`` (e.g. a bag's)."""
    by: Dict[int, list] = {}
    for fr in frames:
        by.setdefault(int(fr.user_id), []).append(fr)
    out = {}
    for uid, fs in by.items():
        rel = [None if fr.reliability is None else np.asarray(fr.reliability, float) for fr in fs]
        # a reliability counts when every frame has one (the driver's raw skeletons carry none:
        # NaN, or all 0 / all 1)
        has_rel = all(r is not None and np.isfinite(r).all() for r in rel) and not all(
            np.all(r == 1.0) or np.all(r == 0.0) for r in rel)
        out[uid] = Track(stamps_ns=[fr.stamp_ns for fr in fs],
                         positions=[fr.positions for fr in fs],
                         tracking_state=[fr.tracking_state for fr in fs],
                         reliability=rel if has_rel else None,
                         frame_id=fs[0].frame_id)
    return out


CIRCLE_RADIUS_M = 1.3      # the calibration walk: a loop about 2.6 m across in the shared view ...
CIRCLE_WOBBLE = 0.6        # ... not a circle: c = R [(cos t, sin t) + 0.3 (cos 2t, sin 2t)]
# the sensor model's placement for it: no treadmill and no turning back to the first sensor (the
# walk goes round; the user faces every way)
WALK_PLACEMENT = {'placement': {'keep_facing': False, 'max_travel_m': 10.0}}


def walk_in_circle(clip, radius: float = CIRCLE_RADIUS_M, wobble: float = CIRCLE_WOBBLE):
    """A straight walk bent onto a closed loop about ``2 radius`` across (counter-clockwise; a
    circle with a ``wobble`` of twice its frequency, so it has no rotational symmetry): every
    frame's body keeps its pose relative to the root's progress and is carried round, facing
    along the path. The calibration walk: the user faces every way and the joints sweep the
    shared view, which the rotation needs (walking on the spot leaves it weak). The asymmetry
    matters: on a perfect circle a time shift and a rotation about the vertical look alike."""
    p = np.asarray(clip.positions, float)
    root = p[:, 0, :2]
    d = root[-1] - root[0]
    n = float(np.linalg.norm(d))
    if n < 0.5:
        raise ValueError(f'{getattr(clip, "name", "clip")}: not a walk (the root moves {n:.2f} m)')
    d = d / n
    left = np.array([-d[1], d[0]])
    rel = p[..., :2] - root[0]
    s = (root - root[0]) @ d                     # the root's progress (T,)
    u = rel @ d - s[:, None]                     # along the walk, relative to the root (T, J)
    v = rel @ left                               # to the left of the walk (T, J)
    # the path: the closed curve c(th) = R [(cos th, sin th) + wobble (cos 2th, sin 2th) / 2]
    # (no rotational symmetry), walked at the clip's own pace: th from the arc length
    laps = int(np.ceil(max(abs(s.min()), abs(s.max())) / (2 * np.pi * radius))) + 2
    th = np.linspace(-laps * 2 * np.pi, laps * 2 * np.pi, 4000 * laps)
    curve = radius * (np.stack([np.cos(th), np.sin(th)], 1)
                      + 0.5 * wobble * np.stack([np.cos(2 * th), np.sin(2 * th)], 1))
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
    arc -= np.interp(0.0, th, arc)
    tang = np.gradient(curve, axis=0)
    psi = np.unwrap(np.arctan2(tang[:, 1], tang[:, 0]))
    c = np.stack([np.interp(s, arc, curve[:, 0]), np.interp(s, arc, curve[:, 1])], 1)
    h = np.interp(s, arc, psi)
    fwd = np.stack([np.cos(h), np.sin(h)], 1)[:, None, :]
    lft = np.stack([-np.sin(h), np.cos(h)], 1)[:, None, :]
    out = p.copy()
    out[..., :2] = c[:, None, :] + u[..., None] * fwd + v[..., None] * lft
    return replace(clip, name=f'{getattr(clip, "name", "clip")}_loop', positions=out)


def synthetic_tracks(view: Transform, seed: int = 0, scenario: str = 'a', duration_s: float = 10.0,
                     clock_offset_s: float = 0.0, phase_s: float = 0.0, clip=None,
                     sensor_params=None, circle: bool = True):
    """Two sensors watching one person (the sensor model, :meth:`SensorModel.corrupt` with
    ``view``): A at the reference placement, B at ``view`` (its pose in A's frame), capturing
    ``phase_s`` later in the motion (0 to one period) and stamping with a clock ``clock_offset_s``
    ahead of A's. ``clip``: default the built-in walk of ``seed``, walked round a circle
    (:func:`walk_in_circle`; ``circle=False``: on the spot, facing A). Returns (A, B, truth of A)."""
    if clip is None:
        clip = builtin_clips(seed, duration=duration_s + 1.0)[0]
    if circle:
        clip = walk_in_circle(clip)
        sensor_params = _merge(load_params(sensor_params), WALK_PLACEMENT)
    model = SensorModel(sensor_params, seed=seed)
    n = int(round(duration_s * model.fps))
    sa = model.corrupt(clip, scenario, max_frames=n, view=Transform())
    sb = model.corrupt(clip, scenario, max_frames=n, view=view, time_shift_s=phase_s)
    start = 1_000_000_000_000
    a = Track(start + sa.stamps_ns, sa.positions, sa.tracking_state, frame_id='a')
    b = Track(start + sb.stamps_ns + int(round((phase_s + clock_offset_s) * 1e9)), sb.positions,
              sb.tracking_state, frame_id='b')
    return a, b, sa.truth


__all__ = ['synthetic_tracks', 'Track', 'Calibration', 'CalibrationError', 'calibrate', 'kabsch', 'robust_fit',
           'correspondences', 'pick_user', 'tracks_from_frames', 'walk_in_circle']
