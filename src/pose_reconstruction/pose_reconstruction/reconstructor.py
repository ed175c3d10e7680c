"""Per-user streaming posture reconstruction: reliability + method A, B or C.

``Reconstructor(db, method='C', **params).process(frame) -> frame`` fills in the reliability,
reconstructs the positions, sets the orientations (sensor frame), and keeps stamp, user id and
frame id. One instance per user (it keeps that user's history); ``reset()`` forgets it.

Methods (Shum et al. 2013, Sec. VIII-B):

* ``'A'`` — Shum & Ho 2012 database completion (:class:`~.completion.PCACompletion`);
* ``'B'`` — the natural-posture-space optimizer with every reliability 1;
* ``'C'`` — the optimizer with the reliability of Eq. 8 (the paper's method).

Output stage of B/C, ``output_mode``:

* ``'segments'`` (default) — every segment's direction is a blend of the database solution's and
  the observed one; the weight of the observation is the larger of ``observation_weight`` (for a
  segment whose two ends are reliable, at or above ``reliable_threshold``; 0 otherwise) and the
  *trust in the sensor* times min(1, reliability of the less reliable end / ``reliable_threshold``);
  the segments get constant user lengths (the mean observed length over the first
  ``length_frames`` reliable observations of each segment, then frozen; with
  ``symmetric_lengths`` the left and right limbs share the mean of their two lengths) and are
  chained from the observed root; the segment
  vectors and the root are smoothed by a One Euro filter (``smooth_min_cutoff`` Hz,
  ``smooth_beta`` s/m, ``smooth_d_cutoff`` Hz; ``smooth_min_cutoff`` 0 = off); a segment the
  database fills in (an end with reliability 0) gets ``smooth_filled_scale`` times the cutoff (1 at
  or above ``reliable_threshold``, linear between): the database solution jumps when the
  neighbours change, the sensor's reliable segments need no more lag. Bone lengths stay
  constant, and errors of the observation do not leak into the segments the database fills in.
* ``'blend'`` — the paper's output: the solution retargeted to the user's lengths (median observed
  lengths over ``length_window`` frames), reliable joints blended towards their observed positions
  when the trust is above 0 (this breaks constant bone lengths).

Unreliable root (``float_root``, default on): the query is expressed relative to the root joint,
so a root that is occluded (Kinect: INFERRED at a stale position) would shift every reliable joint
of the query. When the root's reliability is below ``reliable_threshold`` the KNN search minimises
Eq. 9 over a translation of the query, the query is moved by the neighbours' (inverse-distance
weighted) best translation before the optimisation, and the output root is moved by that
translation times (1 - the trust in the sensor, below): a trusted sensor keeps its root.

Few reliable joints (e.g. hands and feet only, Table III): no segment has two reliable ends, so
no length, height or (with the hips and shoulders unreliable) heading can be measured, and the
positions reported for the unreliable joints must not decide them. Then

* height: until a frame has every joint tracked, the user's height is the median, over the first
  ``height_frames`` such frames, of a scale-invariant database fit (Eq. 9 minimised over a uniform
  scale, neighbours ranked by shape distance; :meth:`~.optimizer.NaturalPostureOptimizer.knn_scaled`);
  it scales the query and gives the standard-body lengths of the segments never observed;
* heading: the last heading of the reliable torso is kept (at the start, the best of
  ``yaw_search`` headings against the database, from the one the unreliable torso gives) and
  turned each frame by ``yaw_rate`` times the rotation that best fits the reliable joints to
  the database (:meth:`Reconstructor._database_yaw`: per database posture a weighted 2-D
  Procrustes, the ``yaw_neighbours`` best postures averaged).

Both need at least three reliable joints. ``smooth_filled_speed``: ``smooth_filled_scale`` lowers
only the minimum cutoff of a filled segment, not the One Euro speed term (less lag in fast
motion, but more jitter: off by default).

``smooth_anchored_speed`` (default on): with few reliable joints (as above: the hip and the
shoulder line unreliable and no segment with two reliable ends), a filled segment with a
reliable joint at or below its child (a tracked hand or foot hanging from it) keeps the One Euro
speed term as with ``smooth_filled_speed``, in proportion to that joint's reliability (1 at or
above ``reliable_threshold``). Then every segment is filled, and filtering them all with
``smooth_filled_scale`` times the whole cutoff made the whole body trail the tracked hands and
feet by about two frames (Table III hands + feet: the error was lowest against the reference
two frames earlier); the speed of an anchored segment is mostly the tracked joint's motion.
Outside that regime filled segments are smoothed as before (the default experiment's
occlusions: unchanged).

Trust in the sensor (graceful degradation), ``trust_mode``:

* ``'noise_ratio'`` (default) — the RMS distance (per reliable joint) of the nearest database
  posture, smoothed over time, divided by the sensor's measured frame-to-frame noise (an
  exponential average, rate ``noise_alpha``, of the median second difference of the reliable
  joints): a database posture that differs from a precise sensor by many times its noise cannot
  describe the posture. The trust rises linearly from 0 at ``trust_sensor_ratio`` to 1 at twice
  it (1 until the noise is known, i.e. the first two frames). On the sensor-model streams the
  ratio is 3-10, on the real UI-PRMD Kinect recordings (rehabilitation exercises the CMU database
  lacks, another joint layout) 20-130.
* ``'distance'`` — the earlier rule: linear from 0 at ``trust_sensor_distance`` (RMS m per
  reliable joint, standard body) to 1 at twice it.

Learned sensor correction (``correction``, a :class:`~.correction.SensorCorrection`, default
None = off): the tracker's posture-dependent offset from the anatomical joint centres is removed
from each input frame, ``correction_stage`` ``'input'`` (default: before the reliability, every
joint) or ``'reliable'`` (after it, only the joints at or above ``reliable_threshold``, with the
posture features of the reliable bones). The correction is refused (``TrackerMismatch``) unless
``input_tracker`` names the tracker it was learned from. ``profile`` (a
:class:`~.profile.UserProfile` or (19,) lengths): the user's segment lengths, used from the first
frame instead of the mean of the first ``length_frames`` observations.

``trust_sensor`` holds the last trust factor. The paper's behaviour: ``output_mode='blend'``,
``trust_mode='distance'``, ``reference_mode='standard'``, ``w_style=0.5`` (the default 8 weights
the closest-neighbour style term 16x higher: measured on the sensor-model dev streams, Eq. 18 a/b/c
4.70/5.90/8.79 -> 4.52/5.48/7.81 cm, real recordings unchanged).
"""
from __future__ import annotations

import time
from collections import deque
from typing import Dict, Optional

import numpy as np

from skeleton_core.conversions import SkeletonFrame
from skeleton_core.filters import OneEuroFilter
from skeleton_core.geometry import facing_yaw
from skeleton_core.model import (HIP_LEFT, HIP_RIGHT, MIRROR, NUM_JOINTS, NUM_SEGMENTS, ROOT,
                                 SEGMENT_CHILDREN, SEGMENT_PARENTS, SHOULDER_LEFT, SHOULDER_RIGHT)

from .completion import PCACompletion
from .optimizer import NaturalPostureOptimizer
from .posture_space import (ANCESTORS, QueryPreparer, as_database_arrays,
                            rest_directions, to_sensor_frame, user_bone_lengths, yaw_quat_matrix,
                            yaw_rotation)
from .correction import check_tracker
from .profile import from_optional as profile_lengths
from .reliability import ReliabilityEstimator

METHODS = ('A', 'B', 'C')
OUTPUT_MODES = ('segments', 'blend')
CORRECTION_STAGES = ('input', 'reliable')
TRUST_MODES = ('noise_ratio', 'distance')
_SEG_P = np.array(SEGMENT_PARENTS)
_SEG_C = np.array(SEGMENT_CHILDREN)
_MIRROR_SEG = np.array([SEGMENT_CHILDREN.index(MIRROR[c]) for c in SEGMENT_CHILDREN])
# (19, 20): positions -> segment vectors (child - parent); (20, 19): segment vectors -> positions
# relative to the root (the segments on the way from the root)
_SEG_DIFF = np.zeros((NUM_SEGMENTS, NUM_JOINTS))
_SEG_DIFF[np.arange(NUM_SEGMENTS), _SEG_C] = 1.0
_SEG_DIFF[np.arange(NUM_SEGMENTS), _SEG_P] -= 1.0
_SEG_CHAIN = ANCESTORS[:, _SEG_C]
# (19, 20): 1 for the joints at and below each segment's child (what hangs from the segment)
_SEG_BELOW = np.ascontiguousarray(_SEG_CHAIN.T)


_MIN_FIT_JOINTS = 3  # the fewest points that fix a rotation and a scale
RELIABILITY_PARAMS = ('d_min', 'f_b', 'theta_floor_deg', 'theta_roof_deg', 'f_total',
                      'sigma_frames', 'tracked_value', 'inferred_value', 'not_tracked_value',
                      'reference_pose_tolerance_deg', 'reference_frames', 'reference_mode',
                      'observed_window')
OPTIMIZER_PARAMS = ('k', 'pca_dims', 'steps', 'samples', 'w_control', 'w_style', 'w_kinematics',
                    'w_continuity', 'step_scale', 'solver', 'gn_iterations', 'seed', 'knn',
                    'kdtree_dims', 'kdtree_candidates')
COMPLETION_PARAMS = ('pca_dims', 'reliability_threshold', 'substitution')
OWN_PARAMS = ('use_reliability', 'use_input_reliability', 'reliable_threshold',
              'trust_sensor_distance', 'output_scale', 'length_window', 'output_mode',
              'trust_mode', 'trust_sensor_ratio', 'noise_alpha', 'length_frames',
              'smooth_min_cutoff', 'smooth_beta', 'smooth_d_cutoff', 'observation_weight',
              'symmetric_lengths', 'smooth_filled_scale', 'float_root', 'height_frames',
              'yaw_rate', 'yaw_search', 'yaw_neighbours', 'smooth_filled_speed',
              'correction', 'correction_stage', 'input_tracker', 'profile')


def split_params(method: str, params: Dict) -> tuple:
    rel = {k: v for k, v in params.items() if k in RELIABILITY_PARAMS}
    if method == 'A':
        core = {k: v for k, v in params.items() if k in COMPLETION_PARAMS}
        if 'reliable_threshold' in params and 'reliability_threshold' not in params:
            core['reliability_threshold'] = params['reliable_threshold']
    else:
        core = {k: v for k, v in params.items() if k in OPTIMIZER_PARAMS}
    own = {k: v for k, v in params.items() if k in OWN_PARAMS}
    unknown = set(params) - set(rel) - set(core) - set(own) - {'reliable_threshold'}
    if method == 'A':
        unknown -= set(OPTIMIZER_PARAMS)  # accepted and ignored, so one config serves all
    else:
        unknown -= set(COMPLETION_PARAMS)
    if unknown:
        raise ValueError(f'unknown reconstruction parameters: {sorted(unknown)}')
    return rel, core, own


class Reconstructor:
    """One user's reconstruction pipeline (see module docstring)."""

    def __init__(self, db, method: str = 'C', use_reliability: Optional[bool] = None,
                 use_input_reliability: bool = True, reliable_threshold: float = 0.5,
                 trust_sensor_distance: float = 0.12, output_scale: str = 'user',
                 length_window: int = 90, output_mode: str = 'segments',
                 trust_mode: str = 'noise_ratio', trust_sensor_ratio: float = 8.0,
                 noise_alpha: float = 0.05, length_frames: int = 15,
                 symmetric_lengths: bool = True, observation_weight: float = 0.3,
                 smooth_min_cutoff: float = 3.0, smooth_beta: float = 10.0,
                 smooth_d_cutoff: float = 1.0, smooth_filled_scale: float = 0.2,
                 float_root: bool = True, height_frames: int = 30, yaw_rate: float = 0.5,
                 yaw_search: int = 12, yaw_neighbours: int = 5,
                 smooth_filled_speed: bool = False, smooth_anchored_speed: bool = True,
                 correction=None, correction_stage: str = 'input', input_tracker: str = '',
                 profile=None, **params):
        method = str(method).upper()
        if method not in METHODS:
            raise ValueError(f'method must be one of {METHODS}, got {method!r}')
        if output_scale not in ('user', 'standard'):
            raise ValueError("output_scale must be 'user' or 'standard'")
        if output_mode not in OUTPUT_MODES:
            raise ValueError(f'output_mode must be one of {OUTPUT_MODES}')
        if trust_mode not in TRUST_MODES:
            raise ValueError(f'trust_mode must be one of {TRUST_MODES}')
        if not trust_sensor_ratio > 0 or not 0 < noise_alpha <= 1:
            raise ValueError('trust_sensor_ratio must be > 0 and noise_alpha in (0, 1]')
        if int(length_frames) < 1:
            raise ValueError('length_frames must be >= 1')
        if smooth_min_cutoff < 0 or smooth_beta < 0 or smooth_d_cutoff <= 0:
            raise ValueError('smooth_min_cutoff, smooth_beta must be >= 0, smooth_d_cutoff > 0')
        self.output_mode = output_mode
        self.trust_mode = trust_mode
        self.trust_sensor_ratio = float(trust_sensor_ratio)
        self.noise_alpha = float(noise_alpha)
        self.length_frames = int(length_frames)
        self.symmetric_lengths = bool(symmetric_lengths)
        if not 0.0 <= observation_weight <= 1.0:
            raise ValueError('observation_weight must be in [0, 1]')
        self.observation_weight = float(observation_weight)
        self.smooth = (float(smooth_min_cutoff), float(smooth_beta), float(smooth_d_cutoff))
        if not 0.0 < smooth_filled_scale <= 1.0:
            raise ValueError('smooth_filled_scale must be in (0, 1]')
        self.smooth_filled_scale = float(smooth_filled_scale)
        self.smooth_filled_speed = bool(smooth_filled_speed)
        if not isinstance(smooth_anchored_speed, (bool, np.bool_)):
            raise ValueError('smooth_anchored_speed must be a bool')
        self.smooth_anchored_speed = bool(smooth_anchored_speed)
        self.float_root = bool(float_root)
        if int(height_frames) < 0 or int(yaw_search) < 0 or not 0.0 <= yaw_rate <= 1.0:
            raise ValueError('height_frames, yaw_search must be >= 0 and yaw_rate in [0, 1]')
        if int(yaw_neighbours) < 1:
            raise ValueError('yaw_neighbours must be >= 1')
        self.yaw_neighbours = int(yaw_neighbours)
        self.height_frames = int(height_frames)
        self.yaw_rate = float(yaw_rate)
        self.yaw_search = int(yaw_search)
        self.method = method
        self.name = method
        if correction_stage not in CORRECTION_STAGES:
            raise ValueError(f'correction_stage must be one of {CORRECTION_STAGES}')
        if correction is not None:
            check_tracker(correction, input_tracker)  # never applied to another tracker
        self.correction = correction
        self.correction_stage = correction_stage
        self._profile_lengths = profile_lengths(profile)
        self.db = as_database_arrays(db)
        rel, core, _ = split_params(method, params)
        self.reliability = ReliabilityEstimator(**rel)
        self.use_reliability = (method == 'C') if use_reliability is None else bool(use_reliability)
        self.use_input_reliability = bool(use_input_reliability)
        self.reliable_threshold = float(reliable_threshold)
        self.trust_sensor_distance = float(trust_sensor_distance)
        self.output_scale = output_scale
        self.preparer = QueryPreparer(self.db.body, self.reliable_threshold)
        self._rest_dirs = rest_directions(self.db.body)
        self._standard_lengths = np.asarray(self.db.body.segment_lengths, float)
        if method == 'A':
            core.setdefault('reliability_threshold', self.reliable_threshold)
            self.core = PCACompletion(self.db, **core)
        else:
            self.core = NaturalPostureOptimizer(self.db, **core)
        self.length_window = int(length_window)
        if self.length_window < 1:
            raise ValueError('length_window must be >= 1')
        self.timings_ms: Dict[str, float] = {}
        self.trust_sensor = 0.0
        self.last_result = None
        self.reset()

    def reset(self) -> None:
        self.reliability.reset()
        self._prev = deque(maxlen=2)  # (normalised solution (20, 3), yaw)
        self._lengths = np.full((self.length_window, NUM_SEGMENTS), np.nan)
        self._lengths_n = 0
        self._user_lengths: Optional[np.ndarray] = None
        # output_mode 'segments': frozen-after-length_frames mean lengths, noise, filters
        self._seg_sum = np.zeros(NUM_SEGMENTS)
        self._seg_count = np.zeros(NUM_SEGMENTS, int)
        self._seg_fallback = np.full(NUM_SEGMENTS, np.nan)
        self._hist = deque(maxlen=2)  # previous observed positions (noise estimate)
        self._noise: Optional[float] = None
        self._noise_n = 0
        self._rms_avg: Optional[float] = None
        self.noise = float('nan')
        mc, b, dc = self.smooth
        self._last_stamp: Optional[int] = None
        self._filter_clock_ns = 0
        # one filter for the 19 segment vectors and the root (rows 0-18, 19): the same per-row
        # One Euro filter as two separate ones, in one call
        self._seg_filter = OneEuroFilter(mc, b, dc, num_joints=NUM_SEGMENTS + 1) if mc > 0 else None
        self._frozen_lengths: Optional[np.ndarray] = None
        # few reliable joints: the heading and the user's height from the database neighbours
        self._yaw_state: Optional[float] = None
        self._height_fits: list = []
        self._height_done = self.height_frames == 0
        if isinstance(self.core, NaturalPostureOptimizer):
            self.core.reset_rng()

    def set_profile(self, profile) -> None:
        """Use another user profile (UserProfile, (19,) lengths or None) and forget the user."""
        self._profile_lengths = profile_lengths(profile)
        self.reset()

    def _reliability_for(self, frame: SkeletonFrame) -> np.ndarray:
        est = self.reliability.update(frame.positions, frame.tracking_state)
        given = np.asarray(frame.reliability, float)
        if self.use_input_reliability and given.shape == (NUM_JOINTS,) and np.all(np.isfinite(given)):
            return given
        return est

    def user_segment_lengths(self) -> np.ndarray:
        """(19,) the user's segment lengths for the output: the median of the observed lengths of
        segments whose two joints were reliable over the last ``length_window`` frames, where
        there are at least 5 such frames; else the reliability reference (captured T-pose /
        standing lengths, or the standard body at the user's height)."""
        if self._profile_lengths is not None:
            return self._profile_lengths
        ref = self.reliability.reference_lengths
        if self.reliability.reference_source != 'standard':
            return ref  # lengths captured in a reference posture (Sec. IV-B)
        if self._user_lengths is None or self._lengths_n % 10 == 0:
            obs = self._lengths[:min(self._lengths_n, self.length_window)]
            count = np.sum(np.isfinite(obs), axis=0)
            med = np.full(NUM_SEGMENTS, np.nan)
            ok = count >= 5
            if ok.any():
                med[ok] = np.nanmedian(obs[:, ok], axis=0)
            self._user_lengths = np.where(ok, med, ref)
        return self._user_lengths

    def _observe_lengths(self, ln: np.ndarray, R: np.ndarray) -> None:
        """``ln`` (19,) this frame's observed segment lengths, ``R`` (20,) reliabilities."""
        good = (R[_SEG_P] >= self.reliable_threshold) & (R[_SEG_C] >= self.reliable_threshold)
        self._lengths[self._lengths_n % self.length_window] = np.where(good, ln, np.nan)
        self._lengths_n += 1

    def output_segment_lengths(self, positions: np.ndarray, R: np.ndarray,
                               lengths: Optional[np.ndarray] = None) -> np.ndarray:
        """(19,) constant user lengths of output_mode 'segments': the mean observed length of each
        segment over its first ``length_frames`` reliable observations (both ends at or above
        ``reliable_threshold``), frozen afterwards; a segment not yet observed reliably keeps the
        reliability reference length it had when first needed. ``lengths`` (19,): the observed
        segment lengths of ``positions`` when already known."""
        if self._frozen_lengths is not None:
            return self._frozen_lengths
        if self._profile_lengths is not None and self.output_scale == 'user':
            L = self._profile_lengths
            self._frozen_lengths = 0.5 * (L + L[_MIRROR_SEG]) if self.symmetric_lengths else L
            return self._frozen_lengths
        if self.output_scale == 'standard':
            self._frozen_lengths = self._standard_lengths
            return self._frozen_lengths
        good = (R[_SEG_P] >= self.reliable_threshold) & (R[_SEG_C] >= self.reliable_threshold)
        good &= self._seg_count < self.length_frames
        if good.any():
            ln = lengths
            if ln is None:
                ln = np.linalg.norm(positions[_SEG_C] - positions[_SEG_P], axis=1)
            self._seg_sum[good] += ln[good]
            self._seg_count[good] += 1
        none = self._seg_count == 0
        if none.any():
            unset = none & ~np.isfinite(self._seg_fallback)
            if not self._height_settled():
                unset = none  # the database height fit is still converging: follow it
            if unset.any():
                self._seg_fallback[unset] = self.reliability.reference_lengths[unset]
        L = np.where(none, self._seg_fallback, self._seg_sum / np.maximum(self._seg_count, 1))
        if self.symmetric_lengths:
            L = 0.5 * (L + L[_MIRROR_SEG])
        if self._seg_count.min() >= self.length_frames:
            self._frozen_lengths = L  # every segment complete: constant from now on
        return L

    def _height_settled(self) -> bool:
        return self._height_done or self.reliability.height_measured

    @staticmethod
    def _torso_weight(w: np.ndarray) -> float:
        """The weight of the better of the hip and shoulder lines (a line counts with the
        smaller reliability of its two joints): what the heading is measured from."""
        return max(min(w[HIP_LEFT], w[HIP_RIGHT]), min(w[SHOULDER_LEFT], w[SHOULDER_RIGHT]))

    def _search_yaw(self, obs: np.ndarray, w: np.ndarray, height: float,
                    translate: bool) -> float:
        """The heading, among ``yaw_search`` evenly spaced ones, whose query is nearest to the
        database: for a user whose torso has not been reliable yet. The unreliable hip and
        shoulder lines are only a hypothesis: the spacing starts at the heading they give. The
        distance is that of the nearest neighbour, scale-invariant while the height is not known
        (:meth:`NaturalPostureOptimizer.knn_scaled`), else Eq. 9."""
        yaw0 = float(facing_yaw(obs, np.maximum(w, 1e-3)))
        best, best_d = yaw0, np.inf
        wr = np.where(w >= self.reliable_threshold, w, 0.0)
        for yaw in yaw0 + np.arange(self.yaw_search) * (2.0 * np.pi / self.yaw_search):
            q = self.preparer.prepare(obs, w, height, yaw=float(yaw)).query
            if self._height_settled():
                d = float(self.core.knn_search(q, w, translate=translate)[1][0])
            else:
                d = float(self.core.knn_scaled(q, wr, translate, (height / 2.3, height))[1][0])
            if d < best_d:
                best, best_d = float(yaw), d
        return best

    def _database_yaw(self, query: np.ndarray, w: np.ndarray, centre: bool,
                      scaled: bool = False) -> Optional[float]:
        """The rotation about the vertical by which the reliable joints of ``query`` (20, 3) are
        off the database: Eq. 9 over the reliable joints minimised, for every database posture,
        over that rotation (closed-form weighted 2-D Procrustes; with ``centre``, i.e. the root
        unreliable, over a translation too: weighted centroids removed); the circular
        inverse-distance weighted mean of the rotations of the ``yaw_neighbours`` nearest.
        Unlike a fit to the KNN neighbours of the query at its current heading, which favour
        that heading, no heading is preferred. ``scaled``: minimised over a uniform scale of the
        query as well (while the user's height is not known). None with fewer than two reliable
        joints."""
        rel = w >= self.reliable_threshold
        if rel.sum() < 2:
            return None
        wr = np.where(rel, w, 0.0)
        ws = float(wr.sum())
        q = np.where(rel[:, None], query, 0.0)  # the other rows do not count (nor a NaN there)
        if centre:
            q = q - (wr @ q) * (1.0 / ws)
        Yh, Yz = self._yaw_arrays()
        sq, coord = self.core.knn_arrays[0], self.core.knn_arrays[2]
        # sum_j w_j conj(q_j) y_j with the horizontal coordinates as complex numbers: its angle
        # is the best rotation of q onto y, and sum_j w_j |y_j - rot q_j|^2 (horizontal) is
        # sum_j w_j (|y_j|^2 + |q_j|^2) - 2 |c| at that rotation. With q centred, y's centroid
        # drops out of c and of the vertical cross term and leaves -|w| |centroid|^2.
        c = Yh @ (wr * (q[:, 0] - 1j * q[:, 1]))                   # (N,)
        ac = np.abs(c)
        syy = sq @ wr                                               # sum_j w_j |y_j|^2
        if centre:
            yc = (coord @ wr).reshape(-1, 3)
            syy -= np.einsum('nd,nd->n', yc, yc) * (1.0 / ws)
        sqq = float(wr @ np.einsum('jd,jd->j', q, q))
        sxq = Yz @ (wr * q[:, 2])                                  # the vertical: not rotated
        sxq += ac
        if scaled:
            # minimised over a uniform scale of the query too: the shape distance of
            # NaturalPostureOptimizer.knn_scaled (the user's height is not known yet)
            d = 1.0 - np.maximum(sxq, 0.0) ** 2 / (np.maximum(syy, 1e-12) * max(sqq, 1e-12))
        else:
            d = syy - 2.0 * sxq
            d += sqq
        k = min(self.yaw_neighbours, len(d))
        idx = np.argpartition(d, k - 1)[:k]
        a = ac[idx]
        if a.max() < 1e-9:
            return None
        inv = 1.0 / (np.maximum(d[idx], 0.0) + 1e-6)
        return float(np.angle(inv @ (c[idx] / np.maximum(a, 1e-12))))

    def _yaw_arrays(self) -> tuple:
        """The database's horizontal coordinates as complex numbers (N, 20) and heights (N, 20),
        computed once per database and shared."""
        arrays = self.db.derived.get('yaw')
        if arrays is None:
            P = self.db.positions
            Yh = np.ascontiguousarray(P[..., 0] + 1j * P[..., 1])
            Yz = np.ascontiguousarray(P[..., 2], dtype=float)
            for x in (Yh, Yz):
                x.setflags(write=False)
            arrays = self.db.derived['yaw'] = (Yh, Yz)
        return arrays

    def _fit_height(self, query: np.ndarray, w: np.ndarray, height: float,
                    translate: bool) -> None:
        """While the sensor has not measured the user's height (no frame with every joint
        tracked), estimate it from the database: the scale-invariant KNN search (Eq. 9 minimised
        over a uniform scale of the query's reliable joints) gives the scale at which the
        query's reliable joints best match a database posture of the standard body; the user
        is ``height / scale`` tall (the query was scaled by standard / ``height``). The median
        over the first ``height_frames`` such frames becomes the reliability estimator's height
        prior (query scale and standard-body lengths), then stays. Only frames where no segment
        has two reliable ends count: then no length can be measured, and every reliable joint
        is below an unreliable one, so the query scaled all of them by the height (a joint below
        reliable ones is retargeted to the standard lengths instead and says nothing about the
        user's size)."""
        rel = w >= self.reliable_threshold
        if rel.sum() < _MIN_FIT_JOINTS or (rel[_SEG_P] & rel[_SEG_C]).any():
            return
        lo, hi = 1.0, 2.3   # the reliability estimator's height range
        _, dist, s = self.core.knn_scaled(query, np.where(rel, w, 0.0), translate,
                                          (height / hi, height / lo))
        inv = 1.0 / (dist + 1e-6)
        scale = float(inv @ s / inv.sum())
        self._height_fits.append(height / scale)
        self.reliability.set_height_prior(float(np.median(self._height_fits)))
        if len(self._height_fits) >= self.height_frames:
            self._height_done = True

    def _update_trust(self, positions: np.ndarray, w: np.ndarray, rms: float) -> float:
        """The trust in the sensor (module docstring) for this frame, in [0, 1]."""
        if self.trust_mode == 'distance':
            d0 = self.trust_sensor_distance  # standard-body metres
            return min(max((rms - d0) / max(d0, 1e-6), 0.0), 1.0)
        if len(self._hist) == 2:
            rel = w >= self.reliable_threshold
            if rel.any():
                a = positions - 2.0 * self._hist[-1] + self._hist[-2]
                a = a[rel]
                an = np.sort(np.sqrt(np.einsum('jk,jk->j', a, a)))
                m = len(an)
                n = 0.5 * float(an[(m - 1) // 2] + an[m // 2])  # the median
                self._noise_n += 1  # running mean first, then exponential
                rate = max(self.noise_alpha, 1.0 / self._noise_n)
                self._noise = n if self._noise is None else (1 - rate) * self._noise + rate * n
        self._hist.append(positions)
        rate = max(2.0 * self.noise_alpha, 1.0 / (self._noise_n + 1))
        self._rms_avg = rms if self._rms_avg is None else (1 - rate) * self._rms_avg + rate * rms
        if self._noise is None:
            return 1.0
        self.noise = self._noise
        r0 = self.trust_sensor_ratio
        return min(max((self._rms_avg / max(self._noise, 1e-4) - r0) / r0, 0.0), 1.0)

    def _segments_output(self, frame: SkeletonFrame, solution: np.ndarray, w: np.ndarray,
                         trust: float, yaw: Optional[float] = None,
                         seg_obs: Optional[np.ndarray] = None,
                         len_obs: Optional[np.ndarray] = None,
                         root: Optional[np.ndarray] = None) -> np.ndarray:
        """Output_mode 'segments' (module docstring). ``solution`` (20, 3): in the sensor frame,
        or, with ``yaw``, the normalised solution (only its segment directions matter: they are
        turned by ``yaw``). ``seg_obs`` / ``len_obs``: the observed segment vectors (19, 3) and
        lengths (19,) when already computed."""
        obs = np.asarray(frame.positions, float)
        if seg_obs is None:
            seg_obs = _SEG_DIFF @ obs
            len_obs = np.sqrt(np.einsum('sk,sk->s', seg_obs, seg_obs))
        L = self.output_segment_lengths(obs, w, len_obs)
        vs = _SEG_DIFF @ solution
        if yaw is not None:
            vs = vs @ yaw_rotation(yaw).T
        ns = np.sqrt(np.einsum('sk,sk->s', vs, vs))
        us = vs / np.maximum(ns, 1e-9)[:, None]
        uo = seg_obs / np.maximum(len_obs, 1e-9)[:, None]
        zero = len_obs <= 1e-9
        if zero.any():
            uo[zero] = us[zero]
        wmin = np.minimum(w[_SEG_P], w[_SEG_C])
        thr = self.reliable_threshold
        rel_frac = np.minimum(wmin * (1.0 / max(thr, 1e-6)), 1.0)
        beta = rel_frac * trust
        if self.observation_weight > 0.0:
            np.maximum(beta, self.observation_weight * (wmin >= thr), out=beta)
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
        if self._seg_filter is not None:
            # filter clock: the stamps' steps where plausible (1 ms - 0.5 s), else 30 Hz
            stamp = int(frame.stamp_ns or 0)
            dt = 1.0 / 30.0
            if self._last_stamp is not None and 1e6 <= stamp - self._last_stamp <= 5e8:
                dt = (stamp - self._last_stamp) * 1e-9
            self._last_stamp = stamp
            self._filter_clock_ns += int(round(dt * 1e9))
            scale = speed = None
            if self.smooth_filled_scale != 1.0:
                # a segment the database fills in (an end with reliability 0) is smoothed with
                # smooth_filled_scale times the cutoff, a reliable one as set, linear between
                fs = self.smooth_filled_scale
                scale = np.ones(NUM_SEGMENTS + 1)
                scale[:NUM_SEGMENTS] = fs + (1.0 - fs) * rel_frac
                if self.smooth_filled_speed:
                    # the factor applies to the minimum cutoff only: the One Euro speed term is
                    # kept, so that a filled segment is smoothed at rest but does not lag when
                    # the body moves
                    speed = np.ones(NUM_SEGMENTS + 1)
                elif (self.smooth_anchored_speed and self._torso_weight(w) < thr
                        and not (wmin >= thr).any()):
                    # few reliable joints: filled segments with a reliable joint hanging from
                    # them keep the speed term too, in proportion (module docstring)
                    anchored = np.minimum((_SEG_BELOW * w).max(axis=1)
                                          * (1.0 / max(thr, 1e-6)), 1.0)
                    if anchored.any():
                        speed = scale.copy()
                        speed[:NUM_SEGMENTS] += anchored * (1.0 - scale[:NUM_SEGMENTS])
            vr = self._seg_filter.update(vr, None, self._filter_clock_ns, scale, speed)
            v = vr[:NUM_SEGMENTS]
            nv = np.sqrt(np.einsum('sk,sk->s', v, v))
            keep = nv > 1e-9
            v = (v / np.maximum(nv, 1e-9)[:, None]) if keep.all() else \
                np.where(keep[:, None], v / np.maximum(nv, 1e-9)[:, None], u)
            v *= L[:, None]
        else:
            v = vr[:NUM_SEGMENTS]
        return vr[NUM_SEGMENTS] + _SEG_CHAIN @ v

    def process(self, frame: SkeletonFrame) -> SkeletonFrame:
        t0 = time.perf_counter()
        corr = self.correction
        if corr is not None and self.correction_stage == 'input':
            frame = frame.copy(positions=corr.apply(frame.positions))
        R = np.asarray(self._reliability_for(frame), float)
        if corr is not None and self.correction_stage == 'reliable':
            frame = frame.copy(positions=corr.apply(frame.positions, R, self.reliable_threshold))
        obs = np.asarray(frame.positions, float)
        seg_obs = _SEG_DIFF @ obs
        len_obs = np.sqrt(np.einsum('sk,sk->s', seg_obs, seg_obs))
        segments = self.method != 'A' and self.output_mode == 'segments'
        if not segments:
            self._observe_lengths(len_obs, R)
        t1 = time.perf_counter()
        height = self.reliability.height
        if self.method == 'A':
            user_bones = user_bone_lengths(self.user_segment_lengths())
            res = self.core.complete(frame.positions, R, height, frame.orientations, user_bones)
            positions, ori = res.positions, res.orientations
            self.timings_ms = {'reliability': 1e3 * (t1 - t0),
                               'completion': 1e3 * (time.perf_counter() - t1)}
        else:
            w = R if self.use_reliability else np.ones(NUM_JOINTS)
            translate = self.float_root and w[ROOT] < self.reliable_threshold
            rel = w >= self.reliable_threshold
            # few reliable joints: the torso is unreliable and no segment has two reliable ends
            few = (self._torso_weight(w) < self.reliable_threshold
                   and not (rel[_SEG_P] & rel[_SEG_C]).any())
            # a heading / scale fit needs at least three reliable joints (two leave the
            # rotation about their line and, with the translation free, the scale undetermined)
            fit_ok = int(rel.sum()) >= _MIN_FIT_JOINTS
            yaw_in = None
            if few:
                # the hips and shoulders are unreliable: keep the heading they last gave (or
                # search one at the start), corrected below from the database
                if self._yaw_state is None and self.yaw_search > 0 and fit_ok:
                    self._yaw_state = self._search_yaw(obs, w, height, translate)
                yaw_in = self._yaw_state
            prep = self.preparer.prepare(obs, w, height, yaw=yaw_in)
            yaw = float(prep.transform.yaw)
            prev = []
            for x, y in self._prev:  # bring earlier solutions into this frame's heading
                prev.append(x @ yaw_rotation(y - yaw).T)
            res = self.core.solve(prep.query, w, prev[::-1], translate=translate)
            self._prev.append((res.positions, yaw))
            theta = None
            if few and fit_ok and self.yaw_rate > 0.0:
                theta = self._database_yaw(prep.query, w, translate,
                                           scaled=not self._height_settled())
            self._yaw_state = yaw if theta is None else yaw - self.yaw_rate * theta
            if not self._height_settled():
                self._fit_height(prep.query, w, height, translate)
            t2 = time.perf_counter()
            wsum = float(w.sum())
            rms = float(np.sqrt(res.distances[0] / max(wsum, 1e-6)))
            alpha = self._update_trust(obs, w, rms)
            self.trust_sensor = alpha
            root = None
            if res.shift is not None and alpha < 1.0:
                # the root towards where the database neighbours place it, as far as the
                # database is trusted more than the sensor
                root = obs[ROOT] - ((1.0 - alpha) / prep.scale) * (yaw_rotation(yaw) @ res.shift)
            if segments:
                positions = self._segments_output(frame, res.positions, w, alpha, yaw=yaw,
                                                  seg_obs=seg_obs, len_obs=len_obs, root=root)
            else:
                user_bones = user_bone_lengths(self.user_segment_lengths())
                bones = user_bones if self.output_scale == 'user' else None
                positions = to_sensor_frame(res.positions, prep.transform, bones,
                                            self._rest_dirs)
                if alpha > 0.0:
                    keep = w >= self.reliable_threshold
                    positions[keep] = ((1.0 - alpha) * positions[keep]
                                       + alpha * frame.positions[keep])
            ori = None
            if res.orientations is not None:
                ori = res.orientations @ yaw_quat_matrix(yaw).T
            elif frame.orientations is not None:
                ori = frame.orientations.copy()
            self.timings_ms = {'reliability': 1e3 * (t1 - t0),
                               'prepare': 1e3 * (t2 - t1) - sum(res.timings_ms.values()),
                               **res.timings_ms,
                               'output': 1e3 * (time.perf_counter() - t2)}
        self.last_result = res
        return frame.copy(positions=np.asarray(positions, float),
                          reliability=R.astype(np.float32),
                          orientations=None if ori is None else np.asarray(ori, float))
