"""Kinematic composition (Ishigaki et al. 2009, Sec. 6.2) and motion integration (Sec. 7).

Poses here are joint positions relative to the COM in the body's yaw-removed frame (metres).

* :class:`PoseComposer` -- the low-dimensional optimisation of Eq. 8 over the example's pose PCA
  (Eq. 7: ``q = B s + q_avg``): ``G_P`` (Eq. 9) pulls the user's unconstrained end-effectors to
  their relative positions r^_j, ``G_E`` (Eq. 10) pulls towards the representative pose q_rep
  (the distance-weighted average of the ``k`` example frames whose feature vectors w are nearest
  the user's: the phase found by matching) scaled by 1/lambda_i, ``G_S`` (Eq. 11) towards the
  previous pose. All three are quadratic in s: one m x m linear solve.
* :func:`integrate_rule` -- the integration rule: the branches of the end-effectors that are
  constrained on the user and free on the character take the composed pose, every other joint the
  user's.
* :func:`integrate_motion` -- Eq. 12 in closed steps: translate the pose so its COM is the
  simulated x, two-bone IK so each engaged effector sits on its contact point, then push joints
  out of the features (the ``p_pen <= p`` inequalities) by projection.
* :func:`penetration` -- the deepest penetration (m) of the character's capsules into the
  features (engaged effectors' hand/foot segments excluded from their own feature).
"""
from __future__ import annotations

import math
import time
from typing import Dict, List, Optional, Sequence

import numpy as np
from skeleton_core.model import (ANKLE_LEFT, ANKLE_RIGHT, ELBOW_LEFT, ELBOW_RIGHT, FOOT_LEFT,
                                 FOOT_RIGHT, HAND_LEFT, HAND_RIGHT, HIP_LEFT,
                                 HIP_RIGHT, JOINT_NAMES, KNEE_LEFT, KNEE_RIGHT, NUM_JOINTS,
                                 SEGMENT_CHILDREN, SEGMENT_PARENTS, SEGMENT_RADIUS_FRACTION,
                                 SHOULDER_LEFT, SHOULDER_RIGHT, WRIST_LEFT,
                                 WRIST_RIGHT, subtree)

from .intention import ExampleModel, center_of_mass, pca_columns, yaw_rotation
from skeleton_core import jit as _jit
from skeleton_core.geometry import facing_yaw

# chains for the IK: effector -> (root, mid, end) joints; the effector rides rigidly on ``end``
CHAINS = {'HandLeft': (SHOULDER_LEFT, ELBOW_LEFT, WRIST_LEFT, HAND_LEFT),
          'HandRight': (SHOULDER_RIGHT, ELBOW_RIGHT, WRIST_RIGHT, HAND_RIGHT),
          'FootLeft': (HIP_LEFT, KNEE_LEFT, ANKLE_LEFT, FOOT_LEFT),
          'FootRight': (HIP_RIGHT, KNEE_RIGHT, ANKLE_RIGHT, FOOT_RIGHT)}
# the branch of each end-effector (joints below its limb's root)
BRANCH = {'HandLeft': subtree(ELBOW_LEFT), 'HandRight': subtree(ELBOW_RIGHT),
          'FootLeft': subtree(KNEE_LEFT), 'FootRight': subtree(KNEE_RIGHT)}
_SEG_R = np.array([SEGMENT_RADIUS_FRACTION[JOINT_NAMES[c]] for c in SEGMENT_CHILDREN])
# the segments that move with the body as a whole (trunk, head, shoulders, pelvis, legs; not
# the arms from the shoulder joint on)
_BODY_SEGS = [(a, b) for a, b in zip(SEGMENT_PARENTS, SEGMENT_CHILDREN)
              if b not in subtree(ELBOW_LEFT) + subtree(ELBOW_RIGHT)]
_BODY_PAR = np.array([i for i, _ in _BODY_SEGS])
_BODY_CHI = np.array([j for _, j in _BODY_SEGS])
_BODY_R = np.array([_SEG_R[SEGMENT_CHILDREN.index(j)] for _, j in _BODY_SEGS])
# the limbs' segments from the shoulder and hip joints on (parent, child)
_LIMB_SEGS = [(a, b) for a, b in zip(SEGMENT_PARENTS, SEGMENT_CHILDREN)
              if b in subtree(ELBOW_LEFT) + subtree(ELBOW_RIGHT) + subtree(KNEE_LEFT)
              + subtree(KNEE_RIGHT)]
# radius (fraction of height) of the thickest segment capsule meeting at each joint
_JOINT_R = np.zeros(NUM_JOINTS)
for _k, (_a, _b) in enumerate(zip(SEGMENT_PARENTS, SEGMENT_CHILDREN)):
    _JOINT_R[_a] = max(_JOINT_R[_a], _SEG_R[_k])
    _JOINT_R[_b] = max(_JOINT_R[_b], _SEG_R[_k])


class PoseComposer:
    """Eq. 7-11 for one example motion (scaled to the user's height)."""

    def __init__(self, model: ExampleModel, components: int = 6, k: int = 4,
                 w_p: float = 1.0, w_e: float = 0.05, w_s: float = 0.2):
        self.model = model
        p = model.positions
        rel = (p - center_of_mass(p)[:, None, :])
        rel = np.einsum('tij,tkj->tki', yaw_rotation(facing_yaw(p)), rel) / model.height
        self.poses = rel.reshape(len(p), -1)            # (N, 60), height units
        self.q_avg, self.B, self.lam = pca_columns(self.poses, components)
        self.lam = np.maximum(self.lam, 1e-6)
        self.k = int(k)
        self.w_p, self.w_e, self.w_s = float(w_p), float(w_e), float(w_s)
        self.prev: Optional[np.ndarray] = None

    def representative(self, w: np.ndarray) -> np.ndarray:
        """q_rep: distance-weighted mean of the k example poses nearest in feature space."""
        d = np.sqrt(np.sum((self.model.w - w) ** 2, axis=1))
        idx = np.argsort(d)[:self.k]
        wt = 1.0 / (d[idx] + 1e-3)
        return (wt[:, None] * self.poses[idx]).sum(0) / wt.sum()

    def phase(self, w: np.ndarray) -> float:
        """The matched example frame as a fraction of the example's length."""
        return float(np.argmin(np.sum((self.model.w - w) ** 2, axis=1))) / len(self.model.w)

    def compose(self, rel_effectors: Dict[int, np.ndarray], w: np.ndarray,
                height: float) -> np.ndarray:
        """The optimal pose (20, 3) relative to the COM (yaw-removed, metres) for the user's
        unconstrained effectors' relative positions ``rel_effectors`` {joint: (3,) metres} and
        feature vector ``w``."""
        B, qa, m = self.B, self.q_avg, self.B.shape[1]
        q_rep = self.representative(w)
        H = self.w_e * np.diag(1.0 / self.lam) + self.w_s * np.eye(m)
        rhs = self.w_e * (B.T @ (q_rep - qa)) / self.lam
        prev = self.prev if self.prev is not None else q_rep
        rhs += self.w_s * (B.T @ (prev - qa))
        for j, r in rel_effectors.items():
            rows = slice(3 * j, 3 * j + 3)
            Bj = B[rows]
            H += self.w_p * Bj.T @ Bj
            rhs += self.w_p * Bj.T @ (np.asarray(r, float) / height - qa[rows])
        s = np.linalg.solve(H, rhs)
        q = B @ s + qa
        self.prev = q
        return q.reshape(NUM_JOINTS, 3) * height

    def reset(self) -> None:
        self.prev = None


def integrate_rule(user: np.ndarray, composed: np.ndarray, replace: Sequence[str]) -> np.ndarray:
    """The user's pose with the branches of the effectors in ``replace`` (user-constrained,
    character-free) taken from ``composed``, attached at the user's limb roots."""
    out = np.array(user, float)
    for e in replace:
        root = CHAINS[e][0]
        for j in BRANCH[e]:
            out[j] = user[root] + (composed[j] - composed[root])
    return out


def _two_bone(a, b, c, target):
    """New (mid, end) of the chain a-b-c reaching ``target`` (as close as the bones allow),
    keeping the bend plane of the current pose."""
    l1, l2 = np.linalg.norm(b - a), np.linalg.norm(c - b)
    d = target - a
    dist = float(np.linalg.norm(d))
    dist_c = min(max(dist, abs(l1 - l2) + 1e-6), l1 + l2 - 1e-6)
    u = d / max(dist, 1e-9)
    pole = (b - a) - np.dot(b - a, u) * u
    if np.linalg.norm(pole) < 1e-6:
        pole = np.cross(u, [0.0, 1.0, 0.0])
        if np.linalg.norm(pole) < 1e-6:
            pole = np.cross(u, [1.0, 0.0, 0.0])
    pole /= np.linalg.norm(pole)
    cos_a = (l1 * l1 + dist_c * dist_c - l2 * l2) / (2 * l1 * dist_c)
    ang = math.acos(min(max(cos_a, -1.0), 1.0))
    mid = a + l1 * (math.cos(ang) * u + math.sin(ang) * pole)
    end = a + dist_c * u
    return mid, end


# body heights: the obstacles within this distance of the COM are all the body can touch in a frame
# (a raised hand is ~0.75 heights from the COM)
NEAR = 1.5
# the samples of a segment tested by Obstacles.clear_segments and trunk_clearance
_T9 = np.linspace(0.0, 1.0, 9)
_T5 = np.linspace(0.0, 1.0, 5)   # the penetration metric's samples
# the samples of an arm's two segments tested by :func:`_swivel_clear` (5 per segment)
_SWIVEL_T = np.linspace(0.0, 1.0, 5)[:, None]
# the swivel angles tried, nearest the current one first (a stable sort of -180..160 deg by |angle|)
_SWIVEL_ANGLES = np.array(sorted(np.radians(np.arange(-180, 180, 20)), key=abs))


def _swivel_clear(p: np.ndarray, chain, obstacles: 'Obstacles', height: float) -> None:
    """Turn an arm's elbow about the shoulder-wrist line (the hand stays where it is) to the
    swivel angle nearest the current one whose upper arm and forearm clear the obstacles
    (every angle's depth in one array operation)."""
    a, b, c, _ = chain
    rc = obstacles._caps()[2]
    if not len(rc):
        return
    ax = p[c] - p[a]
    n = math.sqrt(float(ax @ ax))
    if n < 1e-6:
        return
    ax = ax / n
    rad = np.repeat([_SEG_R[SEGMENT_CHILDREN.index(b)] * height,
                     _SEG_R[SEGMENT_CHILDREN.index(c)] * height], 5)

    def depth(elbows):          # (E, 3) candidate elbows -> (E,) deepest penetration of each
        pts = np.concatenate([p[a] + _SWIVEL_T[None] * (elbows[:, None] - p[a]),
                              elbows[:, None] + _SWIVEL_T[None] * (p[c] - elbows[:, None])],
                             axis=1)                                     # (E, 10, 3)
        d, _ = obstacles._d(pts.reshape(-1, 3))
        return (rad[None, :, None] + rc[None, None] - d.reshape(len(elbows), 10, -1)).reshape(
            len(elbows), -1).max(axis=1)
    if depth(p[b][None])[0] <= 0:
        return
    rel = p[b] - p[a]
    cs, sn = np.cos(_SWIVEL_ANGLES)[:, None], np.sin(_SWIVEL_ANGLES)[:, None]
    # Rodrigues' rotation of rel about ax by every angle
    elbows = p[a] + rel * cs + np.cross(ax, rel) * sn + ax * float(ax @ rel) * (1.0 - cs)
    dd = depth(elbows)
    clear = np.nonzero(dd <= 0)[0]
    p[b] = elbows[clear[0] if len(clear) else int(np.argmin(dd))]


def integrate_motion(pose: np.ndarray, com_target: np.ndarray,
                     contacts: Dict[str, np.ndarray], obstacles: Optional['Obstacles'] = None,
                     engaged_feature: Optional[Dict[str, str]] = None,
                     height: float = 1.75) -> np.ndarray:
    """Eq. 12: ``pose`` (world, any placement) moved so its COM is ``com_target``, each engaged
    effector put on its contact point {effector: (3,)} by two-bone IK (the whole body shifts by
    the mean residual when a contact is out of reach), joints pushed out of ``obstacles``."""
    p = np.array(pose, float)
    p += np.asarray(com_target, float) - center_of_mass(p)
    if obstacles is not None:     # only what the body can reach this frame
        obstacles = obstacles.near(com_target, NEAR * height)
    if contacts:
        shift = np.zeros(3)
        for e, tgt in contacts.items():
            a, b, c, eff = CHAINS[e]
            off = p[eff] - p[c]
            reach = np.linalg.norm(p[b] - p[a]) + np.linalg.norm(p[c] - p[b])
            goal = np.asarray(tgt, float) - off
            d = goal - p[a]
            dist = np.linalg.norm(d)
            if dist > reach:
                shift += d * (1.0 - reach / dist)
        p += shift / len(contacts)
        for e, tgt in contacts.items():
            a, b, c, eff = CHAINS[e]
            off = p[eff] - p[c]
            mid, end = _two_bone(p[a], p[b], p[c], np.asarray(tgt, float) - off)
            p[b], p[c], p[eff] = mid, end, end + off
    if obstacles is not None:
        # the trunk and head clear the features by moving the whole body (the held limbs bend
        # to keep their contacts), then the IK again
        # away from the features: backwards (a character holds a rope or a bar in front of it)
        from skeleton_core.geometry import facing_yaw
        yaw = float(facing_yaw(p))
        direction = np.array([-math.cos(yaw), -math.sin(yaw), 0.0])
        fixed = False
        for _ in range(15):
            move, direction = obstacles.trunk_clearance(p, height, direction, fixed)
            fixed = True
            if not np.any(move):
                break
            p += move
            for e, tgt in (contacts or {}).items():
                a, b, c, eff = CHAINS[e]
                off = p[eff] - p[c]
                mid, end = _two_bone(p[a], p[b], p[c], np.asarray(tgt, float) - off)
                p[b], p[c], p[eff] = mid, end, end + off
    if obstacles is not None:
        for e in ('HandLeft', 'HandRight'):
            _swivel_clear(p, CHAINS[e], obstacles, height)
        skip = set()
        for e in (contacts or {}):
            skip |= set(CHAINS[e][2:])
        obstacles.push_out(p, skip, height)
        obstacles.clear_segments(p, skip, height)
    return p


class Obstacles:
    """The features' solid geometry for the penetration constraints and the metric: capsules
    (bars, rope segments), boxes (trampoline top) and the floor plane, refreshed from the dynamic
    model each step (the rope and the trampoline move). Call :meth:`freeze` after filling."""

    def __init__(self):
        self.capsules: List[tuple] = []   # (a (3,), b (3,), radius, feature)
        self.boxes: List[tuple] = []      # (center (3,), half (3,), feature)
        self.floor: Optional[str] = None
        self._arr = None

    def freeze(self) -> 'Obstacles':
        c = self.capsules
        self._arr = (np.array([x[0] for x in c]).reshape(-1, 3),
                     np.array([x[1] for x in c]).reshape(-1, 3),
                     np.array([x[2] for x in c], float), [x[3] for x in c])
        ab = self._arr[1] - self._arr[0]
        self._axes = (ab, np.maximum((ab * ab).sum(axis=1), 1e-12))   # for _d
        return self

    def near(self, point: np.ndarray, radius: float) -> 'Obstacles':
        """The obstacles whose capsules pass within ``radius`` of ``point`` (boxes and the floor
        kept): the per-frame constraints and the metric then test a few capsules, not all."""
        a, b, rc, feats = self._caps()
        out = Obstacles()
        out.boxes, out.floor = self.boxes, self.floor
        if len(rc):
            d, _ = self._d(np.asarray(point, float)[None])
            keep = np.nonzero(d[0] - rc < radius)[0]
            out.capsules = [self.capsules[k] for k in keep]
        return out.freeze()

    def _caps(self):
        if self._arr is None or len(self._arr[2]) != len(self.capsules):
            self.freeze()
        return self._arr

    def _d(self, pts):
        """Distances (P, K) and closest points (P, K, 3) of points (P, 3) to this set's capsule
        axes, with the axes' vectors and squared lengths computed once per set (:meth:`freeze`);
        the compiled kernel (:func:`_capsule_d_jit`) or its numpy twin."""
        ab, den = self._axes
        return _capsule_d(np.ascontiguousarray(pts, dtype=float), self._caps()[0], ab, den)

    def trunk_clearance(self, p: np.ndarray, height: float,
                        direction: Optional[np.ndarray] = None, fixed: bool = True):
        """(translation (3,), direction) that moves the body's capsules (all but the arms) out of the
        capsule obstacles (bars, rope) horizontally: the direction away from the deepest
        obstacle, seen from the trunk's centre; with ``fixed=False`` the given ``direction`` is
        only an axis, turned towards the side of the obstacle the body is on (then kept: a rope
        across the trunk would otherwise push it back and forth); the length of the deepest
        penetration."""
        a, b, rc, _ = self._caps()
        if not len(rc):
            return np.zeros(3), direction
        ts = _T9   # a superset of the metric's 5 samples
        pts = (p[_BODY_PAR][:, None, :]
               + ts[None, :, None] * (p[_BODY_CHI] - p[_BODY_PAR])[:, None, :]).reshape(-1, 3)
        rad = np.repeat(_BODY_R * height, len(ts))
        d, cp = self._d(pts)
        depth = rad[:, None] + rc[None] - d
        i, k = np.unravel_index(np.argmax(depth), depth.shape)
        if depth[i, k] <= 0:
            return np.zeros(3), direction
        if direction is None or fixed is False:
            centre = pts.mean(axis=0)
            ab = b[k] - a[k]
            t = np.clip((centre - a[k]) @ ab / max(ab @ ab, 1e-12), 0.0, 1.0)
            n = centre - (a[k] + t * ab)
            n[2] = 0.0          # horizontally: the body hangs where the contacts hold it
            if direction is not None:     # the preferred axis, towards the side the body is on
                direction = direction * (1.0 if n @ direction >= 0 else -1.0)
            else:
                nn = np.linalg.norm(n)
                direction = n / nn if nn > 1e-9 else np.array([-1.0, 0.0, 0.0])
        return direction * (depth[i, k] + 1e-3), direction

    def push_out(self, p: np.ndarray, skip, height: float) -> None:
        """Project joints (not in ``skip``) out of the obstacles, in place."""
        keep = np.array([j not in skip for j in range(NUM_JOINTS)])
        r_joint = _JOINT_R * height
        if self.floor is not None:
            low = keep & (p[:, 2] < r_joint)
            p[low, 2] = r_joint[low]
        for c, h, _ in self.boxes:
            q = np.abs(p - c) - h - r_joint[:, None]
            inside = keep & np.all(q < 0, axis=1)
            if np.argmin(h) == 2:        # a flat box (the trampoline): out through the top
                p[inside, 2] = c[2] + h[2] + r_joint[inside]
                continue
            for j in np.nonzero(inside)[0]:   # a slab (a wall): out through its nearest face
                ax = int(np.argmax(q[j]))
                sgn = 1.0 if p[j, ax] >= c[ax] else -1.0
                p[j, ax] = c[ax] + sgn * (h[ax] + r_joint[j])
        a, b, rc, _ = self._caps()
        if len(rc):
            d, cp = self._d(p)
            viol = (d < rc[None] + r_joint[:, None]) & keep[:, None]
            for j, k in zip(*np.nonzero(viol)):
                n = p[j] - cp[j, k]
                nn = np.linalg.norm(n)
                p[j] = cp[j, k] + (n / nn if nn > 1e-9 else np.array([0.0, 0.0, -1.0])) * (
                    rc[k] + r_joint[j])

    def clear_segments(self, p: np.ndarray, skip, height: float, iters: int = 4) -> None:
        """Move the limbs' segment capsules (not only their joints) out of the capsule obstacles,
        in place: a forearm, a free hand or a thigh crossing the rope between two joints that are
        both outside it. Per segment whose child joint is free (not in ``skip``), its deepest sample
        is moved out along the normal from the obstacle's axis, by moving the child joint and its
        free descendants (a sample at fraction t of the segment needs the child moved depth / t).
        """
        a, b, rc, _ = self._caps()
        if not len(rc):
            return
        ts = _T9
        segs = [(i, j) for i, j in _LIMB_SEGS if j not in skip]
        if not segs:
            return
        par, chi = [i for i, _ in segs], [j for _, j in segs]
        rad_all = np.repeat(_SEG_R[[SEGMENT_CHILDREN.index(j) for j in chi]] * height, len(ts))
        for _ in range(iters):
            # every free segment's samples at once: nothing inside any obstacle (the usual
            # frame), nothing to move -- the loop below would move nothing either
            pts = (p[par][:, None, :] + ts[None, :, None] * (p[chi] - p[par])[:, None, :])
            d, _ = self._d(pts.reshape(-1, 3))
            if float(np.max(rad_all[:, None] + rc[None] - d)) <= 0:
                return
            moved = False
            for i, j in _LIMB_SEGS:
                if j in skip:
                    continue
                pts = p[i] + ts[:, None] * (p[j] - p[i])
                rad = _SEG_R[SEGMENT_CHILDREN.index(j)] * height
                d, cp = self._d(pts)
                depth = rad + rc[None] - d
                q, k = np.unravel_index(np.argmax(depth), depth.shape)
                if depth[q, k] <= 0 or ts[q] < 1e-6:
                    continue
                n = pts[q] - cp[q, k]
                nn = np.linalg.norm(n)
                if nn < 1e-9:          # on the axis: sideways, horizontally
                    ab = b[k] - a[k]
                    n = np.cross(ab, [0.0, 0.0, 1.0])
                    nn = np.linalg.norm(n)
                    if nn < 1e-9:
                        n, nn = np.array([1.0, 0.0, 0.0]), 1.0
                step = n / nn * (depth[q, k] + 1e-3) / max(ts[q], 0.25)
                for jj in subtree(j):
                    if jj not in skip:
                        p[jj] += step
                moved = True
            if not moved:
                return

    def penetration(self, p: np.ndarray, height: float,
                    engaged: Optional[Dict[str, str]] = None) -> float:
        """Deepest penetration (m, >= 0) of the character's segment capsules (radii of the
        standard body scaled to ``height``) into the obstacles; the engaged effectors' last two
        segments are not tested against the feature they hold (a hand grips its bar)."""
        engaged = engaged or {}
        ts = _T5
        pa, ch = list(SEGMENT_PARENTS), list(SEGMENT_CHILDREN)
        pts = (p[pa][:, None, :] + ts[None, :, None] * (p[ch] - p[pa])[:, None, :]).reshape(-1, 3)
        rad = np.repeat(_SEG_R * height, len(ts))
        seg_child = np.repeat(np.array(ch), len(ts))
        excl = {}
        for e, feat in engaged.items():
            for j in CHAINS[e][2:]:
                excl.setdefault(feat, set()).add(j)

        def allowed(feat):
            bad = excl.get(feat)
            if not bad:
                return np.ones(len(pts), bool)
            return ~np.isin(seg_child, list(bad))
        worst = 0.0
        if self.floor is not None:
            worst = max(worst, float(np.max(np.where(allowed(self.floor), rad - pts[:, 2], 0))))
        for c, h, f in self.boxes:
            q = np.abs(pts - c) - h
            if np.argmin(h) != 2:          # a slab: depth through the nearest face
                qr = q - rad[:, None]
                inside = np.all(qr < 0, axis=1) & allowed(f)
                if np.any(inside):
                    worst = max(worst, float(np.max(-np.max(qr[inside], axis=1))))
                continue
            inside = np.all(q[:, :2] < 0, axis=1) & (pts[:, 2] > c[2] - h[2]) & allowed(f)
            if np.any(inside):
                worst = max(worst, float(np.max((c[2] + h[2] + rad - pts[:, 2])[inside])))
        a, b, rc, feats = self._caps()
        if len(rc):
            d, _ = self._d(pts)
            depth = rad[:, None] + rc[None] - d
            for f in set(feats):
                if f in excl:
                    cols = np.array([x == f for x in feats])
                    depth[np.ix_(~allowed(f), cols)] = 0.0
            worst = max(worst, float(depth.max()))
        return max(worst, 0.0)


def _capsule_d_np(pts, a, ab, den):
    """Distances (P, K) and closest points (P, K, 3) of points ``pts`` (P, 3) to the segments
    a + t ab, t in [0, 1] (K, 3); ``den`` (K,) = |ab|^2 (floored): the numpy twin."""
    diff = pts[:, None, :] - a[None]
    t = (diff * ab).sum(axis=2) / den
    np.clip(t, 0.0, 1.0, out=t)
    cp = a[None] + t[..., None] * ab[None]
    r = pts[:, None, :] - cp
    return np.sqrt((r * r).sum(axis=2)), cp


@_jit.njit
def _capsule_d_jit(pts, a, ab, den):  # pragma: no cover - numba
    """:func:`_capsule_d_np` compiled: the same operations in the same order per pair (the
    constraints call it ~8 times a frame on a few points and capsules, where numpy's per-call
    overhead was most of its time: round 6, docs/research/2026-11-28-performance-control-development.md)."""
    n, k = pts.shape[0], a.shape[0]
    d = np.empty((n, k))
    cp = np.empty((n, k, 3))
    for i in range(n):
        for j in range(k):
            t = ((pts[i, 0] - a[j, 0]) * ab[j, 0] + (pts[i, 1] - a[j, 1]) * ab[j, 1]
                 + (pts[i, 2] - a[j, 2]) * ab[j, 2]) / den[j]
            if t < 0.0:
                t = 0.0
            elif t > 1.0:
                t = 1.0
            r2 = 0.0
            for c in range(3):
                q = a[j, c] + t * ab[j, c]
                cp[i, j, c] = q
                r = pts[i, c] - q
                r2 += r * r
            d[i, j] = math.sqrt(r2)
    return d, cp


# numba when installed and not switched off (KINECT_NUMBA=0), the numpy twin otherwise
_capsule_d = _jit.pick(_capsule_d_jit, _capsule_d_np)
_warm = [False]


def warm_up() -> float:
    """Compile (or load from numba's cache) the capsule kernel now, with the argument types of
    the real calls, rather than on a user's first control step; once per process. Returns the
    time taken (s; 0 when numba is off or already done)."""
    if _warm[0] or _capsule_d is not _capsule_d_jit:
        return 0.0
    _warm[0] = True
    t0 = time.perf_counter()
    a = np.zeros((1, 3))
    _capsule_d_jit(np.zeros((2, 3)), a, np.ones((1, 3)), np.ones(1))
    return time.perf_counter() - t0


__all__ = ['warm_up', 'PoseComposer', 'integrate_rule', 'integrate_motion', 'Obstacles', 'CHAINS',
           'BRANCH']
