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
  scale, neighbours ranked by shape distance; :meth:`~.search.DatabaseSearch.knn_scaled`);
  it scales the query and gives the standard-body lengths of the segments never observed;
* heading: the last heading of the reliable torso is kept (at the start, the best of
  ``yaw_search`` headings against the database, from the one the unreliable torso gives) and
  turned each frame by ``yaw_rate`` times the rotation that best fits the reliable joints to
  the database (:meth:`~.search.DatabaseSearch.database_yaw`: per database posture a weighted 2-D
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
from skeleton_core.model import NUM_JOINTS, NUM_SEGMENTS, ROOT, SEGMENT_CHILDREN, SEGMENT_PARENTS

from .body_fit import BodyFit
from .completion import PCACompletion
from .optimizer import NaturalPostureOptimizer
from .posture_space import (QueryPreparer, as_database_arrays, rest_directions, to_sensor_frame,
                            user_bone_lengths, yaw_quat_matrix, yaw_rotation)
from .reliability import ReliabilityEstimator
from .segment_output import SEG_DIFF, SegmentOutput
from .trust import TRUST_MODES, SensorTrust

METHODS = ('A', 'B', 'C')
OUTPUT_MODES = ('segments', 'blend')
_SEG_P = np.array(SEGMENT_PARENTS)
_SEG_C = np.array(SEGMENT_CHILDREN)


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
              'yaw_rate', 'yaw_search', 'yaw_neighbours', 'smooth_filled_speed')


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
                 **params):
        method = str(method).upper()
        if method not in METHODS:
            raise ValueError(f'method must be one of {METHODS}, got {method!r}')
        if output_scale not in ('user', 'standard'):
            raise ValueError("output_scale must be 'user' or 'standard'")
        if output_mode not in OUTPUT_MODES:
            raise ValueError(f'output_mode must be one of {OUTPUT_MODES}')
        if trust_mode not in TRUST_MODES:
            raise ValueError(f'trust_mode must be one of {TRUST_MODES}')
        self.output_mode = output_mode
        self.float_root = bool(float_root)
        self.method = method
        self.name = method
        self.db = as_database_arrays(db)
        rel, core, _ = split_params(method, params)
        self.reliability = ReliabilityEstimator(**rel)
        self.use_reliability = (method == 'C') if use_reliability is None else bool(use_reliability)
        self.use_input_reliability = bool(use_input_reliability)
        self.reliable_threshold = float(reliable_threshold)
        self.output_scale = output_scale
        self.preparer = QueryPreparer(self.db.body, self.reliable_threshold)
        self._rest_dirs = rest_directions(self.db.body)
        self.trust = SensorTrust(trust_mode, trust_sensor_ratio, noise_alpha, trust_sensor_distance,
                                 self.reliable_threshold)
        if method == 'A':
            core.setdefault('reliability_threshold', self.reliable_threshold)
            self.core = PCACompletion(self.db, **core)
            self.body_fit = None
        else:
            self.core = NaturalPostureOptimizer(self.db, **core)
            self.body_fit = BodyFit(self.core.search, self.preparer, self.reliability,
                                    self.reliable_threshold, height_frames, yaw_rate, yaw_search,
                                    yaw_neighbours)
        self.segment_output = SegmentOutput(
            self.reliability, self.db.body.segment_lengths,
            self.body_fit.height_settled if self.body_fit else (lambda: True),
            self.reliable_threshold, output_scale, length_frames, symmetric_lengths,
            observation_weight, smooth_min_cutoff, smooth_beta, smooth_d_cutoff,
            smooth_filled_scale, smooth_filled_speed, smooth_anchored_speed)
        self.length_window = int(length_window)
        if self.length_window < 1:
            raise ValueError('length_window must be >= 1')
        self.timings_ms: Dict[str, float] = {}
        self.trust_sensor = 0.0
        self.last_result = None
        self.reset()

    @property
    def noise(self) -> float:
        """The sensor's measured frame-to-frame noise (m; NaN until known)."""
        return self.trust.noise

    def reset(self) -> None:
        self.reliability.reset()
        self._prev = deque(maxlen=2)  # (normalised solution (20, 3), yaw)
        self._lengths = np.full((self.length_window, NUM_SEGMENTS), np.nan)
        self._lengths_n = 0
        self._user_lengths: Optional[np.ndarray] = None
        self.trust.reset()
        self.segment_output.reset()
        if self.body_fit is not None:
            self.body_fit.reset()
        if isinstance(self.core, NaturalPostureOptimizer):
            self.core.reset_rng()

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

    def process(self, frame: SkeletonFrame) -> SkeletonFrame:
        t0 = time.perf_counter()
        obs = np.asarray(frame.positions, float)
        R = np.asarray(self._reliability_for(frame), float)
        seg_obs = SEG_DIFF @ obs
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
            yaw_in = self.body_fit.heading_in(obs, w, height, translate)
            prep = self.preparer.prepare(obs, w, height, yaw=yaw_in)
            yaw = float(prep.transform.yaw)
            prev = []
            for x, y in self._prev:  # bring earlier solutions into this frame's heading
                prev.append(x @ yaw_rotation(y - yaw).T)
            res = self.core.solve(prep.query, w, prev[::-1], translate=translate)
            self._prev.append((res.positions, yaw))
            self.body_fit.update(prep.query, w, height, yaw, translate)
            t2 = time.perf_counter()
            wsum = float(w.sum())
            rms = float(np.sqrt(res.distances[0] / max(wsum, 1e-6)))
            alpha = self.trust.update(obs, w, rms)
            self.trust_sensor = alpha
            root = None
            if res.shift is not None and alpha < 1.0:
                # the root towards where the database neighbours place it, as far as the
                # database is trusted more than the sensor
                root = obs[ROOT] - ((1.0 - alpha) / prep.scale) * (yaw_rotation(yaw) @ res.shift)
            if segments:
                positions = self.segment_output.output(frame, res.positions, w, alpha, yaw=yaw,
                                                       seg_obs=seg_obs, len_obs=len_obs,
                                                       root=root)
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
