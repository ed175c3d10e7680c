"""Intention recognition (Ishigaki et al. 2009, Sec. 6.1).

The unconstrained end-effectors' positions and velocities relative to the centre of mass, with the
body's yaw removed, form the feature vector ``w = [r_j, tau * r'_j]`` (positions divided by the
body height, so users of other sizes compare; ``tau`` (s) puts velocities in the units of
positions). PCA of the example motion's vectors gives the basis ``A`` (first m components);

    e1 = || w - A A^T w ||^2                 (Eq. 5, with w centred on the example's mean)
    e2 = || dw - A A^T dw ||^2,  dw = w_t - w_{t-lag}      (Eq. 6)

A user imitates when both errors (exponentially averaged over ``smoothing`` s) are below their
thresholds and the effectors move at least ``min_activity`` times the example's RMS speed (a
still pose has dw = 0: without this gate standing still would be a perfect "consistency").

Missing effectors (``missing_effectors``): when the sensor reports an effector INFERRED or
NOT_TRACKED (an occlusion: the Kinect freezes it, collapses it onto the body or drops it), its
coordinates are not evidence. The errors are then those of the observed coordinates o only, with
the subspace coefficients fitted to them (PCA with missing data):

    e1 = (D - m) / (D_o - m) * min_c || P_o (w - mean - A c) ||^2

and likewise e2; (D - m) / (D_o - m) keeps the expected residual of isotropic noise the same as
with every coordinate observed (D coordinates, D_o observed, m components; used only while
D_o > m). An effector counts as observed after ``track_settle`` TRACKED frames in a row (its
velocity over ``lag`` frames and the low-pass have left the jump from the held position). The
fit has a Gaussian prior on the coefficients (``missing_prior``: probabilistic PCA), so that one
observed hand is not explained by coefficients far outside the example's range.

Onset (``e2_approach``): e2 leaves out the part of the residual's change that heads back into
the example's subspace (:func:`approach_discount`): a user moving into the example's range is
not inconsistent with it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, Optional, Sequence

import numpy as np
from skeleton_core.geometry import facing_yaw, pca
from skeleton_core.params import check, param
from skeleton_core.model import (JOINT_INDEX, SEGMENT_CHILDREN, SEGMENT_MASS_FRACTION,
                                 SEGMENT_PARENTS, JOINT_NAMES, TRACKED, estimate_height)

from .support import HangDetector

_SEG_W = np.array([SEGMENT_MASS_FRACTION[JOINT_NAMES[c]] for c in SEGMENT_CHILDREN])
_SEG_W = _SEG_W / _SEG_W.sum()
_PARENTS, _CHILDREN = np.array(SEGMENT_PARENTS), np.array(SEGMENT_CHILDREN)


def center_of_mass(positions: np.ndarray) -> np.ndarray:
    """Whole-body COM (..., 3) of joint positions (..., 20, 3): segment midpoints weighted by
    the standard body's mass fractions (Winter 2009)."""
    p = np.asarray(positions, float)
    mid = 0.5 * (p[..., _PARENTS, :] + p[..., _CHILDREN, :])
    if mid.ndim == 2:       # one pose (every control step, several times): no einsum parsing
        return _SEG_W @ mid
    return np.einsum('k,...kd->...d', _SEG_W, mid)


def yaw_rotation(yaw) -> np.ndarray:
    """Rotation matrices (..., 3, 3) taking world vectors to the yaw-removed body frame."""
    yaw = np.asarray(yaw, float)
    c, s = np.cos(yaw), np.sin(yaw)
    r = np.zeros(yaw.shape + (3, 3))
    r[..., 0, 0], r[..., 0, 1], r[..., 1, 0], r[..., 1, 1] = c, s, -s, c
    r[..., 2, 2] = 1.0
    return r


# The activity gate also asks the effectors to move relative to the trunk (the arms themselves, at
# min_activity x the example's speed of the same): a squat, a lunge or standing up carries still
# arms through the COM-relative frame (real Kinect v2, UI-PRMD: the breaststroke fired on them).
ARM_ACTIVITY = True


# body heights: the largest offset of a user's mean posture from the example's that
# ``own_posture`` forgives (the effectors' mean positions, all coordinates; beyond it the excess
# counts in e1 as a distance from the subspace). The offsets of the walking styles the project's
# performers are drawn with (:func:`.examples.random_style`: elbows bent up to 25 deg more,
# shoulders flexed +-12 deg, abducted -8..12 deg) reach 0.155 for every body height (1.5-1.95 m);
# the continuous performance's seed 1 walks at 0.135. An assumption about people, not measured on
# real walkers
OWN_POSTURE_RANGE = 0.16


def relative_effectors(positions: np.ndarray, effectors: Sequence[int],
                       yaw: Optional[np.ndarray] = None) -> np.ndarray:
    """r_j = d_j - COM (the paper's origin, the whole-body COM) in the yaw-removed body frame,
    (..., len(effectors), 3)."""
    p = np.asarray(positions, float)
    if yaw is None:
        yaw = facing_yaw(p)
    rel = p[..., list(effectors), :] - center_of_mass(p)[..., None, :]
    return np.einsum('...ij,...kj->...ki', yaw_rotation(yaw), rel)


def trunk_relative(positions: np.ndarray, effectors: Sequence[int]) -> np.ndarray:
    """The effectors relative to the ShoulderCenter in the trunk's own frame (x forward, y left,
    z from the HipCenter to the ShoulderCenter), (..., len(effectors), 3): what the arms do, not
    the body carrying them (a squat or a lunge moves the hands relative to the COM, not here)."""
    p = np.asarray(positions, float)
    up = p[..., JOINT_INDEX['ShoulderCenter'], :] - p[..., JOINT_INDEX['HipCenter'], :]
    up = up / np.maximum(np.linalg.norm(up, axis=-1, keepdims=True), 1e-9)
    lat = p[..., JOINT_INDEX['ShoulderLeft'], :] - p[..., JOINT_INDEX['ShoulderRight'], :]
    lat = lat - np.sum(lat * up, axis=-1, keepdims=True) * up
    lat = lat / np.maximum(np.linalg.norm(lat, axis=-1, keepdims=True), 1e-9)
    fwd = np.cross(lat, up)
    rot = np.stack([fwd, lat, up], axis=-2)                      # rows: the trunk's axes
    rel = p[..., list(effectors), :] - p[..., JOINT_INDEX['ShoulderCenter'], None, :]
    return np.einsum('...ij,...kj->...ki', rot, rel)


def pca_columns(w: np.ndarray, m: int, center: bool = True):
    """(mean (D,), A (D, m) orthonormal columns, eigenvalues (m,)) of the rows of ``w`` (N, D):
    :func:`skeleton_core.geometry.pca` with the axes as the columns of A (Ishigaki's notation)."""
    mean, axes, lam = pca(w, m, center)
    return mean, axes.T.copy(), lam


def reconstruction_error(v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """|| v - A A^T v ||^2 for v (..., D): Eq. 5 and 6."""
    v = np.asarray(v, float)
    r = v - (v @ a) @ a.T
    return np.sum(r * r, axis=-1)


def residual(v: np.ndarray, a: np.ndarray, observed: Optional[np.ndarray] = None,
             prior: Optional[np.ndarray] = None):
    """(r, scale): the residual of v (D,) out of span(A) (D, m) -- ``v - A A^T v``, scale 1 --
    or, with ``observed`` (D,) bool, of the observed coordinates only: ``v_o - A_o c`` with c
    the least-squares fit to them, scale (D - m) / (D_o - m) (PCA with missing data; D_o, the
    number of observed coordinates, must exceed m). ``scale * |r|^2`` is the error of Eq. 5/6.
    ``prior`` (m,) = sigma^2 / lambda_i: the fit ``min |v_o - A_o c|^2 + sum prior_i c_i^2``
    (probabilistic PCA: the coefficients a Gaussian of the example's variances lambda_i, the
    residual of variance sigma^2 per coordinate), which keeps a few observed coordinates from
    being explained by coefficients far outside the example's range."""
    v = np.asarray(v, float)
    if observed is None:
        return v - a @ (a.T @ v), 1.0
    obs = np.asarray(observed, bool)
    d, m = a.shape
    d_o = int(obs.sum())
    if d_o <= m:
        raise ValueError(f'{d_o} observed coordinates cannot test a {m}-dimensional subspace')
    ao, vo = a[obs], v[obs]
    if prior is None:
        c = np.linalg.lstsq(ao, vo, rcond=None)[0]
    else:
        c = np.linalg.solve(ao.T @ ao + np.diag(prior), ao.T @ vo)
    return vo - ao @ c, (d - m) / (d_o - m)


def partial_reconstruction_error(v: np.ndarray, a: np.ndarray, observed: np.ndarray) -> float:
    """Eq. 5/6 on the observed coordinates only (PCA with missing data):
    (D - m) / (D_o - m) * min_c || v_o - A_o c ||^2, where v_o, A_o are the rows of v (D,) and
    A (D, m) with ``observed`` (D,) bool true and D_o their number. With every coordinate
    observed it is :func:`reconstruction_error` (A orthonormal); D_o must exceed m."""
    r, scale = residual(v, a, observed)
    return float(r @ r) * scale


def approach_discount(r: np.ndarray, dr: np.ndarray) -> np.ndarray:
    """The change ``dr`` of the residual out of the example's subspace without its part that
    heads back into the subspace: with ``r_old = r - dr`` (the residual ``lag`` frames ago),
    the component of dr along ``-r_old`` (at most |r_old|: no credit for overshooting) is
    removed; a change away from the subspace or sideways is kept whole."""
    r_old = np.asarray(r, float) - np.asarray(dr, float)
    n = float(np.linalg.norm(r_old))
    if n <= 0.0:
        return np.asarray(dr, float)
    u = r_old / n
    along = float(dr @ u)
    if along >= 0.0:
        return np.asarray(dr, float)
    return dr - max(along, -n) * u


@dataclass
class RecognizerParams:
    """Intention recognition (Sec. 6.1); every field is a node parameter (skeleton_core.params)."""

    e1_threshold: float = param(0.03, "Eq. 5 threshold (squared error, body-height units): the "
                                "user's pose near the example's PCA subspace", range=(1e-5, 10.0))
    e2_threshold: float = param(0.04, "Eq. 6 threshold: consistency of the user's change over "
                                "lag frames with the example", range=(1e-5, 10.0))
    tau: float = param(0.25, 'weight (s) of the effector velocities against positions in w',
                       range=(0.0, 2.0), public=False)
    lag: int = param(2, 'frames of the velocity and of dw in Eq. 6', range=(1, 30), read_only=True,
                     public=False)
    smoothing: float = param(0.03, 'time constant (s) of the e1/e2 averages', range=(0.0, 5.0),
                             public=False)
    min_activity: float = param(0.3, "share of the example's RMS effector speed the user must "
                                "reach to be imitating (a still pose has dw = 0)",
                                range=(0.0, 10.0))
    activity_window: float = param(0.3, 'time constant (s) of the speed average of the activity '
                                   'gate', range=(0.0, 10.0), public=False)
    activity_lag: int = param(9, "frames of the activity gate's displacement", range=(1, 60),
                              read_only=True, public=False)
    prefilter: float = param(0.03, 'time constant (s) of the low-pass on the relative joint '
                             'positions before the features (sensor noise)', range=(0.0, 1.0),
                             public=False)
    max_change_share: float = param(1.0, "largest share of the user's effector displacement "
                                    "over share_lag frames outside the example's position "
                                    "subspace, for all features (each example has its own "
                                    "too; 1 = off): a change the example never makes, e.g. "
                                    "one hand punching against a two-handed stroke",
                                    range=(0.0, 1.0), public=False)
    share_lag: int = param(4, "frames of the change-share gate's displacement", range=(1, 60),
                           read_only=True, public=False)
    share_window: float = param(0.1, 'time constant (s) of the change-share averages',
                                range=(0.0, 10.0), public=False)
    missing_effectors: bool = param(True, "compare only the effectors the sensor TRACKS when "
                                    "others are INFERRED or NOT_TRACKED (occluded: frozen, "
                                    "collapsed or dropped): e1/e2 of the observed coordinates "
                                    "with the PCA coefficients fitted to them; false = every "
                                    "effector as reported", public=False)
    e2_approach: bool = param(True, "e2 leaves out the part of the change that heads back "
                              "into the example's subspace (the residual shrinking: a user "
                              "moving into the example's range at the onset of an imitation)",
                              public=False)
    missing_prior: float = param(0.1, "the missing-data fit's residual variance sigma^2 (D - m) "
                                 "(body-height^2 units) against the example's variance along "
                                 "each component: c = argmin |v_o - A_o c|^2 + sigma^2 sum "
                                 "c_i^2 / lambda_i (0 = plain least squares)",
                                 range=(0.0, 10.0), public=False)
    track_settle: int = param(3, "TRACKED frames in a row before an effector counts as observed "
                              "again (its velocity over lag frames and the low-pass settle)",
                              range=(1, 30), read_only=True, public=False)
    fps: float = 30.0

    def validate(self) -> None:
        check(self)
        for k in ('e1_threshold', 'e2_threshold', 'tau', 'fps'):
            if not getattr(self, k) > 0:
                raise ValueError(f'{k} must be positive')
        if not 1 <= int(self.lag) <= 30 or not 1 <= int(self.activity_lag) <= 60:
            raise ValueError('lag must be in [1, 30] frames, activity_lag in [1, 60]')
        if not (self.smoothing >= 0 and self.min_activity >= 0 and self.activity_window >= 0):
            raise ValueError('smoothing, activity_window and min_activity must be >= 0')


def feature_vectors(positions: np.ndarray, effectors: Sequence[int], height: float,
                    params: RecognizerParams) -> np.ndarray:
    """w for every frame of a clip (T, 20, 3) -> (T, 6 * len(effectors)); the first ``lag``
    frames get the velocity of frame ``lag``."""
    r = relative_effectors(positions, effectors) / height
    lag = int(params.lag)
    v = np.zeros_like(r)
    if len(r) > lag:
        v[lag:] = (r[lag:] - r[:-lag]) * (params.fps / lag)
        v[:lag] = v[lag]
    return np.concatenate([r.reshape(len(r), -1), params.tau * v.reshape(len(v), -1)], axis=1)


class ExampleModel:
    """The PCA of one feature's example motion (Eq. 5-6), from its positions (T, 20, 3)."""

    def __init__(self, name: str, positions: np.ndarray, effectors: Sequence[str],
                 components: int, params: RecognizerParams, height: Optional[float] = None,
                 max_change_share: float = 1.0, hang_joint: Optional[str] = None,
                 own_posture: float = 0.0):
        self.name = name
        # > 0: e1 also about the user's own mean posture (the feature vector low-passed over
        # this many s, the example's period), the lesser counts -- an oscillation compared with
        # the example's, a user's constant posture offset (elbows bent more, shoulders flexed: a
        # style) not counted (:meth:`IntentionRecognizer.update`)
        self.own_posture = float(own_posture)
        # a feature held from above (the bars): the user hanging -- off the floor longer than a
        # jump, both hands above this joint (:mod:`.support`) -- is recognised as it too
        self.hang_joint = hang_joint
        self.max_change_share = float(max_change_share)
        self.effectors = tuple(JOINT_INDEX[e] for e in effectors)
        self.params = params
        self.positions = np.asarray(positions, float)
        self.height = float(height or estimate_height(self.positions[0]))
        w = feature_vectors(self.positions, self.effectors, self.height, params)
        self.w = w
        self.mean, self.A, self.eigenvalues = pca_columns(w, components)
        # the change-share gate's subspace: every direction in which the example's relative
        # positions move (the principal components up to 99 % of their variance)
        npos = 3 * len(self.effectors)
        _, a_pos, lam_pos = pca_columns(w[:, :npos], npos)
        keep = int(np.searchsorted(np.cumsum(lam_pos) / max(lam_pos.sum(), 1e-12), 0.99)) + 1
        self.A_pos = a_pos[:, :min(keep, npos)]
        lag = min(int(params.lag), len(w) - 1)
        # the variance of dw's coefficients (the missing-data fit's prior for e2)
        self.eigenvalues_dw = np.var((w[lag:] - w[:-lag]) @ self.A, axis=0)
        # the activity gate's normaliser: the example's RMS effector speed measured as the gate
        # measures it (displacement over activity_lag frames)
        r = relative_effectors(self.positions, self.effectors) / self.height
        k = min(int(params.activity_lag), len(r) - 1)
        v = (r[k:] - r[:-k]).reshape(len(r) - k, -1) * (params.fps / k)
        self.rms_speed = float(np.sqrt(np.mean(np.sum(v * v, axis=1))))
        # per effector: its share of the mean square speed (the gate over observed effectors)
        self.ms_speed = np.mean(v * v, axis=0).reshape(len(self.effectors), 3).sum(axis=1)
        # the arm-activity gate's normaliser: per effector, the example's mean square speed of
        # the effector relative to the trunk (:func:`trunk_relative`), measured the same way
        ra = trunk_relative(self.positions, self.effectors) / self.height
        va = (ra[k:] - ra[:-k]).reshape(len(ra) - k, -1) * (params.fps / k)
        self.ms_arm_speed = np.mean(va * va, axis=0).reshape(len(self.effectors), 3).sum(axis=1)

    def errors(self, w: np.ndarray, dw: np.ndarray, observed: Optional[np.ndarray] = None):
        """(e1, e2) of Eq. 5-6 (on the ``observed`` coordinates (D,) bool only, when given:
        :func:`partial_reconstruction_error`)."""
        prm = getattr(self, 'params', None)
        p1 = p2 = None
        pf = float(getattr(prm, 'missing_prior', 0.0))
        if pf > 0 and observed is not None:
            sig = pf / (self.A.shape[0] - self.A.shape[1])     # residual variance per coordinate
            p1 = sig / np.maximum(self.eigenvalues, 1e-12)
            p2 = sig / np.maximum(self.eigenvalues_dw, 1e-12)
        r, scale = residual(w - self.mean, self.A, observed, p1)
        dr, _ = residual(dw, self.A, observed, p2)
        if getattr(prm, 'e2_approach', False):
            dr = approach_discount(r, dr)
        return float(r @ r) * scale, float(dr @ dr) * scale


@dataclass
class Recognition:
    feature: str
    imitating: bool
    confidence: float
    e1: float
    e2: float
    activity: float
    w: Optional[np.ndarray] = None   # the user's feature vector for this feature's effectors
    change_share: float = 0.0        # share of the recent displacement outside the example's
    hanging: bool = False            # recognised by the user's support (:mod:`.support`)


class IntentionRecognizer:
    """Per user: feeds on poses (20, 3) at the sensor rate; :meth:`update` returns a
    :class:`Recognition` per feature with an example motion."""

    def __init__(self, models: Sequence[ExampleModel], params: RecognizerParams):
        params.validate()
        self.models = list(models)
        self.params = params
        self.height: Optional[float] = None
        self._hist = []      # the last lag + 1 relative joint arrays
        self._thist = []     # the same, trunk-relative (:func:`trunk_relative`)
        self._trunk_joints = sorted({j for m in self.models for j in m.effectors})
        self._whist: Dict[str, list] = {}   # the last lag + 1 feature vectors per model
        self._avg: Dict[str, list] = {}
        self._own_mean: Dict[str, np.ndarray] = {}   # the user's mean w per own-posture model
        self._last_t: Optional[float] = None
        self._tracked_run: Optional[np.ndarray] = None   # TRACKED frames in a row per joint
        self.support = HangDetector()
        # the legs at work (a squat, sitting, a lunge: :meth:`.support.HangDetector.legs_bent`)
        # veto every example, all imitated standing; off only in the benchmark, which applies
        # other constants offline (:func:`.support.bent_legs_mask`)
        self.bent_legs_gate = True

    def reset(self) -> None:
        self.support.reset()
        self._tracked_run = None
        self._hist = []
        self._thist = []
        self._whist = {}
        self._avg = {}
        self._own_mean = {}
        self._last_t = None

    def update(self, positions: np.ndarray, t: float,
               tracking_state: Optional[np.ndarray] = None) -> Dict[str, Recognition]:
        """One pose (20, 3) at ``t`` s; ``tracking_state`` (20,) the sensor's per-joint state
        (TRACKED = 2; None: every joint tracked)."""
        p = np.asarray(positions, float)
        if self.height is None:
            h = estimate_height(p)
            self.height = float(np.clip(h, 1.0, 2.3)) if np.isfinite(h) else 1.75
        prm = self.params
        if tracking_state is None or not prm.missing_effectors:
            self._tracked_run = None
        else:
            tr = np.asarray(tracking_state).reshape(-1) == TRACKED
            run = self._tracked_run if self._tracked_run is not None else np.full(len(tr), 10 ** 6)
            self._tracked_run = np.where(tr, run + 1, 0)
        self.support.update(p, t)
        yaw = facing_yaw(p)
        com = center_of_mass(p)
        rot = yaw_rotation(yaw)
        rel = (p - com) @ rot.T / self.height          # every joint, body frame, height units
        dt_f = 1.0 / prm.fps if self._last_t is None else max(t - self._last_t, 1e-3)
        g = 1.0 - math.exp(-dt_f / prm.prefilter) if prm.prefilter > 0 else 1.0
        if self._hist and prm.prefilter > 0:
            rel = self._hist[-1] + g * (rel - self._hist[-1])
        trunk = np.zeros_like(p)       # only the compared effectors' rows are used
        trunk[self._trunk_joints] = trunk_relative(p, self._trunk_joints) / self.height
        if self._thist and prm.prefilter > 0:
            trunk = self._thist[-1] + g * (trunk - self._thist[-1])
        self._hist.append(rel)
        self._thist.append(trunk)
        lag = int(prm.lag)
        keep = max(lag, int(prm.activity_lag), int(prm.share_lag)) + 1
        if len(self._hist) > keep:
            self._hist.pop(0)
            self._thist.pop(0)
        dt = 1.0 / prm.fps if self._last_t is None else max(t - self._last_t, 1e-3)
        self._last_t = t
        alpha = 1.0 if prm.smoothing <= 0 else 1.0 - math.exp(-dt / prm.smoothing)
        beta = 1.0 if prm.activity_window <= 0 else 1.0 - math.exp(-dt / prm.activity_window)
        out = {}
        k = min(len(self._hist) - 1, lag)
        old = self._hist[-1 - k]
        ka = min(len(self._hist) - 1, int(prm.activity_lag))
        old_a = self._hist[-1 - ka]
        ks = min(len(self._hist) - 1, int(prm.share_lag))
        old_s = self._hist[-1 - ks]
        gam = 1.0 if prm.share_window <= 0 else 1.0 - math.exp(-dt / prm.share_window)
        legs_bent = self.bent_legs_gate and self.support.legs_bent()
        shared: Dict[tuple, tuple] = {}
        for m in self.models:
            idx = list(m.effectors)
            obs_e = None
            if self._tracked_run is not None:
                obs_e = self._tracked_run[idx] >= int(prm.track_settle)
                if obs_e.all() or 6 * int(obs_e.sum()) <= m.A.shape[1]:
                    obs_e = None      # all observed, or too few to test the subspace
            key = tuple(idx)
            if key not in shared:     # the same effectors (the hands, every playground
                # feature): their vectors once per frame
                r = rel[idx].reshape(-1)
                v = (r - old[idx].reshape(-1)) * (prm.fps / k) if k else np.zeros_like(r)
                va = (r - old_a[idx].reshape(-1)) * (prm.fps / ka) if ka else np.zeros_like(r)
                old_t = self._thist[-1 - ka]
                vt = ((trunk[idx] - old_t[idx]).reshape(-1) * (prm.fps / ka) if ka
                      else np.zeros_like(r))
                vs = r - old_s[idx].reshape(-1)
                shared[key] = (r, np.concatenate([r, prm.tau * v]), va, vt, vs,
                               float(np.sum(va * va)), float(np.sum(vt * vt)),
                               float(np.sum(vs * vs)))
            r, w, va, vt, vs, va2, vt2, vs2 = shared[key]
            wh = self._whist.setdefault(m.name, [])
            wh.append(w)
            if len(wh) > lag + 1:
                wh.pop(0)
            dw = w - wh[0]
            obs_w = None if obs_e is None else np.tile(np.repeat(obs_e, 3), 2)
            e1, e2 = m.errors(w, dw, obs_w)
            win = float(getattr(m, 'own_posture', 0.0))
            e1_own = None
            if win > 0:       # e1 about the user's own mean posture too
                mu = self._own_mean.get(m.name)
                if mu is None:
                    mu = self._own_mean[m.name] = w.copy()
                else:
                    mu += (1.0 - math.exp(-dt / win)) * (w - mu)
                # the user's posture offset beyond a walking style's counts (a boxer's guard,
                # hands at the chin, is no walking style: CMU boxing took the walk otherwise)
                npos = 3 * len(idx)
                off = float(np.linalg.norm(mu[:npos] - m.mean[:npos]))
                e1_own = (m.errors(w - mu + m.mean, dw, obs_w)[0]
                          + max(0.0, off - OWN_POSTURE_RANGE) ** 2)
            # the share of the displacement over share_lag frames (vs) outside the example's
            # position subspace (energies averaged over share_window, then divided)
            if obs_e is None:
                sp2 = va2 / max(m.rms_speed, 1e-9) ** 2
                arm2 = vt2 / max(float(m.ms_arm_speed.sum()), 1e-18)
                out2, all2 = float(reconstruction_error(vs, m.A_pos)), vs2
            else:     # the observed effectors against the example's speed of the same ones
                obs_p = np.repeat(obs_e, 3)
                sp2 = float(np.sum(va[obs_p] ** 2)) / max(float(m.ms_speed[obs_e].sum()), 1e-18)
                arm2 = (float(np.sum(vt[obs_p] ** 2))
                        / max(float(m.ms_arm_speed[obs_e].sum()), 1e-18))
                all2 = float(np.sum(vs[obs_p] ** 2))
                out2 = (partial_reconstruction_error(vs, m.A_pos, obs_p)
                        * (int(obs_p.sum()) - m.A_pos.shape[1]) / (len(obs_p) - m.A_pos.shape[1])
                        if int(obs_p.sum()) > m.A_pos.shape[1] else all2)
            a = self._avg.get(m.name)
            if a is None:
                a = self._avg[m.name] = [e1, e2, sp2, out2, all2, arm2,
                                         e1 if e1_own is None else e1_own]
            else:
                a[0] += alpha * (e1 - a[0])
                # about the user's own mean an oscillation outside the example's subspace (both
                # arms swinging together) passes near zero error twice a cycle: its e1 is the
                # average over the example's period, the oscillation's energy outside
                if e1_own is not None:
                    a[6] += (1.0 - math.exp(-dt / win)) * (e1_own - a[6])
                a[1] += alpha * (e2 - a[1])
                a[2] += beta * (sp2 - a[2])
                a[3] += gam * (out2 - a[3])
                a[4] += gam * (all2 - a[4])
                a[5] += beta * (arm2 - a[5])
            share = a[3] / max(a[4], 1e-12)
            act = math.sqrt(max(a[2], 0.0))
            if ARM_ACTIVITY:      # the arms themselves must move, not only the body carrying them
                act = min(act, math.sqrt(max(a[5], 0.0)))
            # the user's pose near the example's subspace about the example's mean, or about the
            # user's own mean posture (own_posture: a constant offset is a style; the example's
            # mean still right after a change of posture, while the user's mean follows it)
            # (the user's own posture only with the legs' evidence of a walk: the feet alternate,
            # :meth:`.support.HangDetector.stepping` -- a boxer's punches, which swing the hands
            # fore-aft in anti-phase about a raised guard, did not step: CMU boxing)
            e1_avg = (a[0] if e1_own is None or not self.support.stepping()
                      else min(a[0], a[6]))
            r1, r2 = e1_avg / prm.e1_threshold, a[1] / prm.e2_threshold
            ratio = max(r1, r2)   # e1 and e2 both under their thresholds
            # the activity is measured over activity_lag frames: until a user has been seen that
            # long, a displacement over fewer frames is mostly sensor noise (x30 per frame)
            imitating = bool(ratio < 1.0 and act >= prm.min_activity and k >= lag
                             and ka >= int(prm.activity_lag)
                             and share <= min(prm.max_change_share, m.max_change_share))
            conf = 1.0 / (1.0 + ratio * ratio)
            if act < prm.min_activity:
                conf *= act / max(prm.min_activity, 1e-9)
            if imitating and legs_bent:       # the legs move the body, not an imitation
                imitating = False
            hang = bool(getattr(m, 'hang_joint', None) and self.support.hanging(m.hang_joint))
            if hang:          # held from above: the feature whatever the hands' motion
                imitating, conf = True, max(conf, 1.0 / (1.0 + min(ratio, 1.0) ** 2))
            out[m.name] = Recognition(m.name, imitating, float(conf), float(e1_avg), float(a[1]),
                                      act, w, float(share), hang)
        return out

    def best(self, recs: Dict[str, Recognition]) -> Optional[Recognition]:
        """The imitated feature with the highest confidence (None if none is imitated)."""
        cands = [r for r in recs.values() if r.imitating]
        return max(cands, key=lambda r: r.confidence) if cands else None


__all__ = ['ExampleModel', 'IntentionRecognizer', 'RecognizerParams', 'Recognition',
           'center_of_mass', 'relative_effectors', 'pca_columns', 'reconstruction_error',
           'partial_reconstruction_error', 'residual', 'approach_discount',
           'feature_vectors', 'yaw_rotation']
