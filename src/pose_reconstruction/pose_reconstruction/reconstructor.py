"""Per-user streaming posture reconstruction: reliability + method A, B or C.

``Reconstructor(db, method='C', **params).process(frame) -> frame`` fills in the reliability,
reconstructs the positions, sets the orientations (sensor frame), and keeps stamp, user id and
frame id. One instance per user (it keeps that user's history); ``reset()`` forgets it.

Methods (Shum et al. 2013, Sec. VIII-B):

* ``'A'`` — Shum & Ho 2012 database completion (:class:`~.completion.PCACompletion`);
* ``'B'`` — the natural-posture-space optimizer with every reliability 1;
* ``'C'`` — the optimizer with the reliability of Eq. 8 (the paper's method).

Graceful degradation (B/C): when even the nearest database posture is farther than
``trust_sensor_distance`` (RMS per reliable joint, metres) from the query, the database cannot
describe the posture, so joints at or above ``reliable_threshold`` are blended towards their
observed positions, linearly from 0 % at that distance to 100 % (kept as observed) at twice it
(``trust_sensor`` holds the last blend factor).
"""
from __future__ import annotations

import time
from collections import deque
from typing import Dict, Optional

import numpy as np

from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS, NUM_SEGMENTS, SEGMENT_CHILDREN, SEGMENT_PARENTS

from .completion import PCACompletion
from .optimizer import NaturalPostureOptimizer
from .posture_space import (QueryPreparer, as_database_arrays, orientations_to_sensor,
                            rest_directions, to_sensor_frame, user_bone_lengths)
from .reliability import ReliabilityEstimator

METHODS = ('A', 'B', 'C')
_SEG_P = np.array(SEGMENT_PARENTS)
_SEG_C = np.array(SEGMENT_CHILDREN)
RELIABILITY_PARAMS = ('d_min', 'f_b', 'theta_floor_deg', 'theta_roof_deg', 'f_total',
                      'sigma_frames', 'tracked_value', 'inferred_value', 'not_tracked_value',
                      'reference_pose_tolerance_deg', 'reference_frames')
OPTIMIZER_PARAMS = ('k', 'pca_dims', 'steps', 'samples', 'w_control', 'w_style', 'w_kinematics',
                    'w_continuity', 'step_scale', 'solver', 'gn_iterations', 'seed', 'knn',
                    'kdtree_dims', 'kdtree_candidates')
COMPLETION_PARAMS = ('pca_dims', 'reliability_threshold', 'substitution')
OWN_PARAMS = ('use_reliability', 'use_input_reliability', 'reliable_threshold',
              'trust_sensor_distance', 'output_scale', 'length_window')


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
                 length_window: int = 90, **params):
        method = str(method).upper()
        if method not in METHODS:
            raise ValueError(f'method must be one of {METHODS}, got {method!r}')
        if output_scale not in ('user', 'standard'):
            raise ValueError("output_scale must be 'user' or 'standard'")
        self.method = method
        self.name = method
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

    def _observe_lengths(self, positions: np.ndarray, R: np.ndarray) -> None:
        good = (R[_SEG_P] >= self.reliable_threshold) & (R[_SEG_C] >= self.reliable_threshold)
        ln = np.linalg.norm(positions[_SEG_C] - positions[_SEG_P], axis=1)
        self._lengths[self._lengths_n % self.length_window] = np.where(good, ln, np.nan)
        self._lengths_n += 1

    def process(self, frame: SkeletonFrame) -> SkeletonFrame:
        t0 = time.perf_counter()
        R = self._reliability_for(frame)
        self._observe_lengths(frame.positions, np.asarray(R, float))
        t1 = time.perf_counter()
        height = self.reliability.height
        user_bones = user_bone_lengths(self.user_segment_lengths())
        if self.method == 'A':
            res = self.core.complete(frame.positions, R, height, frame.orientations, user_bones)
            positions, ori = res.positions, res.orientations
            self.timings_ms = {'reliability': 1e3 * (t1 - t0),
                               'completion': 1e3 * (time.perf_counter() - t1)}
        else:
            w = R if self.use_reliability else np.ones(NUM_JOINTS)
            prep = self.preparer.prepare(frame.positions, w, height)
            yaw = float(prep.transform.yaw)
            prev = []
            for x, y in self._prev:  # bring earlier solutions into this frame's heading
                dy = y - yaw
                c, s = np.cos(dy), np.sin(dy)
                prev.append(x @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T)
            res = self.core.solve(prep.query, w, prev[::-1])
            self._prev.append((res.positions, yaw))
            t2 = time.perf_counter()
            bones = user_bones if self.output_scale == 'user' else None
            positions = to_sensor_frame(res.positions, prep.transform, bones, self._rest_dirs)
            wsum = float(np.sum(w))
            rms = np.sqrt(res.distances[0] / max(wsum, 1e-6))
            d0 = self.trust_sensor_distance  # standard-body metres
            alpha = float(np.clip((rms - d0) / max(d0, 1e-6), 0.0, 1.0))
            self.trust_sensor = alpha
            if alpha > 0.0:
                keep = w >= self.reliable_threshold
                positions[keep] = (1.0 - alpha) * positions[keep] + alpha * frame.positions[keep]
            ori = None
            if res.orientations is not None:
                ori = orientations_to_sensor(res.orientations, yaw)
            elif frame.orientations is not None:
                ori = frame.orientations.copy()
            self.timings_ms = {'reliability': 1e3 * (t1 - t0),
                               'prepare': 1e3 * (t2 - t1) - sum(res.timings_ms.values()),
                               **res.timings_ms,
                               'output': 1e3 * (time.perf_counter() - t2)}
        self.last_result = res
        return frame.copy(positions=np.asarray(positions, float),
                          reliability=np.asarray(R, np.float32),
                          orientations=None if ori is None else np.asarray(ori, float))
