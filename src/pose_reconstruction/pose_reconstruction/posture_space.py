"""Shared helpers of the reconstruction methods: database arrays, fast single-posture
retargeting, query preparation (normalise + retarget, Shum et al. 2013 Sec. V-B) and the way back
to the sensor frame.

Everything works on one posture at a time with vectorised numpy (no Python loop over joints), so
that a query costs tens of microseconds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, Optional

import numpy as np

from skeleton_core.geometry import NormalizeTransform, facing_yaw, retarget_by_joint
from skeleton_core.model import (HEADING_JOINTS, NUM_JOINTS, PARENTS, PATH_TO_ROOT, ROOT,
                                 SEGMENT_CHILDREN, SEGMENT_PARENTS, Body, standard_body)

# each joint's parent (the root's own index for the root)
PARENT_ROWS = np.array([max(p, 0) for p in PARENTS])
_SEG_P = np.array(SEGMENT_PARENTS)
_SEG_C = np.array(SEGMENT_CHILDREN)

# ANCESTORS[j, k] = 1 when k is j or one of its ancestors, excluding the root (the model's tree)
ANCESTORS = PATH_TO_ROOT
# STRICT_ANCESTORS[j, k] = 1 when k is a proper ancestor of j (root included)
STRICT_ANCESTORS = np.zeros((NUM_JOINTS, NUM_JOINTS), bool)
for _j in range(NUM_JOINTS):
    _k = PARENTS[_j]
    while _k >= 0:
        STRICT_ANCESTORS[_j, _k] = True
        _k = PARENTS[_k]
_STRICT_ANCESTORS_F = STRICT_ANCESTORS.astype(float)
# (20, 20): positions -> offsets from the parent (the root's row 0)
_PARENT_DIFF = np.eye(NUM_JOINTS)
_PARENT_DIFF[np.arange(NUM_JOINTS), PARENT_ROWS] -= 1.0
_PARENT_DIFF[ROOT] = 0.0
_HEADING = list(HEADING_JOINTS)
_NON_ROOT = np.array([j for j in range(NUM_JOINTS) if j != ROOT])


def _weighted_yaw(p: np.ndarray, w: np.ndarray):
    """``facing_yaw(p, np.maximum(w, 1e-3))`` for one posture (20, 3), the same arithmetic on
    the four hip and shoulder joints as Python floats."""
    (hl, hr, sl, sr), (whl, whr, wsl, wsr) = p[_HEADING, :2].tolist(), w[_HEADING].tolist()
    wh = min(max(whl, 1e-3), max(whr, 1e-3))
    ws = min(max(wsl, 1e-3), max(wsr, 1e-3))
    lx = wh * (hl[0] - hr[0]) + ws * (sl[0] - sr[0])
    ly = wh * (hl[1] - hr[1]) + ws * (sl[1] - sr[1])
    return np.arctan2(-lx, ly)


@dataclass
class DatabaseArrays:
    """The arrays the methods need from a motion database (any object with ``positions``)."""

    positions: np.ndarray                 # (N, 20, 3) normalised, standard body
    flat: np.ndarray                      # (N, 60) float64
    orientations: Optional[np.ndarray]    # (N, 20, 4) or None
    twists: Optional[np.ndarray]          # (N, 19) or None
    body: Body
    # arrays the methods derive from the database (KNN matrices, PCA bases), computed by the first
    # method instance that needs them and shared, read-only, by the later ones (one per user)
    derived: Dict[str, object] = field(default_factory=dict, repr=False, compare=False)

    @property
    def size(self) -> int:
        return self.flat.shape[0]


def as_database_arrays(db, body: Optional[Body] = None) -> DatabaseArrays:
    """Adapt ``skeleton_core.database.MotionDatabase`` (or any object with ``positions``
    (N, 20, 3) and optional ``orientations`` / ``twists``) or a bare (N, 20, 3) array."""
    if isinstance(db, DatabaseArrays):
        return db
    pos = np.asarray(getattr(db, 'positions', db), dtype=float)
    if pos.ndim != 3 or pos.shape[1:] != (NUM_JOINTS, 3) or pos.shape[0] < 2:
        raise ValueError(f'motion database must hold (N >= 2, 20, 3) positions, got {pos.shape}')
    if not np.all(np.isfinite(pos)):
        raise ValueError('motion database holds non-finite positions')
    ori = getattr(db, 'orientations', None)
    ori = None if ori is None else np.asarray(ori, dtype=float)
    if ori is not None and ori.shape != (pos.shape[0], NUM_JOINTS, 4):
        ori = None
    tw = getattr(db, 'twists', None)
    tw = None if tw is None else np.asarray(tw, dtype=float)
    if body is None:
        body = getattr(db, 'body', None) or standard_body()
    return DatabaseArrays(positions=pos, flat=np.ascontiguousarray(pos.reshape(len(pos), -1)),
                          orientations=ori, twists=tw, body=body)


# Shum & Ho 2012 Eq. 3-4 with per-joint lengths (``lengths`` (20,), 0 for the root), batched
fast_retarget = retarget_by_joint


def bone_lengths(body: Body) -> np.ndarray:
    return body.bone_lengths_by_joint()


def rest_directions(body: Body) -> np.ndarray:
    o = body.rest_offsets
    n = np.linalg.norm(o, axis=1, keepdims=True)
    return np.where(n > 1e-12, o / np.maximum(n, 1e-12), 0.0)


def fast_normalize(positions: np.ndarray, weights: Optional[np.ndarray] = None):
    """geometry.normalize for one posture (20, 3), without the batch machinery (same result)."""
    p = np.asarray(positions, float)
    yaw = facing_yaw(p, weights)
    t = p[ROOT].copy()
    c, s = np.cos(yaw), np.sin(yaw)
    d = p - t
    out = np.empty_like(d)
    out[:, 0] = c * d[:, 0] + s * d[:, 1]
    out[:, 1] = -s * d[:, 0] + c * d[:, 1]
    out[:, 2] = d[:, 2]
    return out, NormalizeTransform(yaw=np.asarray(yaw), translation=t)


def fast_denormalize(normalized: np.ndarray, transform: NormalizeTransform) -> np.ndarray:
    """geometry.denormalize for one posture (20, 3)."""
    q = np.asarray(normalized, float)
    yaw = float(transform.yaw)
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.empty_like(q)
    out[:, 0] = c * q[:, 0] - s * q[:, 1]
    out[:, 1] = s * q[:, 0] + c * q[:, 1]
    out[:, 2] = q[:, 2]
    return out + transform.translation


@dataclass
class PreparedQuery:
    """A sensor posture brought into the database space."""

    query: np.ndarray                 # (20, 3) normalised, retargeted to the standard body
    transform: NormalizeTransform     # what normalisation removed (yaw, translation)
    scale: float                      # standard height / user height


class QueryPreparer:
    """Normalise (yaw + translation removed, reliability-weighted heading) and retarget a sensor
    posture to the database's standard body (Shum et al. 2013 Sec. V-B; Shum & Ho Eq. 3-4).

    A joint below an unreliable ancestor cannot be retargeted along the chain (its parent's
    direction is garbage), so it is scaled uniformly by standard/user height instead.
    """

    def __init__(self, body: Body, reliable_threshold: float = 0.5):
        self.body = body
        self.lengths = bone_lengths(body)
        self.rest_dirs = rest_directions(body)
        self.reliable_threshold = reliable_threshold

    def prepare(self, positions: np.ndarray, reliability: np.ndarray,
                user_height: float, yaw: Optional[float] = None) -> PreparedQuery:
        """``yaw``: the heading to remove (default: from the reliability-weighted hip and
        shoulder lines)."""
        w = np.asarray(reliability, float)
        p = np.asarray(positions, float)
        # fast_normalize + fast_retarget in a few matrix products (same results)
        if yaw is None:
            yaw = _weighted_yaw(p, w)
        t = p[ROOT].copy()
        c, s = np.cos(yaw), np.sin(yaw)
        norm = (p - t) @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        d = _PARENT_DIFF @ norm
        n = np.sqrt(np.einsum('jk,jk->j', d, d))
        unit = d / np.maximum(n, 1e-12)[:, None]
        # the root's row (no parent: d = 0) always takes its rest direction; another joint only
        # when it sits on its parent
        if (n.take(_NON_ROOT) <= 1e-9).any():
            zero = n <= 1e-9
            unit[zero] = self.rest_dirs[zero]
        else:
            unit[ROOT] = self.rest_dirs[ROOT]
        unit *= self.lengths[:, None]      # the root's length is 0: no offset
        ret = ANCESTORS @ unit
        tf = NormalizeTransform(yaw=np.asarray(yaw), translation=t)
        scale = self.body.height / max(user_height, 0.5)
        bad = w < self.reliable_threshold
        if bad.any():
            chain_bad = (_STRICT_ANCESTORS_F @ bad) > 0.0
            ret[chain_bad] = norm[chain_bad] * scale
        return PreparedQuery(query=ret, transform=tf, scale=scale)


def to_sensor_frame(normalized: np.ndarray, transform: NormalizeTransform,
                    user_bone_lengths: Optional[np.ndarray], rest_dirs: np.ndarray) -> np.ndarray:
    """Back to the sensor frame: optionally retarget to the user's bone lengths (20,), then
    restore yaw and translation (geometry.denormalize)."""
    p = normalized if user_bone_lengths is None else fast_retarget(normalized, user_bone_lengths,
                                                                    rest_dirs)
    return fast_denormalize(p, transform)


def yaw_quat_matrix(yaw: float) -> np.ndarray:
    """(4, 4) left multiplication by the quaternion of a rotation about +z (x, y, z, w order):
    ``quat_multiply(quat_from_yaw(yaw), q) == q @ M.T``."""
    s, c = math.sin(0.5 * yaw), math.cos(0.5 * yaw)
    return np.array([[c, -s, 0.0, 0.0], [s, c, 0.0, 0.0], [0.0, 0.0, c, s], [0.0, 0.0, -s, c]])


def orientations_to_sensor(quats: np.ndarray, yaw: float) -> np.ndarray:
    """Rotate normalised-frame orientations (..., 4) back by the removed yaw."""
    return np.asarray(quats, float) @ yaw_quat_matrix(float(yaw)).T


def user_bone_lengths(segment_lengths_19: np.ndarray) -> np.ndarray:
    """(19,) segment lengths (SEGMENTS order) -> (20,) by joint."""
    out = np.zeros(NUM_JOINTS)
    out[_SEG_C] = segment_lengths_19
    return out


def parent_relative_error(a: np.ndarray, b: np.ndarray) -> float:
    """Shum et al. 2013 Eq. 18: mean over frames and joints of the distance between parent-relative
    joint vectors of two posture sequences (..., 20, 3), metres (the root row is left out)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    ra = a[..., _SEG_C, :] - a[..., _SEG_P, :]
    rb = b[..., _SEG_C, :] - b[..., _SEG_P, :]
    return float(np.mean(np.linalg.norm(ra - rb, axis=-1)))
