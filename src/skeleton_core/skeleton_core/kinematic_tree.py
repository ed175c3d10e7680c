"""The skeleton as a robot: a tree of links over the model's segments, its URDF, joint angles
solved from joint positions, and forward kinematics (ROS-free, vectorised over bodies).

One link per segment of :mod:`skeleton_core.model` (19), its origin at the segment's parent joint
and its axes aligned with the body's frame in the rest (T-) posture, so a link's rotation *is* the
segment's rotation from the rest posture (the physics character's convention, ``mjcf_body``). A
link hangs from the link of the segment that ends at its parent joint (the root joint's segments
hang from the root link). Each link is moved by

* a *ball* joint: three revolute joints, yaw about z, pitch about the new y, roll about the new x
  (``R = Rz(yaw) Ry(pitch) Rx(roll)``), with two massless links between them, or
* a *hinge*: one revolute joint about a fixed axis (elbows and knees of a human body).

A leaf joint (head, hands, feet) gets a fixed frame at the segment's end. The joint angles of a
posture given only by joint positions (:meth:`Tree.solve`) are the rotation that takes each segment
from its rest direction to its observed direction; a segment's twist about itself, which positions
do not show, is taken from a reference line (the shoulder line for the thorax, the plane of the
limb for the segment above a hinge) or else is the least rotation. Forward kinematics of the
angles with the segment lengths of the URDF gives the positions back exactly when the lengths are
those of the posture (:func:`forward_kinematics_urdf` reads any URDF of revolute and fixed joints).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .model import (CHILDREN, JOINT_NAMES, NUM_JOINTS, PARENTS, ROOT, SEGMENT_OF_JOINT,
                    SEGMENTS, standard_body)

BALL, HINGE = 'ball', 'hinge'
EPS = 1e-9
_AXES = np.eye(3)


# ------------------------------------------------------------------ rotations (vectorised)
def rot_axis(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) about a unit ``axis`` (3,) by ``angle`` (...) (Rodrigues)."""
    a = np.asarray(axis, float)
    t = np.asarray(angle, float)[..., None, None]
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + np.sin(t) * k + (1.0 - np.cos(t)) * (k @ k)


def euler_zyx(r: np.ndarray) -> np.ndarray:
    """(yaw, pitch, roll) (..., 3) of rotations (..., 3, 3) = Rz(yaw) Ry(pitch) Rx(roll)."""
    yaw = np.arctan2(r[..., 1, 0], r[..., 0, 0])
    pitch = np.arcsin(np.clip(-r[..., 2, 0], -1.0, 1.0))
    roll = np.arctan2(r[..., 2, 1], r[..., 2, 2])
    return np.stack([yaw, pitch, roll], axis=-1)


def from_euler_zyx(a: np.ndarray) -> np.ndarray:
    """Rz(a[..., 0]) Ry(a[..., 1]) Rx(a[..., 2]) (..., 3, 3)."""
    a = np.asarray(a, float)
    return rot_axis(_AXES[2], a[..., 0]) @ rot_axis(_AXES[1], a[..., 1]) @ rot_axis(_AXES[0], a[..., 2])


def _rot_axes(axes: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotations (U, n, 3, 3) about unit ``axes`` (n, 3) by ``angle`` (U, n) (Rodrigues)."""
    k = np.zeros(axes.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -axes[..., 2], axes[..., 1], -axes[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = axes[..., 2], -axes[..., 1], axes[..., 0]
    t = np.asarray(angle, float)[..., None, None]
    return np.eye(3) + np.sin(t) * k + (1.0 - np.cos(t)) * (k @ k)


def quat_axis_angle(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(x, y, z, w) quaternions (..., 4) of rotations about ``axis`` (3,) by ``angle`` (...)."""
    h = 0.5 * np.asarray(angle, float)
    s = np.sin(h)[..., None]
    return np.concatenate([s * np.asarray(axis, float), np.cos(h)[..., None]], axis=-1)


def quat_from_matrices(r: np.ndarray) -> np.ndarray:
    """(x, y, z, w) (..., 4) of rotation matrices (..., 3, 3), w >= 0 (vectorised Shepperd)."""
    r = np.asarray(r, float)
    m00, m11, m22 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    cand = np.stack([
        np.stack([1 + m00 - m11 - m22, r[..., 0, 1] + r[..., 1, 0], r[..., 0, 2] + r[..., 2, 0],
                  r[..., 2, 1] - r[..., 1, 2]], -1),
        np.stack([r[..., 0, 1] + r[..., 1, 0], 1 - m00 + m11 - m22, r[..., 1, 2] + r[..., 2, 1],
                  r[..., 0, 2] - r[..., 2, 0]], -1),
        np.stack([r[..., 0, 2] + r[..., 2, 0], r[..., 1, 2] + r[..., 2, 1], 1 - m00 - m11 + m22,
                  r[..., 1, 0] - r[..., 0, 1]], -1),
        np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0],
                  r[..., 1, 0] - r[..., 0, 1], 1 + m00 + m11 + m22], -1)], -2)
    diag = np.stack([m00, m11, m22, m00 + m11 + m22], -1)
    best = np.argmax(diag, axis=-1)
    q = np.take_along_axis(cand, best[..., None, None], axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0, -q, q)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` over the last axis, without its axis juggling (a third of the time)."""
    a, b = np.broadcast_arrays(a, b)
    out = np.empty(a.shape)
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _unit(v: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, EPS), n[..., 0]


def _frame(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation (..., 3, 3) with columns a, b', a x b' (b' = b made orthogonal to a; unit a)."""
    b = b - np.sum(a * b, -1, keepdims=True) * a
    b, _ = _unit(b)
    return np.stack([a, b, _cross(a, b)], axis=-1)


def least_rotation(u: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The smallest rotation (..., 3, 3) taking unit vector(s) ``u`` onto unit vectors ``d``."""
    u = np.broadcast_to(np.asarray(u, float), d.shape)
    c = np.sum(u * d, -1)
    k = _cross(u, d)
    s = np.linalg.norm(k, axis=-1)
    # opposite vectors: half a turn about any axis orthogonal to u
    alt = _cross(u, np.where(np.abs(u[..., :1]) < 0.9, _AXES[0], _AXES[1]))
    k = np.where((s < 1e-9)[..., None] & (c < 0)[..., None], alt, k)
    k, _ = _unit(k)
    ang = np.arctan2(s, c)
    kx = np.zeros(d.shape[:-1] + (3, 3))
    kx[..., 0, 1], kx[..., 0, 2], kx[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    kx[..., 1, 0], kx[..., 2, 0], kx[..., 2, 1] = k[..., 2], -k[..., 1], k[..., 0]
    t = ang[..., None, None]
    return np.eye(3) + np.sin(t) * kx + (1.0 - np.cos(t)) * (kx @ kx)


# ------------------------------------------------------------------ the tree
@dataclass(frozen=True)
class Link:
    """One segment's link. ``segment``: index in ``model.SEGMENTS``; ``parent``: index of the
    parent link in ``Tree.links`` (-1: the root frame); ``kind``: BALL or HINGE; ``axis``: the
    hinge axis in rest axes; ``twist``: how the segment's twist is chosen (``None``: least
    rotation; ``('line', a, b, ref)``: the direction b -> a of joints a, b lies along ``ref`` (rest
    axes), made orthogonal to the segment; ``('hinge', k)``: the axis of the hinge link k below)."""

    name: str
    segment: int
    parent: int
    kind: str
    joints: Tuple[str, ...]
    axis: Tuple[float, float, float] = (0.0, 0.0, 1.0)
    twist: Optional[tuple] = None
    intermediate: Tuple[str, ...] = ()   # the two massless links of a ball joint

    @property
    def parent_joint(self) -> int:
        return SEGMENTS[self.segment][0]

    @property
    def child_joint(self) -> int:
        return SEGMENTS[self.segment][1]


# a reference body for rest directions: the T-pose of the model (directions do not depend on size)
_REST_OFFSETS = standard_body().rest_offsets
REST_DIRECTIONS = _REST_OFFSETS / np.maximum(np.linalg.norm(_REST_OFFSETS, axis=1, keepdims=True),
                                             EPS)
REST_DIRECTIONS[ROOT] = 0.0


class Tree:
    """A link per segment (see the module docstring), in an order where parents come first.

    ``root``: the name of the root frame. With ``root_segment`` set (the physics character), that
    segment's link *is* the root (moved by TF, not by joints); otherwise the root is a frame at the
    root joint and every segment has a joint. ``fixed``: leaf joint -> name of its end frame."""

    def __init__(self, root: str, links: Sequence[Link], fixed: Dict[int, str],
                 root_segment: int = -1, stretch: Optional[Dict[int, Tuple[str, str]]] = None):
        self.root = root
        self.links = list(links)
        self.fixed = dict(fixed)
        self.root_segment = root_segment
        # link index -> (prismatic joint, end link): the segment's length in the frame, along the
        # segment, so that positions whose lengths vary frame to frame come back exactly (and
        # joint states never depend on which URDF a consumer has)
        self.stretch = dict(stretch or {})
        self.stretch_names: List[str] = [self.stretch[i][0] for i in sorted(self.stretch)]
        self.link_of_segment = {lk.segment: i for i, lk in enumerate(self.links)}
        self.joint_names: List[str] = [j for lk in self.links for j in lk.joints]
        self._slices = []
        n = 0
        for lk in self.links:
            self._slices.append(slice(n, n + len(lk.joints)))
            n += len(lk.joints)
        if root_segment >= 0:
            self.link_of_segment[root_segment] = -1
        # index arrays for the vectorised kinematics: links by depth, parents, joints, columns
        self._parent = np.array([lk.parent for lk in self.links], int)
        self._child = np.array([lk.child_joint for lk in self.links], int)
        self._pjoint = np.array([lk.parent_joint for lk in self.links], int)
        depth = []
        for lk in self.links:
            depth.append(0 if lk.parent < 0 else depth[lk.parent] + 1)
        self._levels = [np.array([i for i, dp in enumerate(depth) if dp == level], int)
                        for level in range(max(depth, default=-1) + 1)]
        self._balls = np.array([i for i, lk in enumerate(self.links) if lk.kind != HINGE], int)
        self._hinges = np.array([i for i, lk in enumerate(self.links) if lk.kind == HINGE], int)
        self._ball_cols = np.array([c for i in self._balls for c in
                                    range(self._slices[i].start, self._slices[i].stop)], int)
        self._hinge_cols = np.array([self._slices[i].start for i in self._hinges], int)
        self._stretch_links = np.array(sorted(self.stretch), int)
        self._stretch_segments = np.array([self.links[i].segment for i in sorted(self.stretch)],
                                          int)
        rows, rev, n = {}, [], 0
        for i, lk in enumerate(self.links):
            rev += list(range(n, n + len(lk.joints)))
            n += len(lk.joints)
            if i in self.stretch:
                rows[i] = n
                n += 1
        self._rev_rows = np.array(rev, int)
        self._stretch_rows = np.array([rows[i] for i in sorted(self.stretch)], int)
        self._num_tf = n + len(self.fixed)

    @property
    def num_angles(self) -> int:
        return len(self.joint_names)

    # -------------------------------------------------- where joints are
    def frame_of_joint(self, j: int) -> str:
        """The frame whose origin is joint ``j``: a link starting there (first one), a fixed end
        frame, or the root."""
        if j in self.fixed:
            return self.fixed[j]
        if j == ROOT:
            return self.root
        for lk in self.links:
            if lk.parent_joint == j:
                return lk.name
        raise KeyError(JOINT_NAMES[j])

    # -------------------------------------------------- URDF
    def offsets(self, lengths: np.ndarray) -> np.ndarray:
        """(20, 3) rest offsets of every joint from its parent for segment ``lengths`` (19,)
        along the model's rest directions; rest offsets (20, 3) (a ``Body``'s) are kept as given."""
        lengths = np.asarray(lengths, float)
        if lengths.shape == (NUM_JOINTS, 3):
            return lengths
        out = np.zeros((NUM_JOINTS, 3))
        for k, (_, c) in enumerate(SEGMENTS):
            out[c] = REST_DIRECTIONS[c] * float(lengths[k])
        return out

    def origin(self, link: Link, offsets: np.ndarray) -> np.ndarray:
        """The link's origin in its parent frame (the end of the parent's segment; 0 at the root
        and below a parent's end link)."""
        p = link.parent_joint
        return np.zeros(3) if p == ROOT or link.parent in self.stretch else offsets[p]

    def hang(self, i: int) -> str:
        """The frame that link ``i``'s children hang from (its end link, or itself; -1: root)."""
        if i < 0:
            return self.root
        return self.stretch[i][1] if i in self.stretch else self.links[i].name

    def urdf(self, lengths: np.ndarray, robot_name: str, radii: Optional[np.ndarray] = None,
             rgba: str = '1 0.7 0 1') -> str:
        """The URDF (a string) for segment ``lengths`` (19,) or rest offsets (20, 3): revolute joints (limits +-pi: the
        angles are measured, not commanded), fixed end frames, a cylinder per segment for RViz
        (``radii``: (19,), default 3 cm)."""
        lengths = np.asarray(lengths, float)
        offsets = self.offsets(lengths)
        radii = np.full(len(SEGMENTS), 0.03) if radii is None else np.asarray(radii, float)
        out = ['<?xml version="1.0"?>', f'<robot name="{robot_name}">',
               f'  <material name="skin"><color rgba="{rgba}"/></material>',
               f'  <link name="{self.root}">{self._visual(self.root_segment, offsets, radii)}</link>']

        def joint(name, typ, parent, child, xyz=None, axis=None, lower=-math.pi, upper=math.pi):
            s = f'  <joint name="{name}" type="{typ}"><parent link="{parent}"/><child link="{child}"/>'
            if xyz is not None and np.any(np.abs(xyz) > 0):
                s += f'<origin xyz="{_fmt(xyz)}" rpy="0 0 0"/>'
            if axis is not None:
                s += (f'<axis xyz="{_fmt(axis)}"/>'
                      f'<limit lower="{lower:.6f}" upper="{upper:.6f}" effort="100" velocity="20"/>')
            return s + '</joint>'

        for i, lk in enumerate(self.links):
            parent = self.hang(lk.parent)
            xyz = self.origin(lk, offsets)
            if lk.kind == BALL:
                chain = [parent, *lk.intermediate, lk.name]
                for n, (jn, ax) in enumerate(zip(lk.joints, (_AXES[2], _AXES[1], _AXES[0]))):
                    if n < 2:
                        out.append(f'  <link name="{chain[n + 1]}"/>')
                    out.append(joint(jn, 'revolute', chain[n], chain[n + 1],
                                     xyz if n == 0 else None, ax))
            else:
                out.append(joint(lk.joints[0], 'revolute', parent, lk.name, xyz, lk.axis))
            out.append(f'  <link name="{lk.name}">{self._visual(lk.segment, offsets, radii)}</link>')
            if i in self.stretch:
                jn, end = self.stretch[i]
                out.append(f'  <link name="{end}"/>')
                out.append(joint(jn, 'prismatic', lk.name, end, None,
                                 REST_DIRECTIONS[lk.child_joint], lower=0.0, upper=2.0))
        for j, name in self.fixed.items():
            out.append(f'  <link name="{name}"/>')
            out.append(joint(name, 'fixed', self._fixed_parent(j), name, self._fixed_offset(j, offsets)))
        out.append('</robot>')
        return '\n'.join(out) + '\n'

    def _fixed_parent(self, j: int) -> str:
        """The frame a fixed frame at joint ``j`` hangs from: the segment ending at j (the root's
        frame is the root)."""
        k = SEGMENT_OF_JOINT[j]
        return self.root if k < 0 or k == self.root_segment else \
            self.hang(self.link_of_segment[k])

    def _fixed_offset(self, j: int, offsets: np.ndarray) -> np.ndarray:
        k = SEGMENT_OF_JOINT[j]
        if k >= 0 and k != self.root_segment and self.link_of_segment[k] in self.stretch:
            return np.zeros(3)
        return offsets[j]

    @staticmethod
    def _visual(k: int, offsets: np.ndarray, radii: np.ndarray) -> str:
        if k < 0:
            return ''
        end = offsets[SEGMENTS[k][1]]
        length = float(np.linalg.norm(end))
        if length < 1e-6:
            return ''
        d = end / length
        # a cylinder along z rotated onto the segment: roll-pitch-yaw of the least rotation z -> d
        rpy = euler_zyx(least_rotation(_AXES[2], d[None])[0])[::-1]
        return (f'<visual><origin xyz="{_fmt(end / 2)}" rpy="{_fmt(rpy)}"/><geometry>'
                f'<cylinder length="{length:.6g}" radius="{float(radii[k]):.6g}"/></geometry>'
                f'<material name="skin"/></visual>')

    # -------------------------------------------------- kinematics
    def solve(self, positions: np.ndarray, root_rotation: Optional[np.ndarray] = None
              ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint angles of postures given by joint positions (U, 20, 3).

        Returns ``(root_rotation (U, 3, 3), angles (U, num_angles), local (U, L, 3, 3))``: the root
        frame's axes (given, or the body heading of :func:`body_heading`), the angles in
        ``joint_names`` order and every link's rotation relative to its parent link. The links of
        one depth in the tree are solved together (a handful of array operations per depth)."""
        x = np.asarray(positions, float)
        u = x.shape[0]
        w_root = body_heading(x) if root_rotation is None else np.asarray(root_rotation, float)
        nl = len(self.links)
        world = np.empty((u, nl, 3, 3))
        local = np.empty((u, nl, 3, 3))
        d_all, _ = _unit(x[:, self._child] - x[:, self._pjoint])          # (U, L, 3)
        for lv in self._levels:
            par = self._parent[lv]
            wp = np.where((par < 0)[None, :, None, None], w_root[:, None],
                          world[:, np.maximum(par, 0)])
            d = d_all[:, lv]
            d_l = np.einsum('unji,unj->uni', wp, d)                        # parent link's axes
            rest = REST_DIRECTIONS[self._child[lv]]
            r = least_rotation(rest, d_l)
            twisted = [k for k, i in enumerate(lv) if self.links[i].twist is not None]
            if twisted:
                t = np.array(twisted)
                ref_w = np.stack([self._twist_reference(self.links[lv[k]], x, d_all)
                                  for k in twisted], axis=1)
                ref_rest = np.array([self._twist_rest(self.links[lv[k]]) for k in twisted])
                ref_l = np.einsum('unji,unj->uni', wp[:, t], ref_w)
                dl = d_l[:, t]
                perp = ref_l - np.sum(ref_l * dl, -1, keepdims=True) * dl
                ok = np.linalg.norm(perp, axis=-1) > 1e-3 * np.maximum(
                    np.linalg.norm(ref_l, axis=-1), EPS)
                rest_t = np.broadcast_to(rest[t], dl.shape)
                full = _frame(dl, ref_l) @ _frame(
                    rest_t, np.broadcast_to(ref_rest, dl.shape)).swapaxes(-1, -2)
                r[:, t] = np.where(ok[..., None, None], full, r[:, t])
            hinges = [k for k, i in enumerate(lv) if self.links[i].kind == HINGE]
            if hinges:
                h = np.array(hinges)
                ax = np.array([self.links[lv[k]].axis for k in hinges], float)
                th = np.arctan2(np.sum(_cross(rest[h], d_l[:, h]) * ax, -1),
                                np.sum(d_l[:, h] * rest[h], -1))
                r[:, h] = _rot_axes(ax, th)
            local[:, lv] = r
            world[:, lv] = wp @ r
        angles = np.empty((u, self.num_angles))
        angles[:, self._ball_cols] = euler_zyx(local[:, self._balls]).reshape(u, -1)
        if len(self._hinges):
            ax = np.array([self.links[i].axis for i in self._hinges], float)
            v = np.array([_perp(a) for a in ax])
            rv = np.einsum('ulij,lj->uli', local[:, self._hinges], v)
            angles[:, self._hinge_cols] = np.arctan2(np.sum(_cross(v, rv) * ax, -1),
                                                     np.sum(rv * v, -1))
        return w_root, angles, local

    def _twist_reference(self, lk: Link, x: np.ndarray, d_all: np.ndarray) -> np.ndarray:
        """The world vector (U, 3) that the link's twist reference follows."""
        if lk.twist[0] == 'line':
            return x[:, lk.twist[1]] - x[:, lk.twist[2]]
        # ('hinge', link index): the hinge's axis is the normal of the plane of the two segments
        return _cross(d_all[:, self.links.index(lk)], d_all[:, lk.twist[1]])

    def _twist_rest(self, lk: Link) -> np.ndarray:
        """The twist reference's direction in the rest posture (link axes)."""
        return np.asarray(lk.twist[3] if lk.twist[0] == 'line' else self.links[lk.twist[1]].axis,
                          float)

    def local_rotations(self, angles: np.ndarray) -> np.ndarray:
        """(U, L, 3, 3) link rotations relative to their parents from joint angles (U, n)."""
        angles = np.asarray(angles, float)
        out = np.empty(angles.shape[:-1] + (len(self.links), 3, 3))
        for i, lk in enumerate(self.links):
            a = angles[..., self._slices[i]]
            out[..., i, :, :] = (rot_axis(np.asarray(lk.axis), a[..., 0]) if lk.kind == HINGE
                                 else from_euler_zyx(a))
        return out

    def joint_positions(self, lengths: np.ndarray, root_pos: np.ndarray, root_rotation: np.ndarray,
                        angles: np.ndarray) -> np.ndarray:
        """Forward kinematics: joint positions (U, 20, 3) of angles (U, n) on the tree with
        segment ``lengths`` (19,) or (U, 19) (or rest offsets (20, 3) / (U, 20, 3)), the root at
        ``root_pos`` (U, 3) with axes ``root_rotation`` (U, 3, 3)."""
        angles = np.atleast_2d(angles)
        u = angles.shape[0]
        lengths = np.asarray(lengths, float)
        if lengths.shape[-2:] == (NUM_JOINTS, 3):
            off = np.broadcast_to(lengths, (u, NUM_JOINTS, 3))
        else:
            by_joint = np.zeros((u, NUM_JOINTS))
            by_joint[:, [c for _, c in SEGMENTS]] = np.broadcast_to(lengths, (u, len(SEGMENTS)))
            off = REST_DIRECTIONS * by_joint[..., None]
        local = self.local_rotations(angles)
        world = np.empty_like(local)
        x = np.empty((u, NUM_JOINTS, 3))
        x[:, ROOT] = root_pos
        w_root = np.asarray(root_rotation, float)
        if self.root_segment >= 0:   # the root link carries its own segment
            c = SEGMENTS[self.root_segment][1]
            x[:, c] = root_pos + np.einsum('uij,uj->ui', w_root, off[:, c])
        for i, lk in enumerate(self.links):
            wp = w_root if lk.parent < 0 else world[:, lk.parent]
            world[:, i] = wp @ local[:, i]
            p, c = SEGMENTS[lk.segment]
            x[:, c] = x[:, p] + np.einsum('uij,uj->ui', world[:, i], off[:, c])
        return x

    def angles_from_world(self, root_rotation: np.ndarray, world: np.ndarray) -> np.ndarray:
        """Joint angles (U, n) of links whose world rotations are known: ``world`` (U, 19, 3, 3)
        by segment (``model.SEGMENTS`` order; the root segment's is the root's when the root
        link carries it), ``root_rotation`` (U, 3, 3). A hinge keeps only its rotation about its
        axis. All links at once (no recursion: every rotation is given)."""
        w_root = np.asarray(root_rotation, float)
        world = np.asarray(world, float)
        full = np.concatenate([world, w_root[:, None]], axis=1)   # index -1: the root
        seg = np.array([lk.segment for lk in self.links])
        par = np.array([self.links[lk.parent].segment if lk.parent >= 0 else -1
                        for lk in self.links])
        local = full[:, par].swapaxes(-1, -2) @ world[:, seg]        # (U, L, 3, 3)
        angles = np.empty((w_root.shape[0], self.num_angles))
        balls = [i for i, lk in enumerate(self.links) if lk.kind != HINGE]
        cols = np.concatenate([np.arange(self._slices[i].start, self._slices[i].stop)
                               for i in balls])
        angles[:, cols] = euler_zyx(local[:, balls]).reshape(len(angles), -1)
        for i, lk in enumerate(self.links):
            if lk.kind == HINGE:
                ax = np.asarray(lk.axis)
                v = _perp(ax)
                rv = local[:, i] @ v
                angles[:, self._slices[i]] = np.arctan2(_cross(v, rv) @ ax, rv @ v)[:, None]
        return angles

    def tf_pairs(self) -> List[Tuple[str, str]]:
        """(parent, child) of every URDF joint, what ``robot_state_publisher`` would put on TF:
        each link's revolute joints then its stretch, then the fixed frames."""
        pairs = []
        for i, lk in enumerate(self.links):
            chain = [self.hang(lk.parent), *lk.intermediate, lk.name]
            pairs += list(zip(chain[:-1], chain[1:]))
            if i in self.stretch:
                pairs.append((lk.name, self.stretch[i][1]))
        return pairs + [(self._fixed_parent(j), name) for j, name in self.fixed.items()]

    def tf_translations(self, lengths: np.ndarray, stretch: Optional[np.ndarray] = None
                        ) -> np.ndarray:
        """(J, 3) translations of :meth:`tf_pairs` for the URDF's segment ``lengths`` (or, with
        ``stretch`` (U, S), (U, J, 3): the stretch joints moved by those values)."""
        offsets = self.offsets(lengths)
        out = np.zeros((self._num_tf, 3))
        n = 0
        for i, lk in enumerate(self.links):
            out[n] = self.origin(lk, offsets)
            n += len(lk.joints)
            if i in self.stretch:   # (the stretch joint's value is the whole length)
                n += 1
        out[n:] = [self._fixed_offset(j, offsets) for j in self.fixed]
        return out if stretch is None else self.stretched(out, stretch)

    def stretched(self, translations: np.ndarray, stretch: np.ndarray) -> np.ndarray:
        """:meth:`tf_translations` ``translations`` (J, 3) with the stretch joints at ``stretch``
        (..., S): (..., J, 3)."""
        stretch = np.asarray(stretch, float)
        out = np.array(np.broadcast_to(translations, stretch.shape[:-1] + translations.shape))
        dirs = REST_DIRECTIONS[self._child[self._stretch_links]]
        out[..., self._stretch_rows, :] += stretch[..., None] * dirs
        return out

    def stretch_of(self, lengths: np.ndarray) -> np.ndarray:
        """(..., S) stretch joint values (m) of segment ``lengths`` (..., 19): the lengths."""
        return np.asarray(lengths, float)[..., self._stretch_segments]

    def tf_rotations(self, angles: np.ndarray) -> np.ndarray:
        """(U, J, 4) quaternions x y z w of :meth:`tf_pairs` for joint angles (U, n)."""
        if not hasattr(self, '_axes'):
            axes = []
            for lk in self.links:
                axes += [lk.axis] if lk.kind == HINGE else [_AXES[2], _AXES[1], _AXES[0]]
            self._axes = np.array(axes, float)
        angles = np.atleast_2d(np.asarray(angles, float))
        h = 0.5 * angles
        q = np.zeros((angles.shape[0], self._num_tf, 4))
        q[..., 3] = 1.0
        q[:, self._rev_rows, :3] = np.sin(h)[..., None] * self._axes
        q[:, self._rev_rows, 3] = np.cos(h)
        return q


def _perp(a: np.ndarray) -> np.ndarray:
    """A unit vector orthogonal to unit vector ``a``."""
    v = np.cross(a, _AXES[0] if abs(a[0]) < 0.9 else _AXES[1])
    return v / np.linalg.norm(v)


def body_heading(x: np.ndarray, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Axes (U, 3, 3) of a body's frame from its joint positions (U, 20, 3): z up (``up`` of the
    positions' frame), y along the hip line (right to left hip) made horizontal, x = y x z
    forward (REP-155's ``body_<id>``: x forward, z up)."""
    from .model import HIP_LEFT, HIP_RIGHT, SHOULDER_LEFT, SHOULDER_RIGHT
    z = np.broadcast_to(np.asarray(up, float), x.shape[:1] + (3,))
    y = x[:, HIP_LEFT] - x[:, HIP_RIGHT]
    y = y - np.sum(y * z, -1, keepdims=True) * z
    shoulders = x[:, SHOULDER_LEFT] - x[:, SHOULDER_RIGHT]
    shoulders = shoulders - np.sum(shoulders * z, -1, keepdims=True) * z
    weak = np.linalg.norm(y, axis=-1) < 1e-4
    y = np.where(weak[:, None], shoulders, y)
    y, n = _unit(y)
    y = np.where((n < 1e-6)[:, None], _AXES[1], y)
    return np.stack([_cross(y, z), y, z], axis=-1)


def segment_tree(root: str, name: Callable[[int], str], kinds: Dict[int, str] = None,
                 axes: Dict[int, tuple] = None, twists: Dict[int, tuple] = None,
                 fixed: Dict[int, str] = None, root_segment: int = -1,
                 joint_names: Callable[[int], Tuple[str, ...]] = None,
                 intermediate: Callable[[int], Tuple[str, str]] = None,
                 stretch: Callable[[int], Tuple[str, str]] = None) -> Tree:
    """A :class:`Tree` with one link per segment, named ``name(k)`` (k: segment index);
    ``kinds[k]`` BALL (default) or HINGE with ``axes[k]``; ``twists[k]`` as :class:`Link`'s
    (a ``('hinge', k2)`` names the hinge's *segment*); ``joint_names(k)`` the revolute joints'
    names (3 for a ball, 1 for a hinge) and ``intermediate(k)`` a ball's two massless links;
    ``stretch(k)``: (prismatic joint, end link) of a segment whose length may vary (:class:`Tree`)."""
    kinds, axes, twists, fixed = kinds or {}, axes or {}, twists or {}, fixed or {}
    order: List[int] = []

    def visit(j):
        for c in CHILDREN[j]:
            k = SEGMENT_OF_JOINT[c]
            if k != root_segment:
                order.append(k)
            visit(c)
    visit(ROOT)
    index = {k: i for i, k in enumerate(order)}
    links = []
    for k in order:
        p = SEGMENTS[k][0]
        pk = SEGMENT_OF_JOINT[p] if p != ROOT else -1
        parent = -1 if (pk < 0 or pk == root_segment) else index[pk]
        tw = twists.get(k)
        if tw is not None and tw[0] == 'hinge':
            tw = ('hinge', index[tw[1]])
        links.append(Link(name=name(k), segment=k, parent=parent, kind=kinds.get(k, BALL),
                          joints=joint_names(k), axis=tuple(axes.get(k, (0.0, 0.0, 1.0))),
                          twist=tw, intermediate=intermediate(k) if kinds.get(k, BALL) == BALL
                          else ()))
    st = {} if stretch is None else {i: stretch(k) for i, k in enumerate(order)}
    return Tree(root, links, fixed, root_segment, st)


# ------------------------------------------------------------------ URDF forward kinematics
def _fmt(v) -> str:
    return ' '.join(f'{float(x):.6g}' for x in np.atleast_1d(v))


def _floats(text: Optional[str], n: int = 3) -> np.ndarray:
    return np.zeros(n) if not text else np.array([float(t) for t in text.split()], float)


def parse_urdf(text: str) -> Tuple[str, Dict[str, dict]]:
    """(root link, {child link: joint}) of a URDF; a joint is a dict with ``name``, ``type``,
    ``parent``, ``xyz``, ``rpy``, ``axis``. Raises ``ValueError`` for a URDF that is not a tree."""
    robot = ET.fromstring(text)
    if robot.tag != 'robot':
        raise ValueError(f'not a URDF: root element <{robot.tag}>')
    links = [lk.get('name') for lk in robot.findall('link')]
    if len(set(links)) != len(links):
        raise ValueError('a link name appears twice')
    joints: Dict[str, dict] = {}
    names = set()
    for j in robot.findall('joint'):
        child, parent = j.find('child').get('link'), j.find('parent').get('link')
        if child in joints:
            raise ValueError(f'link {child!r} has two parent joints')
        if child not in links or parent not in links:
            raise ValueError(f'joint {j.get("name")!r} names a link that does not exist')
        if j.get('name') in names:
            raise ValueError(f'joint {j.get("name")!r} appears twice')
        names.add(j.get('name'))
        o, ax = j.find('origin'), j.find('axis')
        joints[child] = dict(name=j.get('name'), type=j.get('type'), parent=parent,
                             xyz=_floats(o.get('xyz') if o is not None else None),
                             rpy=_floats(o.get('rpy') if o is not None else None),
                             axis=_floats(ax.get('xyz') if ax is not None else '1 0 0'))
    roots = [lk for lk in links if lk not in joints]
    if len(roots) != 1:
        raise ValueError(f'a URDF has one root link, this one has {roots}')
    for lk in links:   # every link reaches the root (no cycle)
        seen, f = set(), lk
        while f in joints:
            if f in seen:
                raise ValueError(f'cycle through link {f!r}')
            seen.add(f)
            f = joints[f]['parent']
    return roots[0], joints


def forward_kinematics_urdf(text: str, positions: Dict[str, float]
                            ) -> Dict[str, Tuple[np.ndarray, np.ndarray]]:
    """Pose ``(rotation 3x3, translation 3)`` of every link of a URDF in its root link's frame, for
    joint ``positions`` by joint name (revolute / continuous / prismatic / fixed; a joint left out
    is at 0)."""
    root, joints = parse_urdf(text)
    out = {root: (np.eye(3), np.zeros(3))}

    def pose(link):
        if link in out:
            return out[link]
        j = joints[link]
        rp, tp = pose(j['parent'])
        r, p, y = j['rpy']
        ro = from_euler_zyx(np.array([y, p, r]))
        q = float(positions.get(j['name'], 0.0))
        ax = j['axis'] / max(float(np.linalg.norm(j['axis'])), EPS)
        rj, tj = np.eye(3), np.zeros(3)
        if j['type'] in ('revolute', 'continuous'):
            rj = rot_axis(ax, q)
        elif j['type'] == 'prismatic':
            tj = ax * q
        out[link] = (rp @ ro @ rj, tp + rp @ (j['xyz'] + ro @ tj))
        return out[link]

    for lk in joints:
        pose(lk)
    return out


__all__ = ['BALL', 'HINGE', 'Link', 'Tree', 'segment_tree', 'body_heading', 'REST_DIRECTIONS',
           'rot_axis', 'euler_zyx', 'from_euler_zyx', 'least_rotation', 'quat_axis_angle',
           'quat_from_matrices', 'parse_urdf', 'forward_kinematics_urdf', 'PARENTS']
