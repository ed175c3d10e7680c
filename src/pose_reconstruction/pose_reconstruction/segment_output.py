"""Output stage ``'segments'`` of methods B/C: constant user lengths, blended and smoothed segments.

Every segment's direction is a blend of the database solution's and the observed one; the
weight of the observation is the larger of its expected-error weight (for a segment whose two ends
are reliable, at or above ``reliable_threshold``; 0 otherwise: ``direction_fusion``, the
observation's direction error from the user's joint-centre offsets and the segment's length
against the database's -- a constant plus, with ``direction_db_spread``, the spread of the K
neighbours' directions of that segment: where they disagree the database knows it less --, so a
long segment the sensor sees follows it and a short one takes the database's direction;
``observation_weight`` when off) and the *trust in the sensor*
(:mod:`.trust`) times min(1, reliability of the less reliable end / ``reliable_threshold``). One
rigid skeleton per user: the segments get the user's constant lengths (:mod:`.bone_lengths`: the
robust mean of the first trusted observations of each segment, ``length_min_frames`` to
``length_frames`` of them (until its standard error is at most ``length_tolerance``), frozen then or
``length_settle_s`` after the first; estimated again when the observed lengths disagree with them
by more than ``length_new_person`` for ``length_new_person_s``: another person under the same id;
with ``symmetric_lengths`` the left and right limbs share the mean of their two lengths) and are
chained from the observed root. The lengths are imposed last, after the smoothing: every output
posture has exactly them (to float precision). Chaining adds
every segment's length and direction error down the chain (a spine 1 cm longer than the sensor's
moves the head and both arms by 1 cm), so where the sensor is trusted ``position_fit`` places the
constant-length skeleton nearest the observed joints instead: each joint pulled towards its
observation by ``position_fit`` times the trust times min(1, reliability / ``reliable_threshold``),
the lengths then restored by moving both ends of each segment, the result's directions kept
(on the UI-PRMD recordings, where the sensor is trusted, this is what the constant lengths cost in
MPJPE; docs/real_recordings.md). The segment
vectors and the root are smoothed by a One Euro filter (``smooth_min_cutoff`` Hz, ``smooth_beta``
s/m, ``smooth_d_cutoff`` Hz; ``smooth_min_cutoff`` 0 = off); a segment the database fills in (an
end with reliability 0) gets ``smooth_filled_scale`` times the cutoff (1 at or above
``reliable_threshold``, linear between); a segment the output takes from the sensor gets up to
``smooth_trusted_scale`` times the cutoff (in proportion to the observed direction's weight in
it; the root: to the trust times its reliability fraction): the smoothing's lag no longer bends
what the sensor gives right, the full smoothing stays on what the database fills in.
``filled_memory_s``: a segment the database fills (an end below ``reliable_threshold``) starts
from where the sensor last saw it reliably, in proportion to the trust in the sensor times its
unreliable fraction, the memory fading as ``exp(-age / filled_memory_s)``: where the database
does not explain the user (trust ~1, the real recordings) a glitch of a few frames keeps the last
seen direction, not a fill from postures unlike the user's; where it does (trust ~0) nothing
changes. ``smooth_anchored_speed``: see :mod:`.reconstructor`.
``smooth_lead`` (prediction correction, default 1): on the reliable
segments (in proportion to ``min(1, reliability / reliable_threshold)`` of the less reliable
end) and the root, the low-pass lag is added back along the smoothed velocity
(``OneEuroFilter`` ``lead``): no lag on a ramp, so the light smoothing of what the sensor gives
reliably adds no latency, and the heavy smoothing stays on the filled segments. The velocity it
leads along trails the motion by its own low-pass lag; ``smooth_lead_accel`` extrapolates it
along the smoothed acceleration over that lag and the low-pass lag (no lag when the motion
accelerates either). That acceleration is where the
noise is (it made the lead's jitter): it passes a second low-pass whose cutoff rises with its own
magnitude (``smooth_accel_cutoff`` + ``smooth_accel_beta`` |acceleration|, a One Euro filter on
the acceleration): heavily smoothed where it is at its noise level, followed where it is large.
``smooth_lead_speed``: the lead fades on segments slower than that (gain ``|v|^2 / (|v|^2 +
s^2)``): their lag is small, and their velocity estimate is mostly the sensor's slow wander,
which the full lead put back (on the real recordings it cost the direction the smoothing gains).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from skeleton_core import jit
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.filters import OneEuroFilter
from skeleton_core.geometry import yaw_matrix
from skeleton_core.model import (MIRROR, NUM_JOINTS, NUM_SEGMENTS, ROOT, SEGMENT_CHILDREN,
                                 SEGMENT_CHILD_INDEX, SEGMENT_PARENT_INDEX)
from skeleton_core.params import check, param

from .body_fit import torso_weight
from .bone_lengths import BoneLengthEstimator
from .posture_space import ANCESTORS

# the compiled per-user arithmetic of output_rows (numba: when first used; the numpy code here is
# its twin, run when numba is off)
_kernels = jit.lazy_module('pose_reconstruction.segment_output_kernels')
_EYE3 = np.eye(3)
_ZERO3 = np.zeros(3)
_NO_WEIGHTS = np.zeros(NUM_SEGMENTS)

_MIRROR_SEG = np.array([SEGMENT_CHILDREN.index(MIRROR[c]) for c in SEGMENT_CHILDREN])
# (19, 20): positions -> segment vectors (child - parent); (20, 19): segment vectors -> positions
# relative to the root (the segments on the way from the root)
SEG_DIFF = np.zeros((NUM_SEGMENTS, NUM_JOINTS))
SEG_DIFF[np.arange(NUM_SEGMENTS), SEGMENT_CHILD_INDEX] = 1.0
SEG_DIFF[np.arange(NUM_SEGMENTS), SEGMENT_PARENT_INDEX] -= 1.0
_SEG_CHAIN = ANCESTORS[:, SEGMENT_CHILD_INDEX]
# (19, 20): 1 for the joints at and below each segment's child (what hangs from the segment)
_SEG_BELOW = np.ascontiguousarray(_SEG_CHAIN.T)
# (20,) 1 / number of segments at each joint (position_fit's averaged corrections)
_INV_DEGREE = 1.0 / np.abs(SEG_DIFF).sum(axis=0)
_HALF_INV_DEGREE = 0.5 * _INV_DEGREE
_SEG_CHAIN_C = np.ascontiguousarray(_SEG_CHAIN)   # (the compiled kernel's layout)
# direction_fusion: the direction error of the database solution on a segment (deg): C's mean
# direction error on the TRACKED, fault-free segment-frames of the dev clips is 10-11 deg (no-harm
# table, sensor seed 0); 8, 10, 12 and 16 were tried on seed 0, 12 harmed fewest segments
_DB_DIRECTION_VAR = np.radians(12.0) ** 2
# direction_fusion without a length prior: the joint-centre offset of a tracked joint (m per
# axis; length_offset_sigma's default, the sensor model's 2-4 cm)
_OFFSET_SIGMA = 0.03


@dataclass
class SmoothingStep:
    """A user's segment output at its smoothing filter (:meth:`SegmentOutput.output_rows`): the
    segment vectors and the root to smooth (``rows`` (20, 3)), the filter's arguments (``filter``
    None without smoothing) and what :meth:`SegmentOutput.output_positions` needs after it."""

    rows: np.ndarray
    lengths: np.ndarray
    directions: np.ndarray
    filter: Optional[OneEuroFilter] = None
    stamp_ns: int = 0
    cutoff_scale: Optional[np.ndarray] = None
    speed_scale: Optional[np.ndarray] = None
    lead: Optional[np.ndarray] = None

    def smooth(self) -> np.ndarray:
        """The rows through the user's filter (the rows themselves without smoothing)."""
        return self.rows if self.filter is None else self.filter.update(
            self.rows, None, self.stamp_ns, self.cutoff_scale, self.speed_scale, self.lead)


def smooth_many(steps) -> list:
    """``[s.smooth() for s in steps]`` of several users' steps (None: None), their One Euro
    updates stacked (``OneEuroFilter.update_many``: the same numbers); an element is the
    exception that user's filter raised."""
    out = [None if s is None else s.rows for s in steps]
    on = [k for k, s in enumerate(steps) if s is not None and s.filter is not None]
    if on:
        args = [(s.filter, s.rows, s.stamp_ns, s.cutoff_scale, s.speed_scale, s.lead)
                for s in (steps[k] for k in on)]
        for k, rows in zip(on, OneEuroFilter.update_many(*zip(*args))):
            out[k] = rows
    return out


@dataclass
class SegmentOutputConfig:
    """Parameters of :class:`SegmentOutput` (their reconstruction parameter names)."""

    observation_weight: float = param(
        0.3, 'segments: weight of the observed direction of a segment with two reliable ends',
        range=(0.0, 1.0), public=False)
    length_frames: int = param(
        15, "segments: trusted observations per segment behind the user's constant length at "
        'most (their robust mean), fewer when length_tolerance is met', range=(1, 100000),
        public=False)
    length_min_frames: int = param(
        3, 'segments: trusted observations per segment at least', range=(1, 100000),
        public=False)
    length_tolerance: float = param(
        0.003, "segments: a segment's length estimate is good enough when its standard error "
        '(sample std / sqrt(n), m) is at most this: a steady sensor converges in '
        'length_min_frames frames (the output\'s lengths change only then), a noisy one '
        'averages up to length_frames', range=(0.0, 1.0), public=False)
    length_settle_s: float = param(
        2.0, "segments: the user's lengths are frozen at the latest this long (s) after the "
        'first trusted observation (a segment unseen by then keeps the length prior / reference '
        'length); 0 = only when every segment has length_frames observations',
        range=(0.0, 3600.0), public=False)
    length_new_person: float = param(
        0.12, 'segments: the observed lengths disagreeing with the frozen ones by more than this '
        '(|median over the trusted segments of log(observed / frozen)|: a size change, averaged '
        'over length_new_person_s) is taken as another person under the same id: the lengths '
        'are estimated again; 0 = never', range=(0.0, 10.0), public=False)
    length_new_person_s: float = param(
        3.0, 'segments: how long (s) the lengths must disagree before they are estimated again',
        range=(0.05, 3600.0), public=False)
    symmetric_lengths: bool = param(True, 'segments: left and right limbs share their mean '
                                    'lengths', public=False)
    smooth_min_cutoff: float = param(
        1.3, 'segments: One Euro minimum cutoff (Hz) of segment and root smoothing, 0 = off',
        range=(0.0, 1000.0), public=False)
    smooth_beta: float = param(3.0, 'segments: One Euro speed coefficient (s/m)',
                               range=(0.0, 1e6), public=False)
    smooth_d_cutoff: float = param(2.0, 'segments: One Euro speed cutoff (Hz)',
                                   range=(1e-3, 1000.0), public=False)
    smooth_lead: float = param(
        1.0, 'segments: prediction correction of the smoothing on reliable segments and the root '
        '(fraction of the low-pass lag added back along the smoothed velocity; 1 = no lag on a '
        'ramp, 0 = plain One Euro); filled segments keep the plain low-pass', range=(0.0, 1.0),
        public=False)
    smooth_lead_accel: float = param(
        1.0, 'segments: gain of the acceleration term of the prediction correction (the lead '
        'velocity extrapolated over its own and the low-pass lag; 1 = exact to first order on a '
        'constant acceleration, 0 = off)', range=(0.0, 2.0), public=False)
    smooth_accel_cutoff: float = param(
        0.25, 'segments: minimum cutoff (Hz) of a second low-pass stage on the acceleration the '
        'prediction correction extrapolates along (the acceleration is where the noise is; a '
        'trailing acceleration costs lag only where the acceleration changes); 0 = no stage',
        range=(0.0, 1000.0), public=False)
    smooth_accel_beta: float = param(
        3.0, 'segments: the cutoff of that acceleration stage rises by this times the '
        'acceleration magnitude (Hz per m/s2; a One Euro filter on the acceleration: heavy '
        'smoothing where the acceleration is at its noise level, light in real accelerations)',
        range=(0.0, 1e6), public=False)
    smooth_lead_speed: float = param(
        0.1, 'segments: speed (m/s) below which the prediction correction fades (its gain '
        '|v|^2 / (|v|^2 + this^2), v the velocity it leads along): a slow segment\'s lag is '
        'small (at most the low-pass time constant times half this: 1.5 mm at the trusted '
        'cutoff) and its velocity estimate mostly the sensor\'s slow noise; 0 = the full lead '
        'at every speed', range=(0.0, 10.0), public=False)
    position_fit: float = param(
        1.0, 'segments: where the sensor is trusted, place the constant-length skeleton nearest '
        'the observed joints rather than chain it from the observed root (pull of each joint '
        'towards its observation: this times the trust times min(1, reliability / '
        'reliable_threshold), then the lengths restored by moving both ends of each segment); '
        'chaining adds every segment\'s length and direction error down the chain; 0 = off',
        range=(0.0, 1.0), public=False)
    position_fit_iterations: int = param(
        8, 'segments: length-restoring passes of position_fit (all segments at once, each end '
        'half of the length error)', range=(1, 100), public=False)
    smooth_filled_scale: float = param(
        0.2, 'segments: cutoff factor of a segment the database fills in (an end with '
        'reliability 0; 1 at or above reliable_threshold, linear between), 1 = same smoothing '
        'everywhere', range=(0.01, 1.0), public=False)
    direction_fusion: bool = param(
        True, 'segments: the observed direction of a segment with two reliable ends weighted by '
        "its expected error (the user's joint-centre offsets across the segment) against the "
        "database solution's; false = observation_weight everywhere", public=False)
    smooth_trusted_scale: float = param(
        4.0, 'segments: cutoff factor of the smoothing of a segment the output takes from the '
        'sensor (in proportion to the observed direction\'s weight in it) and of the root (to '
        'the trust times its reliability fraction); 1 = the same smoothing everywhere',
        range=(1.0, 100.0), public=False)
    direction_db_spread: bool = param(
        True, 'segments, direction_fusion: the database solution\'s direction error of each '
        'segment is the constant 12 deg plus the spread of the K neighbours\' directions (where '
        'the neighbours disagree the database knows the segment less); false = the constant',
        public=False)
    direction_db_distance: float = param(
        0.09, 'segments, direction_fusion: the database solution\'s direction error grows with '
        'the nearest database posture\'s RMS distance per reliable joint (standard body, m): '
        'its constant part is scaled by (distance / this)^2 where the distance is larger; '
        '0 = off', range=(0.0, 10.0), public=False)
    filled_memory_s: float = param(
        0.5, 'segments: a segment the database fills (an end below reliable_threshold) starts '
        'from where the sensor last saw it, in proportion to the trust in the sensor, the '
        'memory fading with this time constant (s); where the database does not explain the '
        'user (trust ~1) a glitch of a few frames keeps the last seen direction instead of the '
        'database\'s fill; 0 = off', range=(0.0, 100.0), public=False)
    smooth_anchored_speed: bool = param(
        True, 'segments, few reliable joints (hips, shoulders and every segment unreliable): a '
        'filled segment with a reliable joint at or below its child keeps the One Euro speed '
        'term, so that the body does not trail the tracked hands and feet', public=False)


def segment_units(Y: np.ndarray) -> np.ndarray:
    """(..., 19, 3) the unit segment directions of postures ``Y`` (..., 20, 3) (a zero-length
    segment: zero)."""
    v = Y[..., SEGMENT_CHILD_INDEX, :] - Y[..., SEGMENT_PARENT_INDEX, :]
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def database_segment_units(db) -> np.ndarray:
    """(N, 19, 3) :func:`segment_units` of every posture of ``db`` (a
    :class:`~.posture_space.DatabaseArrays`), computed once per database (``db.derived``): the
    neighbours' directions are rows of it (each row the same numbers as computed alone)."""
    U = db.derived.get('segment_units')
    if U is None:
        # C order: the fancy index leaves the segment axis outermost in memory, and taking
        # rows of that layout costs ~50x more
        U = db.derived['segment_units'] = np.ascontiguousarray(
            segment_units(db.flat.reshape(-1, NUM_JOINTS, 3)))
        U.setflags(write=False)
    return U


def neighbour_direction_spread(Y: np.ndarray, dist: np.ndarray, units=None) -> np.ndarray:
    """(19,) the spread of the K neighbours' segment directions (rad^2): ``1 - |m|^2`` of the
    mean ``m`` of their unit directions, weighted by the inverse of ``dist`` (K,: the search's
    distances, as the optimizer returns them) (the mean squared chord to the mean direction;
    ~ the mean squared angle for small spreads). ``Y`` (K, 20, 3); ``units``: their
    :func:`segment_units` (K, 19, 3) instead (``Y`` then unused)."""
    u = segment_units(Y) if units is None else units
    wk = 1.0 / np.maximum(np.asarray(dist, float), 1e-9)
    m = np.einsum('k,ksd->sd', wk / wk.sum(), u)
    return 1.0 - np.einsum('sd,sd->s', m, m)


def neighbour_direction_spreads(Y: np.ndarray, dist: np.ndarray, units=None) -> np.ndarray:
    """:func:`neighbour_direction_spread` of several users at once: ``Y`` (U, K, 20, 3) (or
    ``units`` (U, K, 19, 3)), ``dist`` (U, K) -> (U, 19)."""
    u = segment_units(Y) if units is None else units
    wk = 1.0 / np.maximum(np.asarray(dist, float), 1e-9)
    m = np.einsum('uk,uksd->usd', wk / wk.sum(axis=1, keepdims=True), u)
    return 1.0 - np.einsum('usd,usd->us', m, m)


class SegmentOutput:
    """One user's segment output: lengths frozen once observed, the One Euro filter state."""

    def __init__(self, reliability, standard_lengths: np.ndarray,
                 height_settled: Callable[[], bool], reliable_threshold: float,
                 output_scale: str, config: SegmentOutputConfig):
        check(config)
        self.reliability = reliability
        self._standard_lengths = np.asarray(standard_lengths, float)
        self.height_settled = height_settled
        self.reliable_threshold = float(reliable_threshold)
        self.output_scale = output_scale
        self.length_frames = int(config.length_frames)
        self.symmetric_lengths = bool(config.symmetric_lengths)
        self.observation_weight = float(config.observation_weight)
        self.smooth = (float(config.smooth_min_cutoff), float(config.smooth_beta),
                       float(config.smooth_d_cutoff))
        self.smooth_filled_scale = float(config.smooth_filled_scale)
        self.smooth_anchored_speed = bool(config.smooth_anchored_speed)
        self.smooth_lead = float(config.smooth_lead)
        self.position_fit = float(config.position_fit)
        self.position_fit_iterations = int(config.position_fit_iterations)
        self.smooth_lead_accel = float(config.smooth_lead_accel)
        self.smooth_lead_speed = float(config.smooth_lead_speed)
        self.smooth_accel_cutoff = float(config.smooth_accel_cutoff)
        self.smooth_accel_beta = float(config.smooth_accel_beta)
        self.direction_fusion = bool(config.direction_fusion)
        self.smooth_trusted_scale = float(config.smooth_trusted_scale)
        self.direction_db_spread = bool(config.direction_db_spread)
        self.direction_db_distance = float(config.direction_db_distance)
        self.filled_memory_s = float(config.filled_memory_s)
        # output_rows' arithmetic compiled (segment_output_kernels) when numba is on
        self.compiled = jit.enabled()
        if self.compiled:
            _kernels.warm_up()   # once per process: not on a user's first frame
        # the user's profile lengths (19,), used from the first frame when set (Reconstructor)
        self.profile_lengths: Optional[np.ndarray] = None
        # the body proportions ((19,) or (k, 19), any scale) the expected final lengths are
        # predicted from while the estimate converges (BoneLengthEstimator.predicted): the
        # database body's, and the length prior's when set (the Reconstructor); None = the
        # running estimate itself
        self.proportions: Optional[np.ndarray] = self._standard_lengths
        # (observed lengths of each side (19,), reliable observation counts (19,)) -> lengths:
        # the length prior (length_prior.py), set by the Reconstructor; None = observed lengths
        # only
        self.length_prior: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None
        # () -> the joint-centre offset scale measured on the user (m per axis; the length
        # prior's), set by the Reconstructor; None = _OFFSET_SIGMA
        self.offset_sigma: Optional[Callable[[], float]] = None
        self.estimator = BoneLengthEstimator(self.length_frames, float(config.length_settle_s),
                                             float(config.length_new_person),
                                             float(config.length_new_person_s),
                                             int(config.length_min_frames),
                                             float(config.length_tolerance))
        self.reset()

    def reset(self) -> None:
        self.estimator.reset()
        self.estimator.restarts = 0
        self._seg_fallback = np.full(NUM_SEGMENTS, np.nan)
        self._frozen_lengths: Optional[np.ndarray] = None
        self._prior_cache: Optional[tuple] = None  # (prior, sides, counts, fused lengths)
        self._estimate_cache: Optional[tuple] = None  # (counts, means, complete, excess)
        self._profile_refused = False  # the profile's lengths were another person's
        self._var_obs_cache: Optional[tuple] = None  # (lengths, sigma, _fused_weight's var_obs)
        # filled_memory_s: each segment's last reliably observed direction and its age (s)
        self._seen_u = np.zeros((NUM_SEGMENTS, 3))
        self._seen_age = np.full(NUM_SEGMENTS, np.inf)
        mc, b, dc = self.smooth
        self._last_stamp: Optional[int] = None
        self._filter_clock_ns = 0
        # one filter for the 19 segment vectors and the root (rows 0-18, 19): the same per-row
        # One Euro filter as two separate ones, in one call
        self._seg_filter = OneEuroFilter(
            mc, b, dc, num_joints=NUM_SEGMENTS + 1,
            lead_accel=self.smooth_lead_accel,
            accel_cutoff=self.smooth_accel_cutoff,
            accel_beta=self.smooth_accel_beta,
            lead_speed=self.smooth_lead_speed) if mc > 0 else None

    def lengths(self, positions: np.ndarray, R: np.ndarray,
                lengths: Optional[np.ndarray] = None, dt: float = 1.0 / 30.0) -> np.ndarray:
        """(19,) the user's constant lengths (:mod:`.bone_lengths`): the robust mean of each
        segment's first ``length_frames`` trusted observations (both ends at or above
        ``reliable_threshold``), with the length prior when set, frozen once complete (or
        ``length_settle_s`` after the first); a segment not yet observed keeps the reliability
        reference length it had when first needed. A profile's lengths are frozen from the first
        frame. Frozen lengths the observations persistently disagree with (another person under
        the same id) are estimated again. ``lengths`` (19,): the observed segment lengths of
        ``positions`` when already known; ``dt`` the frame step (s)."""
        if self.output_scale == 'standard':
            self._frozen_lengths = self._standard_lengths
            return self._frozen_lengths
        thr = self.reliable_threshold
        good = (R[SEGMENT_PARENT_INDEX] >= thr) & (R[SEGMENT_CHILD_INDEX] >= thr)
        ln = lengths
        if ln is None:
            ln = np.linalg.norm(positions[SEGMENT_CHILD_INDEX] - positions[SEGMENT_PARENT_INDEX],
                                axis=1)
        est = self.estimator
        if (self._frozen_lengths is None and self.profile_lengths is not None
                and not self._profile_refused):
            L = np.asarray(self.profile_lengths, float)
            self._frozen_lengths = 0.5 * (L + L[_MIRROR_SEG]) if self.symmetric_lengths else L
            est.freeze(self._frozen_lengths)
        if self._frozen_lengths is not None:
            if not est.observe(ln, good, dt):
                return self._frozen_lengths
            # another person: estimated again, from this frame (a profile was not theirs)
            self._frozen_lengths = None
            self._prior_cache = None
            self._estimate_cache = None
            self._profile_refused = self.profile_lengths is not None
        else:
            est.observe(ln, good, dt)
        counts = est.counts
        none = counts == 0
        if none.any():
            unset = none & ~np.isfinite(self._seg_fallback)
            if not self.height_settled():
                unset = none  # the database height fit is still converging: follow it
            if unset.any():
                self._seg_fallback[unset] = self.reliability.reference_lengths[unset]
        complete = est.complete()
        cached = self._estimate_cache
        if cached is not None and cached[2] == complete and np.array_equal(cached[0], counts):
            mean, excess = cached[1], cached[3]  # nothing observed since
        elif complete:
            mean, excess = est.estimate, None
        else:
            # while converging: the expected final estimate, and how much more the estimate
            # varies now than it will (the output's lengths move less while they converge)
            mean, excess = est.predicted(self.proportions), est.excess_variances()
        self._estimate_cache = (counts.copy(), mean, complete, excess)
        L = np.where(none, self._seg_fallback, mean)
        if self.length_prior is not None:
            # the observed lengths of each side and the length prior (it shares the sides'
            # lengths itself when symmetric_lengths)
            cached = self._prior_cache
            if cached is not None and cached[0] is self.length_prior and cached[4] == complete \
                    and np.array_equal(cached[1], L) and np.array_equal(cached[2], counts):
                L = cached[3].copy()  # nothing observed since: the same fusion
            else:
                fused = (self.length_prior(L, counts) if excess is None
                         else self.length_prior(L, counts, excess))
                self._prior_cache = (self.length_prior, L, counts.copy(), fused.copy(), complete)
                L = fused
        elif self.symmetric_lengths:
            L = 0.5 * (L + L[_MIRROR_SEG])
        if complete:
            self._frozen_lengths = L  # constant from now on
            est.freeze(L)
        return L

    @property
    def user_lengths(self) -> Optional[np.ndarray]:
        """(19,) the user's frozen segment lengths (m), None while still being estimated."""
        return None if self._frozen_lengths is None else self._frozen_lengths.copy()

    def output(self, frame: SkeletonFrame, solution: np.ndarray, w: np.ndarray,
               trust: float, yaw: Optional[float] = None,
               seg_obs: Optional[np.ndarray] = None,
               len_obs: Optional[np.ndarray] = None,
               root: Optional[np.ndarray] = None,
               db_spread: Optional[np.ndarray] = None,
               db_distance: Optional[float] = None) -> np.ndarray:
        """The output positions (20, 3), sensor frame (module docstring). ``solution`` (20, 3): in the sensor frame,
        or, with ``yaw``, the normalised solution (only its segment directions matter: they are
        turned by ``yaw``). ``seg_obs`` / ``len_obs``: the observed segment vectors (19, 3) and
        lengths (19,) when already computed."""
        return self.output_positions(self.output_rows(frame, solution, w, trust, yaw, seg_obs,
                                                      len_obs, root, db_spread, db_distance))

    def output_rows(self, frame, solution, w, trust, yaw=None, seg_obs=None, len_obs=None,
                    root=None, db_spread=None, db_distance=None) -> SmoothingStep:
        """:meth:`output` up to the smoothing filter (its arguments as :meth:`output`'s):
        several users' filters are updated together (:func:`smooth_many`) between this and
        :meth:`output_positions`."""
        obs = np.asarray(frame.positions, float)
        if seg_obs is None:
            seg_obs = SEG_DIFF @ obs
            len_obs = np.sqrt(np.einsum('sk,sk->s', seg_obs, seg_obs))
        # filter clock: the stamps' steps where plausible (1 ms - 0.5 s), else 30 Hz
        stamp = int(frame.stamp_ns or 0)
        dt = 1.0 / 30.0
        if self._last_stamp is not None and 1e6 <= stamp - self._last_stamp <= 5e8:
            dt = (stamp - self._last_stamp) * 1e-9
        self._last_stamp = stamp
        L = self.lengths(obs, w, len_obs, dt)
        if self.compiled and w.dtype == np.float64:
            return self._output_rows_compiled(obs, solution, w, trust, yaw, seg_obs, len_obs,
                                              root, db_spread, db_distance, L, dt)
        vs = SEG_DIFF @ solution
        if yaw is not None:
            vs = vs @ yaw_matrix(yaw).T
        ns = np.sqrt(np.einsum('sk,sk->s', vs, vs))
        us = vs / np.maximum(ns, 1e-9)[:, None]
        uo = seg_obs / np.maximum(len_obs, 1e-9)[:, None]
        zero = len_obs <= 1e-9
        if zero.any():
            uo[zero] = us[zero]
        wmin = np.minimum(w[SEGMENT_PARENT_INDEX], w[SEGMENT_CHILD_INDEX])
        thr = self.reliable_threshold
        rel_frac = np.minimum(wmin * (1.0 / max(thr, 1e-6)), 1.0)
        beta = rel_frac * trust
        reliable = wmin >= thr
        if self.direction_fusion:
            np.maximum(beta, self._fused_weight(L, db_spread, db_distance) * reliable, out=beta)
        elif self.observation_weight > 0.0:
            np.maximum(beta, self.observation_weight * reliable, out=beta)
        if self.filled_memory_s > 0.0:
            us = self._remembered(us, uo, reliable & ~zero, rel_frac, trust, dt)
        u = us + beta[:, None] * (uo - us)
        nu = np.sqrt(np.einsum('sk,sk->s', u, u))
        small = nu <= 1e-9
        u /= np.maximum(nu, 1e-9)[:, None]
        if small.any():
            u[small] = us[small]
        vr = np.empty((NUM_SEGMENTS + 1, 3))
        vr[:NUM_SEGMENTS] = u
        vr[:NUM_SEGMENTS] *= L[:, None]
        vr[NUM_SEGMENTS] = obs[ROOT] if root is None else root
        if self.position_fit > 0.0 and trust > 0.0:
            pull = (self.position_fit * trust) * np.minimum(w * (1.0 / max(thr, 1e-6)), 1.0)
            if pull.any():
                # a segment takes the fitted direction only as far as its direction is not the
                # sensor's already: the fit restores constant lengths by moving joints, which
                # turns short segments (the hips, the feet, the shoulders) away from what the
                # sensor sees (real UI-PRMD subset: +4-6 deg on the hip segments); an
                # observed direction is kept, the fit then places the skeleton
                self._fit_positions(vr, obs, pull, L, rel_frac * (1.0 - beta))
        if self._seg_filter is not None:
            self._filter_clock_ns += int(round(dt * 1e9))
            scale = speed = None
            if self.smooth_filled_scale != 1.0:
                # a segment the database fills in (an end with reliability 0) is smoothed with
                # smooth_filled_scale times the cutoff, a reliable one as set, linear between
                fs = self.smooth_filled_scale
                scale = np.ones(NUM_SEGMENTS + 1)
                scale[:NUM_SEGMENTS] = fs + (1.0 - fs) * rel_frac
                if (self.smooth_anchored_speed and not reliable.any()
                        and torso_weight(w) < thr):
                    # few reliable joints: filled segments with a reliable joint hanging from
                    # them keep the speed term too, in proportion (module docstring)
                    anchored = np.minimum((_SEG_BELOW * w).max(axis=1)
                                          * (1.0 / max(thr, 1e-6)), 1.0)
                    if anchored.any():
                        speed = scale.copy()
                        speed[:NUM_SEGMENTS] += anchored * (1.0 - scale[:NUM_SEGMENTS])
            if self.smooth_trusted_scale != 1.0:
                # less smoothing where the output follows the sensor: a segment's cutoff times up
                # to smooth_trusted_scale in proportion to the observed direction's weight in it
                # (beta: the trust times the reliability fraction, or direction_fusion's weight
                # of a reliable segment), the root's in proportion to the trust times its
                # reliability fraction; the full smoothing stays on what the database gives
                ts = np.empty(NUM_SEGMENTS + 1)
                ts[:NUM_SEGMENTS] = beta
                ts[NUM_SEGMENTS] = trust * min(1.0, w[ROOT] / max(thr, 1e-6))
                ts = 1.0 + (self.smooth_trusted_scale - 1.0) * ts
                scale = ts if scale is None else scale * ts
                if speed is not None:
                    speed = speed * ts
            lead = None
            if self.smooth_lead > 0.0:
                # prediction correction on what the sensor gives reliably and on the root
                # (filters.OneEuroFilter lead): no lag there; the database-filled segments keep
                # the plain low-pass
                lead = np.empty(NUM_SEGMENTS + 1)
                lead[:NUM_SEGMENTS] = self.smooth_lead * rel_frac
                lead[NUM_SEGMENTS] = self.smooth_lead  # the root is never heavily smoothed
            return SmoothingStep(vr, L, u, self._seg_filter, self._filter_clock_ns, scale,
                                 speed, lead)
        return SmoothingStep(vr, L, u)

    def _output_rows_compiled(self, obs, solution, w, trust, yaw, seg_obs, len_obs, root,
                              db_spread, db_distance, L, dt) -> SmoothingStep:
        """:meth:`output_rows` after the lengths ``L``, in one compiled call
        (:func:`.segment_output_kernels.output_core`: the same arithmetic as the numpy code)."""
        K = _kernels
        fusion = self.direction_fusion
        fw = self._fused_weight(L, db_spread, db_distance) if fusion else _NO_WEIGHTS
        mode = 1 if fusion else (2 if self.observation_weight > 0.0 else 0)
        vr = np.empty((NUM_SEGMENTS + 1, 3))
        u = np.empty((NUM_SEGMENTS, 3))
        scale = np.empty(NUM_SEGMENTS + 1)
        speed = np.empty(NUM_SEGMENTS + 1)
        lead = np.empty(NUM_SEGMENTS + 1)
        filt = self._seg_filter
        flags = K.output_core(
            np.asarray(solution, float), _EYE3 if yaw is None else yaw_matrix(yaw),
            yaw is not None, obs, seg_obs, len_obs, w, L, float(trust), self.reliable_threshold,
            fw, mode, self.observation_weight, self.filled_memory_s, self._seen_u,
            self._seen_age, float(dt), _ZERO3 if root is None else np.asarray(root, float),
            root is not None, self.position_fit, self.position_fit_iterations, _SEG_CHAIN_C,
            _HALF_INV_DEGREE, K.CHILD_I, K.PARENT_I, filt is not None,
            self.smooth_filled_scale, self.smooth_anchored_speed, _SEG_BELOW, K.TORSO_I,
            self.smooth_trusted_scale, self.smooth_lead, vr, u, scale, speed, lead)
        if filt is None:
            return SmoothingStep(vr, L, u)
        self._filter_clock_ns += int(round(dt * 1e9))
        return SmoothingStep(vr, L, u, filt, self._filter_clock_ns,
                             scale if flags & K.HAS_SCALE else None,
                             speed if flags & K.HAS_SPEED else None,
                             lead if flags & K.HAS_LEAD else None)

    @staticmethod
    def output_positions(step: SmoothingStep, rows: Optional[np.ndarray] = None) -> np.ndarray:
        """:meth:`output` from the smoothing filter on: the output positions (20, 3) of ``step``
        (:meth:`output_rows`), ``rows`` (20, 3) its smoothed rows when already smoothed (else
        smoothed here); the segments get their lengths again (a segment smoothed to zero keeps
        its unsmoothed direction)."""
        rows = step.smooth() if rows is None else rows
        v = rows[:NUM_SEGMENTS]
        if step.filter is not None:
            nv = np.sqrt(np.einsum('sk,sk->s', v, v))
            keep = nv > 1e-9
            v = (v / np.maximum(nv, 1e-9)[:, None]) if keep.all() else \
                np.where(keep[:, None], v / np.maximum(nv, 1e-9)[:, None], step.directions)
            v *= step.lengths[:, None]
        return rows[NUM_SEGMENTS] + _SEG_CHAIN @ v

    def _remembered(self, us: np.ndarray, uo: np.ndarray, seen: np.ndarray,
                    rel_frac: np.ndarray, trust: float, dt: float) -> np.ndarray:
        """(19, 3) ``filled_memory_s``: the database directions ``us`` of the segments not seen
        reliably now turned towards their last reliably observed direction, by ``trust`` times
        ``exp(-age / filled_memory_s)`` times the unreliable fraction ``1 - rel_frac``; the
        directions of ``seen`` (19,) segments are remembered (age 0)."""
        self._seen_age += dt
        if seen.any():
            self._seen_u[seen] = uo[seen]
            self._seen_age[seen] = 0.0
        if trust <= 0.0:
            return us
        m = trust * np.exp(-self._seen_age / self.filled_memory_s) * (1.0 - rel_frac)
        act = (m > 1e-3) & ~seen
        if not act.any():
            return us
        out = us.copy()
        v = us[act] + m[act, None] * (self._seen_u[act] - us[act])
        n = np.linalg.norm(v, axis=1)
        good = n > 1e-9
        idx = np.nonzero(act)[0][good]
        out[idx] = v[good] / n[good, None]
        return out

    def _fused_weight(self, L: np.ndarray,
                      db_spread: Optional[np.ndarray] = None,
                      db_distance: Optional[float] = None) -> np.ndarray:
        """(19,) ``direction_fusion``: the weight of a reliable segment's observed direction,
        ``var_db / (var_db + var_obs)`` (the blend of minimum expected error). ``var_obs``, the
        observed direction's error variance (rad^2): the two ends' joint-centre offsets across a
        segment of length ``L``, ``sigma`` per axis, two axes each: ``4 sigma^2 / L^2`` (``sigma``
        the offset scale the length prior measures on the user from left/right length
        differences; ``_OFFSET_SIGMA`` without it). ``var_db``: the database solution's direction
        error, 12 deg (``_DB_DIRECTION_VAR``) plus ``db_spread`` (19,) when given, the spread of
        the K neighbours' directions (:func:`neighbour_direction_spread`): on the sensor-model
        streams the solution's error grows with it (rms 6.6 deg where the neighbours agree within
        1-3.5 deg, 21.6 deg where they spread 17-53 deg; docs/research, accuracy, round 7). With
        ``db_distance`` (the nearest database posture's RMS distance per reliable joint, standard
        body, m) above ``direction_db_distance``, the constant part is scaled by
        ``(db_distance / direction_db_distance)^2``: measured, the solution's direction error grows
        in proportion to that distance (rms 8.6 deg at 0.02-0.07 m, 17.7 at 0.12-0.24; about
        120-130 deg per m, i.e. 12 deg at 0.09 m), also where the neighbours agree: a posture the
        database lacks has neighbours that agree and are all wrong (a sword fight's forearm). A long
        segment the sensor sees (a shank, an upper arm: 5-8 deg) follows the sensor; a short one
        (the hips, the shoulders, the feet: 20-30 deg) takes the database's direction."""
        sigma = self.offset_sigma() if self.offset_sigma is not None else _OFFSET_SIGMA
        cached = self._var_obs_cache
        if cached is not None and cached[0] is L and cached[1] == sigma:
            var_obs = cached[2]   # the frozen lengths (the same array) and the same sigma
        else:
            var_obs = 4.0 * sigma * sigma / np.maximum(L, 1e-2) ** 2
            self._var_obs_cache = (L, sigma, var_obs)
        var_db = _DB_DIRECTION_VAR
        d0 = self.direction_db_distance
        if d0 > 0.0 and db_distance is not None and db_distance > d0:
            var_db = var_db * (db_distance / d0) ** 2
        if db_spread is not None:
            # the neighbours' disagreement adds to the database's error (db_spread: the
            # reconstructor's neighbour_direction_spread, when direction_db_spread)
            var_db = var_db + db_spread
        return var_db / (var_db + var_obs)

    def _fit_positions(self, vr: np.ndarray, obs: np.ndarray, pull: np.ndarray,
                       L: np.ndarray, seg_rel: Optional[np.ndarray] = None) -> None:
        """``position_fit`` (in place on ``vr``: 19 segment vectors of lengths ``L`` and the
        root): the chained skeleton's joints pulled towards the observed ones by ``pull`` (20,),
        then its segment lengths restored by ``position_fit_iterations`` simultaneous passes
        (each segment's length error shared by its two ends, a joint's corrections averaged over
        its segments). A segment takes the fitted direction in proportion to ``seg_rel`` (19,)
        (default 1: the reliability fraction of its less reliable end; a segment the database
        fills keeps its direction), with lengths ``L``; the root goes where the chained result
        fits the pulled joints best (a translation, weighted by ``pull``)."""
        p = vr[NUM_SEGMENTS] + _SEG_CHAIN @ vr[:NUM_SEGMENTS]
        ok = np.isfinite(obs).all(axis=1) & (pull > 0)
        p[ok] += pull[ok, None] * (obs[ok] - p[ok])
        for _ in range(self.position_fit_iterations):
            d = SEG_DIFF @ p
            n = np.sqrt(np.einsum('sk,sk->s', d, d))
            e = ((n - L) / np.maximum(n, 1e-9))[:, None] * d   # (19, 3) length error vectors
            p -= _HALF_INV_DEGREE[:, None] * (SEG_DIFF.T @ e)
        d = SEG_DIFF @ p
        n = np.sqrt(np.einsum('sk,sk->s', d, d))
        good = n > 1e-9
        fit = np.zeros_like(d)
        fit[good] = d[good] * (L[good] / n[good])[:, None]
        v = vr[:NUM_SEGMENTS]
        if seg_rel is not None:
            b = np.where(good, seg_rel, 0.0)[:, None]
            u = v + b * (fit - v)
            nu = np.sqrt(np.einsum('sk,sk->s', u, u))
            okv = nu > 1e-9
            v[okv] = u[okv] * (L[okv] / nu[okv])[:, None]
        else:
            v[good] = fit[good]
        wt = np.where(ok, pull, 0.0)
        q = p - _SEG_CHAIN @ v
        vr[NUM_SEGMENTS] = (wt @ q) / wt.sum() if wt.sum() > 0 else q.mean(axis=0)
