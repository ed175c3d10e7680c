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
  the segments get the user's constant lengths (one rigid skeleton per user,
  :mod:`.bone_lengths`: the robust mean of the first ``length_frames`` trusted observations of
  each segment, then frozen, estimated again only for another person; :attr:`bone_lengths`; with
  ``symmetric_lengths`` the left and right limbs share the mean of their two lengths; with
  ``length_prior`` and a database that stores its bodies' proportions, combined with those
  proportions at the user's fitted size, each weighted by its expected error -- with a
  ``correction`` that carries them, its reference's proportions instead:
  :mod:`.length_prior`) and are chained from the observed root; the segment
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

Both need at least three reliable joints.

``smooth_anchored_speed`` (default on): with few reliable joints (as above: the hip and the
shoulder line unreliable and no segment with two reliable ends), a filled segment with a
reliable joint at or below its child (a tracked hand or foot hanging from it) keeps the One Euro
speed term (``smooth_filled_scale`` lowers only its minimum cutoff), in proportion to that joint's reliability (1 at or
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
frame instead of the mean of the first ``length_frames`` observations. (Their node parameters:
:class:`~.correction.CorrectionConfig`.)

``trust_sensor`` holds the last trust factor. The paper's behaviour: ``output_mode='blend'``,
``trust_mode='distance'``, ``reference_mode='standard'``, ``w_style=0.5`` (the default 8 weights
the closest-neighbour style term 16x higher: measured on the sensor-model dev streams, Eq. 18 a/b/c
4.70/5.90/8.79 -> 4.52/5.48/7.81 cm, real recordings unchanged).
"""
from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass
from typing import Dict, Optional

import numpy as np

from skeleton_core.conversions import SkeletonFrame
from skeleton_core.geometry import yaw_matrix
from skeleton_core.model import (NUM_JOINTS, NUM_SEGMENTS, ROOT, SEGMENT_CHILD_INDEX,
                                 SEGMENT_PARENT_INDEX)
from skeleton_core.params import build, check, nested, param
from skeleton_core.params import split as params_split

from .body_fit import BodyFit, BodyFitConfig
from .completion import CompletionConfig, PCACompletion
from .optimizer import NaturalPostureOptimizer, OptimizerConfig, solve_batch
from .plausibility import unswap_permutation
from .posture_space import (QueryConfig, QueryPreparer, as_database_arrays, rest_directions,
                            to_sensor_frame, user_bone_lengths, yaw_quat_matrix)
from .correction import STAGES as CORRECTION_STAGES
from .correction import CorrectionConfig, check_tracker
from .profile import from_optional as profile_lengths
from .length_prior import LengthPrior, LengthPriorConfig
from .reliability import ReliabilityConfig, ReliabilityEstimator
from .segment_output import (SEG_DIFF, SegmentOutput, SegmentOutputConfig,
                             database_segment_units, neighbour_direction_spread,
                             neighbour_direction_spreads, smooth_many)
from .trust import SensorTrust, TrustConfig

METHODS = ('A', 'B', 'C')
OUTPUT_MODES = ('segments', 'blend')


@dataclass
class ReconstructorConfig(QueryConfig):
    """The reconstruction's own parameters (module docstring) and those of its units (the trust
    in the sensor, the body fit, the segment output); its core's are in
    :class:`~.optimizer.OptimizerConfig` / :class:`~.completion.CompletionConfig`, the reliability's
    in :class:`~.reliability.ReliabilityConfig`."""

    use_input_reliability: bool = param(
        True, 'use the reliability field of the input when it is filled (else estimate it)',
        public=False)
    output_scale: str = param('user', "user: result retargeted to the user's bone lengths; "
                              'standard: the database body', choices=('user', 'standard'),
                              public=False)
    output_mode: str = param(
        'segments', 'segments: blended segment directions, constant user lengths, chained from '
        'the root, smoothed; blend: solution blended towards the observed joints (paper)',
        choices=OUTPUT_MODES, public=False)
    length_window: int = param(90, 'blend: frames of observed segment lengths whose median gives '
                               "the user's lengths", range=(1, 100000), public=False)
    float_root: bool = param(
        True, 'when the root joint is unreliable, match the database translation-invariantly '
        'and place the root (and the query) where the neighbours put it', public=False)
    latch_trust: bool = param(
        True, 'a segment the plausibility stage latched after a jump (a snap) scores the '
        'trust in the sensor after its jump frame: where the database does not explain the '
        'user its fill would be worse than the sensor\'s new place', public=False)
    trust: TrustConfig = nested(TrustConfig)
    lengths: LengthPriorConfig = nested(LengthPriorConfig)
    segments: SegmentOutputConfig = nested(SegmentOutputConfig)
    body_fit: BodyFitConfig = nested(BodyFitConfig)


def split_params(method: str, params: Dict) -> tuple:
    """``params`` by owner: (:class:`ReliabilityConfig`, the core's config (method A:
    :class:`CompletionConfig`, else :class:`OptimizerConfig`), :class:`ReconstructorConfig`).
    The other core's parameters are accepted and ignored (one set of values serves every method);
    any other name is refused."""
    core_cls, other_cls = ((CompletionConfig, OptimizerConfig) if method == 'A'
                           else (OptimizerConfig, CompletionConfig))
    own, rel, core, _, unknown = params_split(params, ReconstructorConfig, ReliabilityConfig,
                                              core_cls, other_cls)
    if unknown:
        raise ValueError(f'unknown reconstruction parameters: {sorted(unknown)}')
    return rel, core, own


class Reconstructor:
    """One user's reconstruction pipeline (see module docstring). Parameters: the fields of
    :class:`ReconstructorConfig`, :class:`ReliabilityConfig` and the core's config as keywords
    (their parameter names). ``use_reliability``: weight the query by the reliability (default:
    method C only)."""

    def __init__(self, db, method: str = 'C', use_reliability: Optional[bool] = None,
                 correction=None, correction_stage: str = CorrectionConfig.correction_stage,
                 input_tracker: str = '', profile=None, length_noise=None, **params):
        method = str(method).upper()
        if method not in METHODS:
            raise ValueError(f'method must be one of {METHODS}, got {method!r}')
        rel, core, own = split_params(method, params)
        cfg = build(ReconstructorConfig, own)
        check(cfg)
        self.config = cfg
        self.output_mode = cfg.output_mode
        self.float_root = bool(cfg.float_root)
        self.latch_trust = bool(cfg.latch_trust)
        self.method = method
        self.name = method
        if correction_stage not in CORRECTION_STAGES:
            raise ValueError(f'correction_stage must be one of {CORRECTION_STAGES}')
        if correction is not None:
            check_tracker(correction, input_tracker)  # never applied to another tracker
        self.correction = correction
        self.correction_stage = correction_stage
        self.db = as_database_arrays(db)
        self.reliability = ReliabilityEstimator(**rel)
        self.use_reliability = (method == 'C') if use_reliability is None else bool(use_reliability)
        self.use_input_reliability = bool(cfg.use_input_reliability)
        self.reliable_threshold = float(cfg.reliable_threshold)
        self.output_scale = cfg.output_scale
        self.preparer = QueryPreparer(self.db.body, self.reliable_threshold)
        self._rest_dirs = rest_directions(self.db.body)
        self.trust = SensorTrust(cfg.trust, self.reliable_threshold)
        if method == 'A':
            self.core = PCACompletion(self.db, reliable_threshold=self.reliable_threshold, **core)
            self.body_fit = None
        else:
            self.core = NaturalPostureOptimizer(self.db, **core)
            self.body_fit = BodyFit(self.core.search, self.preparer, self.reliability,
                                    self.reliable_threshold, cfg.body_fit)
        self.segment_output = SegmentOutput(
            self.reliability, self.db.body.segment_lengths,
            self.body_fit.height_settled if self.body_fit else (lambda: True),
            self.reliable_threshold, self.output_scale, cfg.segments)
        self.segment_output.profile_lengths = profile_lengths(profile)
        # the sensor's segment length noise on earlier users (bone_lengths.SensorLengthNoise,
        # shared by the users of one sensor): a new user's first frames converge with it
        self.segment_output.estimator.noise_memory = length_noise
        # a correction maps the joints to its reference's layout: the prior takes its proportions
        self.length_prior = LengthPrior.from_meta(
            cfg.lengths, getattr(db, 'meta', None), cfg.segments.symmetric_lengths,
            layout=getattr(correction, 'meta', None))
        if self.length_prior is not None:
            self.segment_output.length_prior = self.length_prior.fuse
            self.segment_output.proportions = np.stack([self.segment_output.proportions,
                                                        self.length_prior.mean])
            prior = self.length_prior
            self.segment_output.offset_sigma = lambda: prior.offset_sigma
        self.length_window = int(cfg.length_window)
        self.timings_ms: Dict[str, float] = {}
        self.trust_sensor = 0.0
        self.last_result = None
        self.reset()

    @property
    def noise(self) -> float:
        """The sensor's measured frame-to-frame noise (m; NaN until known)."""
        return self.trust.noise

    def reset(self) -> None:
        self._user_id = None
        self.reliability.reset()
        self._last_output: Optional[SkeletonFrame] = None
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

    def set_profile(self, profile) -> None:
        """Use another user profile (UserProfile, (19,) lengths or None) and forget the user."""
        self.segment_output.profile_lengths = profile_lengths(profile)
        self.reset()

    @property
    def rigid_output(self) -> bool:
        """Every output posture has the user's constant lengths (methods B / C, segments)."""
        return self.method != 'A' and self.output_mode == 'segments'

    @property
    def bone_lengths(self) -> Optional[np.ndarray]:
        """(19,) the user's segment lengths (m) every output posture of methods B and C (output
        mode ``'segments'``) has, once estimated (:mod:`.bone_lengths`); None before, and for
        method A and the blend output."""
        return self.segment_output.user_lengths if self.rigid_output else None

    @property
    def bone_length_restarts(self) -> int:
        """How often the lengths were estimated again (another person under the same id)."""
        return int(self.segment_output.estimator.restarts)

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
        if self.segment_output.profile_lengths is not None:
            return self.segment_output.profile_lengths
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
        thr = self.reliable_threshold
        good = (R[SEGMENT_PARENT_INDEX] >= thr) & (R[SEGMENT_CHILD_INDEX] >= thr)
        self._lengths[self._lengths_n % self.length_window] = np.where(good, ln, np.nan)
        self._lengths_n += 1

    def process(self, frame: SkeletonFrame) -> SkeletonFrame:
        step = self._begin(frame)
        if isinstance(step, SkeletonFrame):
            return step
        res = self.core.solve(step.query, step.w, step.prev, translate=step.translate)
        return self._output_frame(step, res, self._output_rows(step, res))

    def _begin(self, frame: SkeletonFrame):
        """The frame up to the optimizer: the output frame when it is done without one (method
        A, a held skeleton), else the :class:`_Pending` solve that :meth:`_output_rows` and
        :meth:`_output_frame` complete."""
        t0 = time.perf_counter()
        uid = getattr(frame, 'user_id', None)
        if uid != self._user_id:
            if self._user_id is not None:
                # the input says this is another user (a new tracking id): nothing of the last
                # one holds -- no whole-skeleton-jump hold on the old place, no lengths, no
                # smoothing state (plausibility.py's jump rule is for one user's skeleton)
                self.reset()
            self._user_id = uid
        corr = self.correction
        if corr is not None and self.correction_stage == 'input':
            frame = frame.copy(positions=corr.apply(frame.positions))
        R = np.asarray(self._reliability_for(frame), float)
        plaus = self.reliability.plausibility
        if plaus.skeleton_outlier and self._last_output is not None:
            # the whole skeleton jumped (another person / a chair): nothing of this frame is
            # the user; the last output is held until the skeleton is back (plausibility.py)
            self.timings_ms = {'reliability': 1e3 * (time.perf_counter() - t0)}
            return self._last_output.copy(stamp_ns=frame.stamp_ns,
                                          reliability=R.astype(np.float32))
        perm = unswap_permutation(plaus.swapped) if plaus.lr_unswap else None
        if perm is not None:
            # the sensor swapped left and right limbs (plausibility.py): swap them back, each
            # joint with its own reliability
            frame = frame.copy(positions=np.asarray(frame.positions, float)[perm],
                               tracking_state=frame.tracking_state[perm])
            R = R[perm]
        if corr is not None and self.correction_stage == 'reliable':
            frame = frame.copy(positions=corr.apply(frame.positions, R, self.reliable_threshold))
        obs = np.asarray(frame.positions, float)
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
            self.timings_ms = {'reliability': 1e3 * (t1 - t0),
                               'completion': 1e3 * (time.perf_counter() - t1)}
            return self._emit(frame, res.positions, R, res.orientations, res)
        w = R if self.use_reliability else np.ones(NUM_JOINTS)
        translate = self.float_root and w[ROOT] < self.reliable_threshold
        few = self.body_fit.few_reliable(w)   # (the body fit's update takes it again)
        yaw_in = self.body_fit.heading_in(obs, w, height, translate, few)
        prep = self.preparer.prepare(obs, w, height, yaw=yaw_in)
        yaw = float(prep.transform.yaw)
        prev = []
        for x, y in self._prev:  # bring earlier solutions into this frame's heading
            prev.append(x @ yaw_matrix(y - yaw).T)
        return _Pending(frame=frame, R=R, obs=obs, seg_obs=seg_obs, len_obs=len_obs, w=w,
                        translate=translate, prep=prep, yaw=yaw, height=height,
                        prev=prev[::-1], segments=segments, t0=t0, t1=t1, few=few)

    def _wants_spread(self, p: '_Pending', res) -> bool:
        return bool(p.segments and self.segment_output.direction_db_spread
                    and res.neighbours is not None)

    def _output_rows(self, p: '_Pending', res, spread=None):
        """The frame after the optimizer's result ``res`` for :meth:`_begin`'s ``p``, up to the
        segment output's smoothing filter (``spread``: the neighbours' direction spread when
        already computed): the body fit and the trust updated; the segment output's
        :class:`~.segment_output.SmoothingStep` (None for the blend output)."""
        obs, w, yaw, prep = p.obs, p.w, p.yaw, p.prep
        tf = time.perf_counter()
        self._prev.append((res.positions, yaw))
        self.body_fit.update(prep.query, w, p.height, yaw, p.translate, p.few)
        t2 = time.perf_counter()
        # the optimizer's own stages are timed by it (in a batch: its share of the batch)
        prepare = (1e3 * (p.t_solve - p.t1 + t2 - tf) if p.t_solve
                   else 1e3 * (t2 - p.t1) - sum(res.timings_ms.values()))
        self.timings_ms = {'reliability': 1e3 * (p.t1 - p.t0), 'prepare': prepare,
                           **res.timings_ms}
        wsum = float(w.sum())
        rms = float(np.sqrt(res.distances[0] / max(wsum, 1e-6)))
        alpha = self.trust.update(obs, w, rms)
        self.trust_sensor = alpha
        if self.latch_trust:
            self.reliability.plausibility.sensor_trust = alpha
        step = None
        if p.segments:
            root = None
            if res.shift is not None and alpha < 1.0:
                # the root towards where the database neighbours place it, as far as the
                # database is trusted more than the sensor
                root = obs[ROOT] - ((1.0 - alpha) / prep.scale) * (yaw_matrix(yaw) @ res.shift)
            if spread is None and self._wants_spread(p, res):
                units = database_segment_units(self.db).take(res.neighbours, axis=0)
                spread = neighbour_direction_spread(None, res.distances, units)
            step = self.segment_output.output_rows(
                p.frame, res.positions, w, alpha, yaw=yaw, seg_obs=p.seg_obs, len_obs=p.len_obs,
                root=root, db_spread=spread, db_distance=rms)
        self.timings_ms['output'] = 1e3 * (time.perf_counter() - t2)
        return step

    def _output_frame(self, p: '_Pending', res, step, rows=None) -> SkeletonFrame:
        """:meth:`_output_rows`' frame from the smoothing filter on: the output frame of
        :meth:`_output_rows`' ``step`` (None: the blend output), ``rows`` its smoothed rows
        when already smoothed (else smoothed here)."""
        t3 = time.perf_counter()
        frame, yaw = p.frame, p.yaw
        if step is not None:
            positions = self.segment_output.output_positions(step, rows)
        else:
            user_bones = user_bone_lengths(self.user_segment_lengths())
            bones = user_bones if self.output_scale == 'user' else None
            positions = to_sensor_frame(res.positions, p.prep.transform, bones,
                                        self._rest_dirs)
            alpha = self.trust_sensor
            if alpha > 0.0:
                keep = p.w >= self.reliable_threshold
                positions[keep] = ((1.0 - alpha) * positions[keep]
                                   + alpha * frame.positions[keep])
        ori = None
        if res.orientations is not None:
            ori = res.orientations @ yaw_quat_matrix(yaw).T
        elif frame.orientations is not None:
            ori = frame.orientations.copy()
        self.timings_ms['output'] += 1e3 * (time.perf_counter() - t3)
        return self._emit(frame, positions, p.R, ori, res)

    def _emit(self, frame, positions, R, ori, res) -> SkeletonFrame:
        self.last_result = res
        out = frame.copy(positions=np.asarray(positions, float),
                         reliability=R.astype(np.float32),
                         orientations=None if ori is None else np.asarray(ori, float))
        self._last_output = out
        return out


@dataclass
class _Pending:
    """One user's frame from :meth:`Reconstructor._begin` to its output frame: the optimizer's
    inputs (``query`` normalised, ``w``, ``prev`` most recent first, ``translate``) and what
    the output stage needs."""
    frame: SkeletonFrame
    R: np.ndarray
    obs: np.ndarray
    seg_obs: np.ndarray
    len_obs: np.ndarray
    w: np.ndarray
    translate: bool
    prep: object
    yaw: float
    height: float
    prev: list
    segments: bool
    t0: float
    t1: float
    t_solve: float = 0.0
    few: Optional[tuple] = None   # the body fit's few_reliable(w)

    @property
    def query(self) -> np.ndarray:
        return self.prep.query


def process_batch(recs, frames) -> list:
    """:meth:`Reconstructor.process` of several users' frames of one time (one Reconstructor
    each, distinct), their optimizer runs solved together (:func:`~.optimizer.solve_batch`):
    the outputs are those of ``[r.process(f) for r, f in zip(recs, frames)]``. Each element of
    the result is the output frame or the exception that user's frame raised (the others go
    on)."""
    outs: list = [None] * len(recs)
    pend = []
    for i, (r, f) in enumerate(zip(recs, frames)):
        try:
            step = r._begin(f)
        except USER_ERRORS as e:
            outs[i] = e
            continue
        if isinstance(step, SkeletonFrame):
            outs[i] = step
        else:
            step.t_solve = time.perf_counter()
            pend.append((i, step))
    if not pend:
        return outs
    try:
        results = solve_batch([recs[i].core for i, _ in pend], [p.query for _, p in pend],
                              [p.w for _, p in pend], [p.prev for _, p in pend],
                              [p.translate for _, p in pend])
    except USER_ERRORS:
        results = None   # one user's numbers broke the batch: each alone, its error its own
    spreads = {}
    if results is not None:
        # the neighbours' segment direction spreads of the users whose output uses them
        want = [k for k, (i, p) in enumerate(pend) if recs[i]._wants_spread(p, results[k])]
        if len(want) > 1 and len({len(results[k].neighbours) for k in want}) == 1:
            idx = np.array([results[k].neighbours for k in want])
            units = database_segment_units(recs[pend[want[0]][0]].db).take(idx, axis=0)
            sp = neighbour_direction_spreads(None, np.array([results[k].distances for k in want]),
                                             units)
            spreads = dict(zip(want, sp))
    done = []
    for k, (i, p) in enumerate(pend):
        try:
            res = results[k] if results is not None else recs[i].core.solve(
                p.query, p.w, p.prev, translate=p.translate)
            done.append((i, p, res, recs[i]._output_rows(p, res, spreads.get(k))))
        except USER_ERRORS as e:
            outs[i] = e
    t = time.perf_counter()
    smoothed = smooth_many([step for *_, step in done])   # the users' filters together
    share = 1e3 * (time.perf_counter() - t) / max(len(done), 1)
    for (i, p, res, step), rows in zip(done, smoothed):
        recs[i].timings_ms['output'] += share
        try:
            outs[i] = (rows if isinstance(rows, Exception)   # that user's filter raised
                       else recs[i]._output_frame(p, res, step, rows))
        except USER_ERRORS as e:
            outs[i] = e
    return outs


# what one user's frame may raise in the reconstruction (the node drops that frame and resets
# that user)
USER_ERRORS = (ValueError, FloatingPointError, ArithmeticError, IndexError)
