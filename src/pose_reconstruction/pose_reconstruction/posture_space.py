"""Shared helpers of the reconstruction methods: database arrays, fast single-posture
retargeting, query preparation (normalise + retarget, Shum et al. 2013 Sec. V-B) and the way back
to the sensor frame.

Everything works on one posture at a time with vectorised numpy (no Python loop over all the
joints), so that a query costs tens of microseconds; at that size numpy's per-call overhead is
most of the cost, hence the few-call forms below (combined matrices, cached joint sets, np.dot).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Dict, List, NamedTuple, Optional

import numpy as np

from skeleton_core.geometry import NormalizeTransform, facing_yaw, retarget_by_joint, yaw_matrix
from skeleton_core.model import (HEADING_JOINTS, NUM_JOINTS, PARENTS, PATH_TO_ROOT, ROOT,
                                 SEGMENT_CHILD_INDEX, SEGMENT_PARENT_INDEX, Body, standard_body)
from skeleton_core.params import param

# each joint's parent (the root's own index for the root)
PARENT_ROWS = np.array([max(p, 0) for p in PARENTS])

# ANCESTORS[j, k] = 1 when k is j or one of its ancestors, excluding the root (the model's tree)
ANCESTORS = PATH_TO_ROOT
# STRICT_ANCESTORS[j, k] = 1 when k is a proper ancestor of j (root included)
STRICT_ANCESTORS = np.zeros((NUM_JOINTS, NUM_JOINTS), bool)
for _j in range(NUM_JOINTS):
    _k = PARENTS[_j]
    while _k >= 0:
        STRICT_ANCESTORS[_j, _k] = True
        _k = PARENTS[_k]
# (20, 20): positions -> offsets from the parent (the root's row 0)
_PARENT_DIFF = np.eye(NUM_JOINTS)
_PARENT_DIFF[np.arange(NUM_JOINTS), PARENT_ROWS] -= 1.0
_PARENT_DIFF[ROOT] = 0.0
_HEADING = list(HEADING_JOINTS)
_NON_ROOT = np.array([j for j in range(NUM_JOINTS) if j != ROOT])
# flat indices of the x and y of the four heading joints in a (20, 3) posture: one ``take`` reads
# them (fancy row + column indexing costs about three times as much)
_HEADING_XY = np.array([[3 * j, 3 * j + 1] for j in _HEADING]).ravel()
# (19, 20): positions -> the bones (offset of each non-root joint from its parent), and
# (20, 19): bones -> positions relative to the root (ANCESTORS without the root's column, which
# is zero anyway)
_BONE_DIFF = _PARENT_DIFF[_NON_ROOT]
_BONE_ANCESTORS = np.ascontiguousarray(ANCESTORS[:, _NON_ROOT])
# _DESCENDANT_BITS[k]: bit j set when k is a proper ancestor of j (the joints whose chain to the
# root passes through k)
_DESCENDANT_BITS = [sum(1 << j for j in range(NUM_JOINTS) if STRICT_ANCESTORS[j, k])
                    for k in range(NUM_JOINTS)]


class JointSet(NamedTuple):
    """A set of joints (the unreliable ones of a frame, say) in the forms the per-frame code
    indexes with. Fancy indexing with a Python list converts the list on every call and a
    boolean mask costs a comparison per frame: ~1-3 us each, the price of a whole (20, 3)
    product. The few sets a stream meets are built once (:func:`joint_set`)."""

    rows: List[int]          # the joints, ascending (a tree order: parents first)
    index: np.ndarray        # the same as an index array (for ``take``)
    mask: np.ndarray         # (20,) bool
    column: np.ndarray       # (20, 1) bool: ``np.copyto(a, b, where=column)`` sets the rows
    weights: List[float]     # 0.0 for the joints of the set, 1.0 for the others
    below: int               # bits of the joints with a proper ancestor in the set


@functools.lru_cache(maxsize=4096)
def joint_set(bits: int) -> JointSet:
    """The :class:`JointSet` of the joints whose bits (``1 << joint``) are set in ``bits``
    (arrays read-only, shared)."""
    rows = [j for j in range(NUM_JOINTS) if bits >> j & 1]
    mask = np.zeros(NUM_JOINTS, bool)
    mask[rows] = True
    index = np.array(rows, dtype=np.intp)
    column = mask[:, None].copy()
    for a in (mask, index, column):
        a.setflags(write=False)
    below = 0
    for j in rows:
        below |= _DESCENDANT_BITS[j]
    return JointSet(rows=rows, index=index, mask=mask, column=column,
                    weights=[0.0 if bits >> j & 1 else 1.0 for j in range(NUM_JOINTS)],
                    below=below)


def heading_yaw(p: np.ndarray, w) -> np.float64:
    """``facing_yaw(p, np.maximum(w, 1e-3))`` for one posture (20, 3) and its weights ``w`` (any
    sequence of 20 numbers): the same arithmetic on the four hip and shoulder joints as Python
    floats. ``np.arctan2`` (not ``math.atan2``) so that the result stays equal to facing_yaw's
    wherever numpy's arctan2 is not the C library's (SIMD builds)."""
    hlx, hly, hrx, hry, slx, sly, srx, sry = p.take(_HEADING_XY).tolist()
    whl, whr, wsl, wsr = w[_HEADING[0]], w[_HEADING[1]], w[_HEADING[2]], w[_HEADING[3]]
    wh = min(max(whl, 1e-3), max(whr, 1e-3))
    ws = min(max(wsl, 1e-3), max(wsr, 1e-3))
    lx = wh * (hlx - hrx) + ws * (slx - srx)
    ly = wh * (hly - hry) + ws * (sly - sry)
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
    """Adapt ``skeleton_data.database.MotionDatabase`` (or any object with ``positions``
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


@dataclass
class QueryConfig:
    """What counts as reliable; shared by every reconstruction method (the completion's and the
    optimizer's configurations extend it)."""

    reliable_threshold: float = param(
        0.5, 'a joint at or above this reliability counts as reliable (method A: the joints '
        'below it are substituted from the database)', range=(0.0, 1.0))


class QueryPreparer:
    """Normalise (yaw + translation removed, reliability-weighted heading) and retarget a sensor
    posture to the database's standard body (Shum et al. 2013 Sec. V-B; Shum & Ho Eq. 3-4).

    A joint below an unreliable ancestor cannot be retargeted along the chain (its parent's
    direction is garbage), so it is scaled uniformly by standard/user height instead.
    """

    def __init__(self, body: Body, reliable_threshold: float = QueryConfig.reliable_threshold):
        self.body = body
        self.lengths = bone_lengths(body)
        self.rest_dirs = rest_directions(body)
        self.reliable_threshold = reliable_threshold
        self._bone_lengths = self.lengths[_NON_ROOT]

    def prepare(self, positions: np.ndarray, reliability: np.ndarray,
                user_height: float, yaw: Optional[float] = None) -> PreparedQuery:
        """``yaw``: the heading to remove (default: from the reliability-weighted hip and
        shoulder lines)."""
        w = np.asarray(reliability, float).tolist()
        p = np.asarray(positions, float)
        if yaw is None:
            yaw = heading_yaw(p, w)
        thr = self.reliable_threshold
        bad = 0
        for j, x in enumerate(w):
            if x < thr:  # a NaN reliability is not below
                bad |= 1 << j
        query, t, _, scale = self.prepare_rows(p, bad, user_height, yaw)
        return PreparedQuery(query=query, transform=NormalizeTransform(yaw=np.asarray(yaw),
                                                                       translation=t),
                             scale=scale)

    def prepare_rows(self, p: np.ndarray, bad: int, user_height: float, yaw: float):
        """:meth:`prepare`'s work for a float (20, 3) posture ``p`` whose heading ``yaw`` is
        known and whose unreliable joints are the bits ``bad`` (``1 << joint``, as
        :func:`joint_set`): ``(query, root translation, rotation, scale)``, the rotation ``R``
        being ``geometry.yaw_matrix(yaw)`` (``(x - t) @ R`` is the normalisation, ``x @ R.T``
        turns back). Method A's completion calls it directly: it needs the rotation as well, and
        knows its unreliable joints already."""
        rot = yaw_matrix(yaw)
        t = p.take(ROOT, 0)  # a copy
        scale = self.body.height / max(user_height, 0.5)
        # fast_normalize + fast_retarget in a few matrix products (the same results to rounding,
        # ~1e-16 m). A rotation keeps the bones' lengths and a translation does not change them,
        # so the bones are taken from the sensor posture, scaled to the standard lengths and
        # summed down the tree by one (20, 19) matrix, ANCESTORS with each bone's factor, and
        # turned only then: one (3, 3) product for the rotation, no subtraction of the root.
        # A joint below an unreliable joint is scaled uniformly instead (see the class doc):
        # its row of the matrix takes ``scale`` for every bone. np.dot, not @: the same BLAS
        # call for 2-D arrays with less dispatch (~0.4 us a call).
        bones = np.dot(_BONE_DIFF, p)
        n = np.sqrt(np.einsum('jk,jk->j', bones, bones))
        if n.min() > 1e-9:
            m = _BONE_ANCESTORS * (self._bone_lengths / n)
            below = joint_set(bad).below if bad else 0
            if below:
                np.multiply(_BONE_ANCESTORS, scale, out=m, where=joint_set(below).column)
            return np.dot(np.dot(m, bones), rot), t, rot, scale
        # a joint on its parent (or a NaN): the joint takes its rest direction, which is given
        # in the normalised frame, so normalise first (the straightforward way)
        norm = np.dot(p - t, rot)
        d = np.dot(_PARENT_DIFF, norm)
        n = np.sqrt(np.einsum('jk,jk->j', d, d))
        unit = d / np.maximum(n, 1e-12)[:, None]
        zero = n <= 1e-9   # the root's row (no parent: d = 0) always
        unit[zero] = self.rest_dirs[zero]
        unit *= self.lengths[:, None]      # the root's length is 0: no offset
        ret = np.dot(ANCESTORS, unit)
        if bad and joint_set(bad).below:
            np.copyto(ret, norm * scale, where=joint_set(joint_set(bad).below).column)
        return ret, t, rot, scale


def to_sensor_frame(normalized: np.ndarray, transform: NormalizeTransform,
                    user_bone_lengths: Optional[np.ndarray], rest_dirs: np.ndarray) -> np.ndarray:
    """Back to the sensor frame: optionally retarget to the user's bone lengths (20,), then
    restore yaw and translation (geometry.denormalize)."""
    p = normalized if user_bone_lengths is None else fast_retarget(normalized, user_bone_lengths,
                                                                    rest_dirs)
    return fast_denormalize(p, transform)


def yaw_quat_matrix(yaw: float) -> np.ndarray:
    """(4, 4) left multiplication by the quaternion of a rotation about +z (x, y, z, w order):
    ``quat_multiply(quat_from_yaw(yaw), q) == q @ M.T``. Built from a flat list (a nested one
    costs twice as much)."""
    s, c = math.sin(0.5 * yaw), math.cos(0.5 * yaw)
    return np.array([c, -s, 0.0, 0.0, s, c, 0.0, 0.0,
                     0.0, 0.0, c, s, 0.0, 0.0, -s, c]).reshape(4, 4)


def orientations_to_sensor(quats: np.ndarray, yaw: float) -> np.ndarray:
    """Rotate normalised-frame orientations (..., 4) back by the removed yaw."""
    return np.asarray(quats, float) @ yaw_quat_matrix(float(yaw)).T


def user_bone_lengths(segment_lengths_19: np.ndarray) -> np.ndarray:
    """(19,) segment lengths (SEGMENTS order) -> (20,) by joint."""
    out = np.zeros(NUM_JOINTS)
    out[SEGMENT_CHILD_INDEX] = segment_lengths_19
    return out


def parent_relative_error(a: np.ndarray, b: np.ndarray) -> float:
    """Shum et al. 2013 Eq. 18: mean over frames and joints of the distance between parent-relative
    joint vectors of two posture sequences (..., 20, 3), metres (the root row is left out)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    ra = a[..., SEGMENT_CHILD_INDEX, :] - a[..., SEGMENT_PARENT_INDEX, :]
    rb = b[..., SEGMENT_CHILD_INDEX, :] - b[..., SEGMENT_PARENT_INDEX, :]
    return float(np.mean(np.linalg.norm(ra - rb, axis=-1)))
