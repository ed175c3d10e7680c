"""Per-joint reliability of a Kinect skeleton (Shum et al. 2013, Sec. IV, Eq. 1-8).

For every joint ``i`` and frame ``f`` three terms in [0, 1] are computed:

* behaviour ``R_b`` (Eq. 1-4): high-frequency vibration. ``theta_i(f)`` is the angle between two
  successive displacement vectors (0 when either is shorter than ``d_min``); the mean over the last
  ``f_b`` angles is mapped linearly from ``theta_floor`` (reliable) to ``theta_roof`` (unreliable);
* kinematics ``R_k`` (Eq. 5-6): ``1 -`` the mean, over the segments touching the joint, of the
  relative segment-length difference ``min(|l - l_ref| / l_ref, 1)`` against reference lengths;
* tracking state ``R_t`` (Eq. 7): 1 tracked, 0 inferred, 0 not tracked;

and the reliability is the Gaussian-weighted sum, over the last ``f_total`` frames, of the
per-frame minimum of the three (Eq. 8), the most recent frame weighted most.

Beyond the paper (``plausibility``, default on): the Kinect's confident failures — joints reported
TRACKED at a wrong place — are caught by :mod:`.plausibility` (bone lengths against the user's
profile, segment speed, left/right against the heading, floor penetration, whole-skeleton jumps);
the reliability is ``min(Eq. 8, R_p)``, so an implausible joint is unreliable from the frame it
becomes implausible, and the length profile learns only from plausible segments. With it, Eq. 6
judges a TRACKED joint by its segments to other TRACKED joints only (none: R_k = 1): a segment
whose other end is INFERRED (held at a stale place) or NOT_TRACKED has R_t = 0 there already and
must not make the tracked end unreliable too (the paper's Eq. 6 averaged it in: a tracked spine
above a hidden hip centre read R_k <= 0.5 and was replaced by the database). Nor does a
segment to an end joint (head, hand, foot) judge its parent when the parent has other segments:
the end joint has only that segment to be judged by, so a wrong length there is the end's (a hand
resting TRACKED on an object 10-20 cm off put the wrist beside it at R_k ~ 0.5 and handed the
well-seen forearm to the database). And a joint the sensor tracks again is not held down by the
frames of the window in which it was INFERRED: its reliability is at least Eq. 8 of
``min(R_b, R_k)`` with this frame's R_t (``_reacquired``; the paper's window held a re-acquired
shank at 0.33, 0.61, 0.81 and handed it to the database for 2-3 frames).

Reference segment lengths (Sec. IV-B) are captured automatically whenever every joint is tracked
and the posture is close to one of the two reference postures (T-pose, standing with arms down),
and refreshed the same way later. Until the first capture, ``reference_mode='observed'`` (default)
uses the median length of every segment over the recent frames in which both its joints were
tracked (``observed_window`` frames; a segment with fewer than 5 such frames falls back to the
standard body), so a sensor whose skeleton layout differs from the database body (real Kinect: a
spine about 14 cm longer than the CMU-derived standard body) does not make whole joints unreliable;
``reference_mode='standard'`` is the paper's behaviour: the standard body scaled to the user's
estimated height.
"""
from __future__ import annotations

import collections
import dataclasses
from dataclasses import dataclass
from typing import Deque, Optional, Tuple

import numpy as np

from skeleton_core.geometry import normalize
from skeleton_core.params import check, nested, param
from skeleton_core.model import (ANKLE_LEFT, ANKLE_RIGHT, ELBOW_LEFT, ELBOW_RIGHT, FOOT_LEFT,
                                 FOOT_RIGHT, HAND_LEFT, HAND_RIGHT, HEAD, HIP_LEFT, HIP_RIGHT,
                                 INFERRED, KNEE_LEFT, KNEE_RIGHT, NOT_TRACKED, NUM_JOINTS,
                                 NUM_SEGMENTS, SEGMENT_CHILDREN, SEGMENT_CHILD_INDEX,
                                 SEGMENT_OF_JOINT, SEGMENT_PARENT_INDEX, SHOULDER_CENTER,
                                 SHOULDER_LEFT, SHOULDER_RIGHT, SPINE, STANDARD_HEIGHT, TRACKED,
                                 WRIST_LEFT, WRIST_RIGHT, estimate_height, segment_lengths,
                                 standard_body)

from skeleton_core import jit

from .plausibility import PLAUSIBILITY_PARAMS, PlausibilityCheck, PlausibilityConfig
from .posture_space import heading_yaw

K = jit.lazy_module('pose_reconstruction.reliability_kernels')   # (numba: when first used)

REFERENCE_MODES = ('observed', 'standard')
# the ufunc np.clip calls on arrays with both bounds (numpy 2), without np.clip's Python layers
_clip = getattr(getattr(getattr(np, '_core', None), 'umath', None), 'clip', np.clip)
_ONES = [1.0] * NUM_JOINTS   # heading_yaw's weights: the hip and shoulder lines alike

# Joint-segment incidence (20, 19): a joint touches the segment ending at it and those leaving it.
INCIDENCE = np.zeros((NUM_JOINTS, NUM_SEGMENTS))
INCIDENCE[SEGMENT_PARENT_INDEX, np.arange(NUM_SEGMENTS)] = 1.0
INCIDENCE[SEGMENT_CHILD_INDEX, np.arange(NUM_SEGMENTS)] = 1.0
_INCIDENCE_COUNT = INCIDENCE.sum(axis=1)


def reference_directions() -> dict:
    """Unit segment directions (19, 3) of the two reference postures, facing +x (Fig. 2)."""
    body = standard_body()
    rest = body.rest_offsets[SEGMENT_CHILD_INDEX]
    tpose = rest / np.linalg.norm(rest, axis=1, keepdims=True)
    standing = tpose.copy()
    seg_of = {c: k for k, c in enumerate(SEGMENT_CHILDREN)}
    for j in (ELBOW_LEFT, WRIST_LEFT, HAND_LEFT, ELBOW_RIGHT, WRIST_RIGHT, HAND_RIGHT):
        standing[seg_of[j]] = (0.0, 0.0, -1.0)
    return {'tpose': tpose, 'standing': standing}


_REF_DIRS = reference_directions()
# segments judged by the reference-posture test: not the hands and feet (short, noisy on Kinect)
# and not the hip and shoulder girdles, whose direction is where each skeleton model puts its hip
# and shoulder joints, not a posture (CMU's pelvis segments point ~50 deg below the standard
# body's horizontal ones, so a CMU T-pose never matched)
_POSE_SEGS = np.array([k for k, c in enumerate(SEGMENT_CHILDREN)
                       if c not in (HAND_LEFT, HAND_RIGHT, FOOT_LEFT, FOOT_RIGHT,
                                    HIP_LEFT, HIP_RIGHT, SHOULDER_LEFT, SHOULDER_RIGHT)])
_REF_STACK = np.stack([_REF_DIRS['tpose'][_POSE_SEGS], _REF_DIRS['standing'][_POSE_SEGS]])
_REF_NAMES = ('tpose', 'standing')
# model.estimate_height from precomputed segment lengths: the leg + trunk + head chain against the
# standard body's
_HEIGHT_CHAIN = np.array([SEGMENT_OF_JOINT[j] for j in (SPINE, SHOULDER_CENTER, HEAD, KNEE_LEFT,
                                                        ANKLE_LEFT, KNEE_RIGHT, ANKLE_RIGHT)])
_HEIGHT_REF = float(standard_body().segment_lengths[_HEIGHT_CHAIN].sum())
_INCIDENCE_MEAN = INCIDENCE / INCIDENCE.sum(axis=1, keepdims=True)
# (20, 19): the segments a TRACKED joint is judged by with the plausibility stage (Eq. 6 without
# blaming a neighbour): its own, less a segment to an end joint (head, hand, foot) when the joint
# has others -- an end joint has only that segment to be judged by, so a wrong length there is
# the end's (a hand resting on an object 10-20 cm off), not its parent's
_END = INCIDENCE.sum(axis=1) == 1
_JUDGED_BY = INCIDENCE.copy()
for _s in range(NUM_SEGMENTS):
    for _a, _b in ((SEGMENT_PARENT_INDEX[_s], SEGMENT_CHILD_INDEX[_s]),
                   (SEGMENT_CHILD_INDEX[_s], SEGMENT_PARENT_INDEX[_s])):
        if _END[_b] and not _END[_a]:
            _JUDGED_BY[_a, _s] = 0.0
_SEG_COLS = np.arange(NUM_SEGMENTS)
_SEG_PAR = np.asarray(SEGMENT_PARENT_INDEX, np.int64)
_SEG_CHILD = np.asarray(SEGMENT_CHILD_INDEX, np.int64)


def _column_nanmedian(obs: np.ndarray, count: np.ndarray) -> np.ndarray:
    """``np.nanmedian(obs, axis=0)`` (same values) for columns with ``count`` >= 1 finite rows:
    one sort (NaN last) and the mean of the two middle finite values (np.nanmedian's small-array
    path goes through masked arrays, ~1 ms here)."""
    s = np.sort(obs, axis=0)
    h = count // 2
    lo = np.where(count % 2 == 1, h, np.maximum(h - 1, 0))
    return (s[lo, _SEG_COLS] + s[h, _SEG_COLS]) / 2.0


def _column_median(a: np.ndarray) -> np.ndarray:
    """``np.median(a, axis=0)`` (same values, NaN where a column holds one) by one sort."""
    s = np.sort(a, axis=0)
    n = len(s)
    med = (s[(n - 1) // 2] + s[n // 2]) / 2.0
    nan = np.isnan(s[-1])
    if nan.any():
        med[nan] = np.nan
    return med


def _median_of(values) -> float:
    """``np.median`` of a few floats (same value): sorted in Python, without array overhead."""
    v = sorted(values)
    n = len(v)
    return float(v[n // 2]) if n % 2 else (v[n // 2 - 1] + v[n // 2]) / 2.0


def behaviour_term(history: np.ndarray, d_min: float, f_b: int, theta_floor: float,
                   theta_roof: float) -> Tuple[np.ndarray, np.ndarray]:
    """Eq. 1-4 on a position history ``(T, 20, 3)`` (oldest first). Angles in radians.

    Returns ``(R_b (20,), theta (T-2, 20))``. Missing angles (short history) count as 0 in the
    mean over ``f_b`` angles, as do displacements shorter than ``d_min`` (Eq. 3).
    """
    h = np.asarray(history, float)
    if h.shape[0] < 3:
        return np.ones(h.shape[1]), np.zeros((0, h.shape[1]))
    d = np.diff(h, axis=0)                      # (T-1, 20, 3), Eq. 1-2
    n = np.linalg.norm(d, axis=-1)              # (T-1, 20)
    dot = np.sum(d[1:] * d[:-1], axis=-1)
    denom = n[1:] * n[:-1]
    ok = (n[1:] > d_min) & (n[:-1] > d_min)
    cos = np.where(ok, dot / np.where(ok, denom, 1.0), 1.0)
    theta = np.where(ok, np.arccos(np.clip(cos, -1.0, 1.0)), 0.0)  # Eq. 3
    mean = theta[-f_b:].sum(axis=0) / f_b
    rb = 1.0 - np.maximum(np.minimum(mean, theta_roof) - theta_floor, 0.0) / (theta_roof - theta_floor)
    return rb, theta


def kinematics_term(positions: np.ndarray, reference_lengths: np.ndarray) -> np.ndarray:
    """Eq. 5-6: ``R_k`` (20,) from the segment-length ratios against ``reference_lengths`` (19,)."""
    lengths = segment_lengths(positions)
    ref = np.maximum(np.asarray(reference_lengths, float), 1e-6)
    ds = np.minimum(np.abs(lengths - ref) / ref, 1.0)           # Eq. 5
    return 1.0 - (INCIDENCE @ ds) / _INCIDENCE_COUNT            # Eq. 6


def tracking_term(tracking_state: np.ndarray, tracked: float = 1.0, inferred: float = 0.0,
                  not_tracked: float = 0.0) -> np.ndarray:
    """Eq. 7."""
    t = np.asarray(tracking_state)
    out = np.full(t.shape, not_tracked, float)
    out[t == TRACKED] = tracked
    out[t == INFERRED] = inferred
    out[t == NOT_TRACKED] = not_tracked
    return out


def gaussian_weights(n: int, sigma: float) -> np.ndarray:
    """Normalised Gaussian weights for ``n`` frames, oldest first, the last (most recent) largest."""
    age = np.arange(n - 1, -1, -1, dtype=float)
    w = np.exp(-0.5 * (age / sigma) ** 2)
    return w / w.sum()


def reference_pose_match(positions: np.ndarray, tolerance_deg: float) -> Optional[str]:
    """Which reference posture (``'tpose'`` / ``'standing'``) the skeleton is in, or None.

    Compares segment directions after removing yaw: the largest angle over the segments (hands and
    feet left out: short and noisy on Kinect) must be below ``tolerance_deg``.
    """
    p, _ = normalize(positions)
    d = p[SEGMENT_CHILD_INDEX] - p[SEGMENT_PARENT_INDEX]
    n = np.linalg.norm(d, axis=1)
    if np.any(n < 1e-6):
        return None
    u = d / n[:, None]
    best, best_err = None, np.inf
    for name, ref in _REF_DIRS.items():
        err = np.degrees(np.max(np.arccos(np.clip(np.sum(u[_POSE_SEGS] * ref[_POSE_SEGS], axis=1),
                                                  -1.0, 1.0))))
        if err < best_err:
            best, best_err = name, err
    return best if best_err <= tolerance_deg else None


def _pose_match_segments(p: np.ndarray, seg: np.ndarray, ln: np.ndarray,
                         cos_tolerance: float) -> Optional[str]:
    """:func:`reference_pose_match` from precomputed segment vectors ``seg`` (19, 3) and lengths
    ``ln`` (19,): the same heading (hips + shoulders) and decision, compared as cosines."""
    if ln.min() < 1e-6:
        return None
    yaw = heading_yaw(p, _ONES)
    c, s = np.cos(yaw), np.sin(yaw)
    u = seg.take(_POSE_SEGS, axis=0)
    u /= ln.take(_POSE_SEGS)[:, None]
    rot = np.empty_like(u)
    rot[:, 0] = c * u[:, 0] + s * u[:, 1]
    rot[:, 1] = c * u[:, 1] - s * u[:, 0]
    rot[:, 2] = u[:, 2]
    worst = np.einsum('rsk,sk->rs', _REF_STACK, rot).min(axis=1)   # smallest cosine per posture
    best = 0 if worst[0] >= worst[1] else 1
    return _REF_NAMES[best] if worst[best] >= cos_tolerance else None


@dataclass
class ReliabilityConfig:
    """Parameters of :class:`ReliabilityEstimator` (Shum et al. 2013 Sec. IV; the paper's values
    except ``sigma_frames``, which the paper does not give)."""

    d_min: float = param(0.03, 'Eq. 3: minimum displacement (m) for an angle to count',
                         range=(0.0, 0.5), public=False)
    f_b: int = param(3, 'Eq. 4: frames averaged by the behaviour term', range=(1, 30),
                     public=False)
    theta_floor_deg: float = param(90.0, 'Eq. 4: acceptable angle change (deg)',
                                   range=(0.0, 180.0), public=False)
    theta_roof_deg: float = param(135.0, 'Eq. 4: fully unacceptable angle change (deg)',
                                  range=(0.0, 180.0), public=False)
    f_total: int = param(6, 'Eq. 8: frames in the Gaussian-weighted window', range=(1, 60),
                         public=False)
    sigma_frames: float = param(2.0, 'Eq. 8: width (frames) of the Gaussian weight',
                                range=(0.1, 60.0), public=False)
    tracked_value: float = param(1.0, 'Eq. 7: R_t of a tracked joint', range=(0.0, 1.0),
                                 public=False)
    inferred_value: float = param(0.0, 'Eq. 7: R_t of an inferred joint', range=(0.0, 1.0),
                                  public=False)
    not_tracked_value: float = param(0.0, 'Eq. 7: R_t of a not-tracked joint', range=(0.0, 1.0),
                                     public=False)
    reference_pose_tolerance_deg: float = param(
        25.0, 'largest segment-direction error (deg) to accept a T-pose / standing reference '
        'posture', range=(1.0, 90.0), public=False)
    reference_frames: int = param(15, 'reference segment lengths: median of this many captures',
                                  range=(1, 300), public=False)
    reference_mode: str = param(
        'observed', 'reference lengths before a reference posture is captured: observed (running '
        'median of tracked segments) or standard (the standard body at the user height, paper)',
        choices=REFERENCE_MODES, public=False)
    observed_window: int = param(90, 'reference_mode observed: frames in the running median',
                                 range=(1, 10000), public=False)
    plausibility: PlausibilityConfig = nested(PlausibilityConfig)

    def validate(self) -> None:
        check(self)
        if not self.theta_floor_deg < self.theta_roof_deg:
            raise ValueError('theta_floor_deg must be below theta_roof_deg')
        self.plausibility.validate()


class ReliabilityEstimator:
    """Streaming per-user reliability (Eq. 1-8). Call :meth:`update` once per frame.

    Parameters: :class:`ReliabilityConfig` fields as keywords (or ``config``). ``height`` /
    ``reference_lengths``: a known user height / reference lengths (tests, offline tools).
    """

    # compiled path: Eq. 1-8 and the re-acquisition floor in one call (False: two steps, the
    # floor in numpy; the tests compare the two)
    _k_reacquired = True

    def __init__(self, config: Optional[ReliabilityConfig] = None, *,
                 height: Optional[float] = None,
                 reference_lengths: Optional[np.ndarray] = None, **params):
        pl = {k: params.pop(k) for k in list(params) if k in PLAUSIBILITY_PARAMS}
        cfg = dataclasses.replace(config or ReliabilityConfig(), **params)
        if pl:
            cfg = dataclasses.replace(cfg, plausibility=dataclasses.replace(cfg.plausibility, **pl))
        cfg.validate()
        self.config = cfg
        # the confident-failure term (plausibility.py); min(Eq. 8, R_p)
        self.plausibility = PlausibilityCheck(cfg.plausibility)
        d_min, f_b, f_total, sigma_frames = cfg.d_min, cfg.f_b, cfg.f_total, cfg.sigma_frames
        theta_floor_deg, theta_roof_deg = cfg.theta_floor_deg, cfg.theta_roof_deg
        tracked_value, inferred_value = cfg.tracked_value, cfg.inferred_value
        not_tracked_value = cfg.not_tracked_value
        reference_pose_tolerance_deg = cfg.reference_pose_tolerance_deg
        reference_frames, reference_mode = cfg.reference_frames, cfg.reference_mode
        observed_window = cfg.observed_window
        self.d_min = float(d_min)
        self.f_b = int(f_b)
        self.theta_floor = np.radians(theta_floor_deg)
        self.theta_roof = np.radians(theta_roof_deg)
        self.f_total = int(f_total)
        self.sigma_frames = float(sigma_frames)
        self.tracked_value = float(tracked_value)
        self.inferred_value = float(inferred_value)
        self.not_tracked_value = float(not_tracked_value)
        self.reference_pose_tolerance_deg = float(reference_pose_tolerance_deg)
        self._cos_tolerance = float(np.cos(np.radians(self.reference_pose_tolerance_deg)))
        self._rt_lut = np.array([not_tracked_value, inferred_value, tracked_value], float)
        # Eq. 7 for uint8 states in one lookup: any value other than 1 or 2 counts as not tracked
        self._rt_lut8 = np.full(256, float(not_tracked_value))
        self._rt_lut8[:3] = self._rt_lut
        self._std_height: Optional[float] = None
        self._std_lengths: Optional[np.ndarray] = None
        self._gauss = [None] + [gaussian_weights(n, sigma_frames) for n in range(1, f_total + 1)]
        # the compiled step (reliability_kernels) when numba is on; row n of the table: weights
        # for n frames
        self._jit = jit.enabled()
        if self._jit:
            K.warm_up()   # the compiled step, once per process: not on a user's first frame
        self._gauss_table = np.zeros((f_total + 1, f_total))
        for n in range(1, f_total + 1):
            self._gauss_table[n, :n] = self._gauss[n]
        self.reference_frames = int(reference_frames)
        self.reference_mode = reference_mode
        self.observed_window = int(observed_window)
        self._fixed_height = height
        self._fixed_reference = None if reference_lengths is None else np.asarray(reference_lengths, float)
        self.reset()

    def reset(self) -> None:
        self._last_p: Optional[np.ndarray] = None     # behaviour term, streamed (Eq. 1-4)
        self._last_d: Optional[np.ndarray] = None
        self._last_n: Optional[np.ndarray] = None
        self._theta: Deque[np.ndarray] = collections.deque(maxlen=self.f_b)
        self._minima: Deque[np.ndarray] = collections.deque(maxlen=self.f_total)
        # Eq. 8's window of min(R_b, R_k) alone (_reacquired): rows oldest first, _bk_n filled
        self._bk = np.zeros((self.f_total, NUM_JOINTS))
        self._bk_n = np.zeros(1, np.int64)
        # the compiled step's state (the same quantities, as rings oldest first)
        self._k_last_p = np.zeros((NUM_JOINTS, 3))
        self._k_last_d = np.zeros((NUM_JOINTS, 3))
        self._k_last_n = np.zeros(NUM_JOINTS)
        self._k_stage = np.zeros(1, np.int64)
        self._k_theta = np.zeros((self.f_b, NUM_JOINTS))
        self._k_theta_n = np.zeros(1, np.int64)
        self._k_minima = np.zeros((self.f_total, NUM_JOINTS))
        self._k_minima_n = np.zeros(1, np.int64)
        self._heights: Deque[float] = collections.deque(maxlen=30)
        self._captured: Deque[np.ndarray] = collections.deque(maxlen=self.reference_frames)
        self.reference_source = 'standard'
        self._height = standard_body().height
        self._height_prior: Optional[float] = None
        self._frames_since_height = 0
        self._reference: Optional[np.ndarray] = None
        self._observed = np.full((self.observed_window, NUM_SEGMENTS), np.nan)
        self._observed_n = 0
        self._observed_median: Optional[np.ndarray] = None
        self.last_terms: Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]] = None
        self.reliability = np.ones(NUM_JOINTS)
        self.plausibility.reset()

    # -- reference lengths ---------------------------------------------------------------------
    @property
    def height(self) -> float:
        """The user's estimated standing height (m): fixed, else measured on frames with every
        joint tracked, else the prior set by :meth:`set_height_prior`, else the standard body's."""
        if self._fixed_height is not None:
            return float(self._fixed_height)
        if self._height_prior is not None and not self._heights:
            return self._height_prior
        return self._height

    @property
    def height_measured(self) -> bool:
        """True when the height comes from the sensor (fixed, or frames with every joint
        tracked), not from a prior or the standard body."""
        return self._fixed_height is not None or bool(self._heights)

    def set_height_prior(self, height: Optional[float]) -> None:
        """The height to use while no frame had every joint tracked (e.g. fitted to a motion
        database by the reconstructor); None = the standard body's. The standard-body reference
        lengths follow it."""
        h = None if height is None else float(np.clip(height, 1.0, 2.3))
        if h != self._height_prior:
            self._height_prior = h
            if not self._heights:
                self._reference = None

    @property
    def reference_lengths(self) -> np.ndarray:
        """(19,) the user's reference segment lengths (captured, or standard body at height)."""
        if self._fixed_reference is not None:
            return self._fixed_reference
        if self._reference is None:
            if self._captured:
                self._reference = _column_median(np.asarray(self._captured))
            else:
                std = self._standard_lengths(self.height)
                med = self._observed_median
                self._reference = std if med is None else np.where(np.isfinite(med), med, std)
        return self._reference

    @property
    def profile_lengths(self) -> np.ndarray:
        """(19,) the user's own segment lengths for the plausibility term: fixed or captured in a
        reference posture, else (reference_mode 'observed') the running median of the tracked
        lengths, NaN for a segment not observed yet (never the standard body, whose layout may
        differ from the sensor's); reference_mode 'standard': the reference lengths."""
        if (self._fixed_reference is not None or self._captured
                or self.reference_mode == 'standard'):
            return self.reference_lengths
        med = self._observed_median
        return np.full(NUM_SEGMENTS, np.nan) if med is None else med

    def _standard_lengths(self, height: float) -> np.ndarray:
        """``standard_body(height).segment_lengths``, kept for the last height asked for (the
        reference is recomputed whenever the observed median is refreshed)."""
        if self._std_height != height:
            self._std_height = height
            self._std_lengths = standard_body(height).segment_lengths
        return self._std_lengths

    def _observe_lengths(self, tracked: np.ndarray, lengths: np.ndarray) -> None:
        """Running median of the tracked segments' lengths (reference_mode 'observed');
        ``tracked`` (20,) bool, ``lengths`` (19,) this frame's segment lengths."""
        if self.reference_mode != 'observed':
            return
        good = tracked[SEGMENT_PARENT_INDEX] & tracked[SEGMENT_CHILD_INDEX]
        row = self._observed[self._observed_n % self.observed_window]
        row[:] = lengths
        row[~good] = np.nan
        self._observed_n += 1
        n = self._observed_n
        if n <= 10 or n % 10 == 0:  # often at first, then every 10 frames
            obs = self._observed[:min(n, self.observed_window)]
            count = np.sum(np.isfinite(obs), axis=0)
            med = np.full(NUM_SEGMENTS, np.nan)
            ok = count >= min(5, n)
            if ok.any():
                med[ok] = _column_nanmedian(obs, count)[ok]
            self._observed_median = med
            if not self._captured:
                self._reference = None

    def _observe_reference(self, positions: np.ndarray, seg: np.ndarray,
                           lengths: np.ndarray) -> None:
        """A frame with every joint tracked: height estimate, reference posture capture."""
        h = STANDARD_HEIGHT * float(lengths[_HEIGHT_CHAIN].sum()) / _HEIGHT_REF
        self._heights.append(h if np.isfinite(h) else estimate_height(positions))
        self._frames_since_height += 1
        if len(self._heights) < 30 or self._frames_since_height >= 10:
            self._frames_since_height = 0
            h = min(max(_median_of(self._heights), 1.0), 2.3)
            if abs(h - self._height) > 1e-4:
                self._height = h
                self._reference = None
        pose = _pose_match_segments(positions, seg, lengths, self._cos_tolerance)
        if pose is not None:
            self._captured.append(lengths.copy())
            self.reference_source = pose
            self._reference = None

    # -- streaming -------------------------------------------------------------------------------
    def _update_compiled(self, p, ts, tracked, ln, rp) -> np.ndarray:
        """Eq. 1-8 of :meth:`update` in one compiled call (reliability_kernels.eq18_step),
        with the plausibility stage its re-acquisition floor too (:meth:`_reacquired`:
        reliability_kernels.eq18_reacquired_step, the same bits)."""
        rb = np.empty(NUM_JOINTS)
        rk = np.empty(NUM_JOINTS)
        rt = self._rt_lut8[ts]
        judge = self.plausibility.enabled
        if judge and self._k_reacquired:
            out = np.empty(NUM_JOINTS)
            K.eq18_reacquired_step(p, ln, self.reference_lengths, tracked, rt,
                                   rt if rp is None else rp, rp is not None, judge, self.d_min,
                                   self.theta_floor, self.theta_roof, self._k_last_p,
                                   self._k_last_d, self._k_last_n, self._k_stage, self._k_theta,
                                   self._k_theta_n, self._k_minima, self._k_minima_n,
                                   self._gauss_table, _JUDGED_BY, _INCIDENCE_MEAN, _SEG_PAR,
                                   _SEG_CHILD, rb, rk, self._bk, self._bk_n, out)
            self.last_terms = (rb, rk, rt)
            self.reliability = out
            return out
        r = K.eq18_step(p, ln, self.reference_lengths, tracked, rt,
                        rt if rp is None else rp, rp is not None, judge, self.d_min,
                        self.theta_floor, self.theta_roof, self._k_last_p, self._k_last_d,
                        self._k_last_n, self._k_stage, self._k_theta, self._k_theta_n,
                        self._k_minima, self._k_minima_n, self._gauss_table, _JUDGED_BY,
                        _INCIDENCE_MEAN, _SEG_PAR, _SEG_CHILD, rb, rk)
        self.last_terms = (rb, rk, rt)
        self.reliability = r
        return r

    def update(self, positions: np.ndarray, tracking_state: np.ndarray) -> np.ndarray:
        """Add one frame; return the reliability (20,) in [0, 1] (Eq. 8)."""
        p = np.ascontiguousarray(positions, dtype=float)   # one compiled layout
        ts = np.asarray(tracking_state)
        seg = p.take(SEGMENT_CHILD_INDEX, axis=0)
        seg -= p.take(SEGMENT_PARENT_INDEX, axis=0)
        ln = np.sqrt(np.einsum('sk,sk->s', seg, seg))
        tracked = ts == TRACKED
        profile = tracked
        rp = None
        if self.plausibility.enabled:
            # confident failures (plausibility.py) against the profile so far; the profile
            # learns only from plausible joints: a hand snapped to a table for a second must not
            # become the user's forearm
            rp = self.plausibility.update(p, ts, self.profile_lengths, seg, ln)
            profile = tracked & self.plausibility.lengths_plausible()
        if profile.all():
            self._observe_reference(p, seg, ln)
        self._observe_lengths(profile, ln)
        if self._jit and ts.dtype == np.uint8:
            r = self._update_compiled(p, ts, tracked, ln, rp)
            return r if self.plausibility.enabled and self._k_reacquired else self._reacquired(r, rp)
        # Eq. 1-4, one new angle per frame (as behaviour_term on the last f_b + 2 positions)
        if self._last_p is not None:
            d = p - self._last_p
            n = np.sqrt(np.einsum('jk,jk->j', d, d))
            if self._last_d is not None:
                ok = (n > self.d_min) & (self._last_n > self.d_min)
                dot = np.einsum('jk,jk->j', d, self._last_d)
                cos = np.where(ok, dot / np.where(ok, n * self._last_n, 1.0), 1.0)
                np.maximum(cos, -1.0, out=cos)   # np.clip, without its Python wrapper
                np.minimum(cos, 1.0, out=cos)
                self._theta.append(np.where(ok, np.arccos(cos), 0.0))
            self._last_d, self._last_n = d, n
        self._last_p = p
        if self._theta:
            mean = sum(self._theta) / self.f_b
            rb = 1.0 - (np.maximum(np.minimum(mean, self.theta_roof) - self.theta_floor, 0.0)
                        / (self.theta_roof - self.theta_floor))
        else:
            rb = np.ones(NUM_JOINTS)
        # Eq. 5-6
        ref = self.reference_lengths
        ds = np.abs(ln - ref)
        ds /= np.maximum(ref, 1e-6)
        np.minimum(ds, 1.0, out=ds)
        rk = 1.0 - _INCIDENCE_MEAN @ ds
        if self.plausibility.enabled:
            # blame where it belongs: a segment with an end the sensor does not track (R_t = 0
            # there already; an INFERRED joint is held at a stale place) says nothing about its
            # TRACKED end. Eq. 6 averages it in, so a tracked spine above a table-hidden hip
            # centre, or a tracked knee below a hidden hip, reads R_k <= 0.5 and is handed to the
            # database although the sensor sees it; likewise a tracked wrist beside a
            # tracked hand resting 10-20 cm off on an object. A tracked joint is judged by its
            # segments to other tracked joints only, less a segment to an end joint when it has
            # others (_JUDGED_BY; none left: R_k = 1; bone lengths of confident failures are the
            # plausibility term's).
            both = (tracked.take(SEGMENT_PARENT_INDEX) & tracked.take(SEGMENT_CHILD_INDEX))
            cnt = _JUDGED_BY @ both
            rk_t = 1.0 - (_JUDGED_BY @ (ds * both)) / np.maximum(cnt, 1.0)
            rk = np.where(tracked, rk_t, rk)
        # Eq. 7
        if ts.dtype == np.uint8:
            rt = self._rt_lut8[ts]
        elif ts.dtype.kind in 'ui' and ts.size and 0 <= ts.min() and ts.max() <= 2:
            rt = self._rt_lut[ts]
        else:
            rt = tracking_term(ts, self.tracked_value, self.inferred_value, self.not_tracked_value)
        self.last_terms = (rb, rk, rt)
        m = np.minimum(rb, rk)
        np.minimum(m, rt, out=m)
        self._minima.append(m)
        w = self._gauss[len(self._minima)]
        r = w @ np.asarray(self._minima)
        if rp is not None:
            # confident failures: implausible now is unreliable now (not Gaussian-delayed)
            np.minimum(r, rp, out=r)
        np.maximum(r, 0.0, out=r)
        np.minimum(r, 1.0, out=r)
        self.reliability = r
        return self._reacquired(r, rp)

    def _reacquired(self, r: np.ndarray, rp: Optional[np.ndarray]) -> np.ndarray:
        """With the plausibility stage: a joint the sensor tracks again is not held down by the
        frames in which it was INFERRED or NOT_TRACKED. Eq. 8 smooths ``min(R_b, R_k, R_t)`` over
        its window, so a joint re-acquired TRACKED read 0.33, 0.61, 0.81 on its first three
        frames and its segments were filled by the database although the sensor saw them
        (the re-acquired shanks of classes b, c, e). The tracking state is the SDK's statement
        about this frame, not a noisy measurement: the reliability is at least ``min(Eq. 8 of
        min(R_b, R_k), R_t now)`` -- the behaviour and length terms keep their window, a
        vibrating or wrong-length joint stays unreliable -- and still at most ``R_p``. Losing a
        joint is unchanged (R_t 0 now: Eq. 8 as the paper)."""
        if not self.plausibility.enabled or self.last_terms is None:
            return r
        rb, rk, rt = self.last_terms
        bk = self._bk
        n = int(self._bk_n[0])
        if n < len(bk):
            n += 1
            self._bk_n[0] = n
        else:
            bk[:-1] = bk[1:]
        np.minimum(rb, rk, out=bk[n - 1])
        # the window's rows as one contiguous (n, J) block: the product np.asarray(deque) gave
        now = self._gauss[n] @ bk[:n]
        np.minimum(now, rt, out=now)
        out = np.maximum(r, now)
        if rp is not None:
            np.minimum(out, rp, out=out)
        _clip(out, 0.0, 1.0, out=out)     # np.clip's ufunc, without its Python wrapper
        self.reliability = out
        return out
