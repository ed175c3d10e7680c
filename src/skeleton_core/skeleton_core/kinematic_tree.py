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


def _unit(v: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, EPS), n[..., 0]


def _frame(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation (..., 3, 3) with columns a, b', a x b' (b' = b made orthogonal to a; unit a)."""
    b = b - np.sum(a * b, -1, keepdims=True) * a
    b, _ = _unit(b)
    return np.stack([a, b, np.cross(a, b)], axis=-1)


def least_rotation(u: np.ndarray, d: np.ndarray) -> np.ndarray:
    """The smallest rotation (..., 3, 3) taking unit vector(s) ``u`` onto unit vectors ``d``."""
    u = np.broadcast_to(np.asarray(u, float), d.shape)
    c = np.sum(u * d, -1)
    k = np.cross(u, d)
    s = np.linalg.norm(k, axis=-1)
    # opposite vectors: half a turn about any axis orthogonal to u
    alt = np.cross(u, np.where(np.abs(u[..., :1]) < 0.9, _AXES[0], _AXES[1]))
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
                 root_segment: int = -1):
        self.root = root
        self.links = list(links)
        self.fixed = dict(fixed)
        self.root_segment = root_segment
        self.link_of_segment = {lk.segment: i for i, lk in enumerate(self.links)}
        self.joint_names: List[str] = [j for lk in self.links for j in lk.joints]
        self._slices = []
        n = 0
        for lk in self.links:
            self._slices.append(slice(n, n + len(lk.joints)))
            n += len(lk.joints)
        if root_segment >= 0:
            self.link_of_segment[root_segment] = -1

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
        """(20, 3) rest offsets of every joint from its parent for segment ``lengths`` (19,)."""
        out = np.zeros((NUM_JOINTS, 3))
        for k, (_, c) in enumerate(SEGMENTS):
            out[c] = REST_DIRECTIONS[c] * float(lengths[k])
        return out

    def origin(self, link: Link, offsets: np.ndarray) -> np.ndarray:
        """The link's origin in its parent link (the end of the parent's segment; 0 at the root)."""
        p = link.parent_joint
        return np.zeros(3) if p == ROOT else offsets[p]

    def urdf(self, lengths: np.ndarray, robot_name: str, radii: Optional[np.ndarray] = None,
             rgba: str = '1 0.7 0 1') -> str:
        """The URDF (a string) for segment ``lengths`` (19,): revolute joints (limits +-pi: the
        angles are measured, not commanded), fixed end frames, a cylinder per segment for RViz
        (``radii``: (19,), default 3 cm)."""
        lengths = np.asarray(lengths, float)
        offsets = self.offsets(lengths)
        radii = np.full(len(SEGMENTS), 0.03) if radii is None else np.asarray(radii, float)
        out = ['<?xml version="1.0"?>', f'<robot name="{robot_name}">',
               f'  <material name="skin"><color rgba="{rgba}"/></material>',
               f'  <link name="{self.root}">{self._visual(self.root_segment, offsets, radii)}</link>']

        def joint(name, typ, parent, child, xyz=None, axis=None):
            s = f'  <joint name="{name}" type="{typ}"><parent link="{parent}"/><child link="{child}"/>'
            if xyz is not None and np.any(np.abs(xyz) > 0):
                s += f'<origin xyz="{_fmt(xyz)}" rpy="0 0 0"/>'
            if axis is not None:
                s += (f'<axis xyz="{_fmt(axis)}"/>'
                      f'<limit lower="{-math.pi:.6f}" upper="{math.pi:.6f}" effort="100" velocity="20"/>')
            return s + '</joint>'

        for lk in self.links:
            parent = self.root if lk.parent < 0 else self.links[lk.parent].name
            xyz = self.origin(lk, offsets)
            if lk.kind == BALL:
                chain = [parent, *lk.intermediate, lk.name]
                for i, (jn, ax) in enumerate(zip(lk.joints, (_AXES[2], _AXES[1], _AXES[0]))):
                    if i < 2:
                        out.append(f'  <link name="{chain[i + 1]}"/>')
                    out.append(joint(jn, 'revolute', chain[i], chain[i + 1],
                                     xyz if i == 0 else None, ax))
            else:
                out.append(joint(lk.joints[0], 'revolute', parent, lk.name, xyz, lk.axis))
            out.append(f'  <link name="{lk.name}">{self._visual(lk.segment, offsets, radii)}</link>')
        for j, name in self.fixed.items():
            k = SEGMENT_OF_JOINT[j]
            parent = self.root if k == self.root_segment else self.links[self.link_of_segment[k]].name
            out.append(f'  <link name="{name}"/>')
            out.append(joint(name, 'fixed', parent, name, offsets[j]))
        out.append('</robot>')
        return '\n'.join(out) + '\n'

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
        ``joint_names`` order and every link's rotation relative to its parent link."""
        x = np.asarray(positions, float)
        u = x.shape[0]
        w_root = body_heading(x) if root_rotation is None else np.asarray(root_rotation, float)
        nl = len(self.links)
        world = np.empty((u, nl, 3, 3))
        local = np.empty((u, nl, 3, 3))
        angles = np.empty((u, self.num_angles))
        for i, lk in enumerate(self.links):
            wp = w_root if lk.parent < 0 else world[:, lk.parent]
            p, c = SEGMENTS[lk.segment]
            d, _ = _unit(x[:, c] - x[:, p])
            d_l = np.einsum('uji,uj->ui', wp, d)           # in the parent link's axes
            rest = REST_DIRECTIONS[c]
            if lk.kind == HINGE:
                ax = np.asarray(lk.axis)
                th = np.arctan2(np.cross(rest, d_l) @ ax, d_l @ rest)
                r = rot_axis(ax, th)
                angles[:, self._slices[i]] = th[:, None]
            else:
                r = least_rotation(rest, d_l)
                ref_w, ref_rest = self._twist_reference(lk, x, d)
                if ref_w is not None:
                    ref_l = np.einsum('uji,uj->ui', wp, ref_w)
                    ref_l_perp = ref_l - np.sum(ref_l * d_l, -1, keepdims=True) * d_l
                    ok = np.linalg.norm(ref_l_perp, axis=-1) > 1e-3 * np.maximum(
                        np.linalg.norm(ref_l, axis=-1), EPS)
                    full = _frame(d_l, ref_l) @ _frame(np.broadcast_to(rest, d_l.shape),
                                                       np.broadcast_to(ref_rest, d_l.shape)
                                                       ).swapaxes(-1, -2)
                    r = np.where(ok[:, None, None], full, r)
                angles[:, self._slices[i]] = euler_zyx(r)
            local[:, i] = r
            world[:, i] = wp @ r
        return w_root, angles, local

    def _twist_reference(self, lk: Link, x: np.ndarray, d: np.ndarray):
        if lk.twist is None:
            return None, None
        if lk.twist[0] == 'line':
            _, a, b, ref = lk.twist
            return x[:, a] - x[:, b], np.asarray(ref, float)
        # ('hinge', link index): the hinge's axis is the normal of the plane of the two segments
        h = self.links[lk.twist[1]]
        d2, _ = _unit(x[:, h.child_joint] - x[:, h.parent_joint])
        return np.cross(d, d2), np.asarray(h.axis, float)

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
        segment ``lengths`` (19,) or (U, 19), the root at ``root_pos`` (U, 3) with axes
        ``root_rotation`` (U, 3, 3)."""
        angles = np.atleast_2d(angles)
        u = angles.shape[0]
        lengths = np.broadcast_to(np.asarray(lengths, float), (u, len(SEGMENTS)))
        local = self.local_rotations(angles)
        world = np.empty_like(local)
        x = np.empty((u, NUM_JOINTS, 3))
        x[:, ROOT] = root_pos
        w_root = np.asarray(root_rotation, float)
        if self.root_segment >= 0:   # the root link carries its own segment
            c = SEGMENTS[self.root_segment][1]
            x[:, c] = root_pos + np.einsum('uij,j->ui', w_root, REST_DIRECTIONS[c]) * \
                lengths[:, self.root_segment, None]
        for i, lk in enumerate(self.links):
            wp = w_root if lk.parent < 0 else world[:, lk.parent]
            world[:, i] = wp @ local[:, i]
            p, c = SEGMENTS[lk.segment]
            x[:, c] = x[:, p] + np.einsum('uij,j->ui', world[:, i], REST_DIRECTIONS[c]) * \
                lengths[:, lk.segment, None]
        return x

    def joint_transforms(self, angles: np.ndarray, lengths: np.ndarray
                         ) -> Tuple[List[Tuple[str, str]], np.ndarray, np.ndarray]:
        """What ``robot_state_publisher`` would put on TF for every URDF joint: ``(pairs,
        translations (U, J, 3), quaternions (U, J, 4))``, ``pairs[j] = (parent, child)`` link."""
        angles = np.atleast_2d(np.asarray(angles, float))
        u = angles.shape[0]
        offsets = self.offsets(lengths)
        pairs, trans, quats = [], [], []
        zero = np.zeros((u, 3))
        for i, lk in enumerate(self.links):
            parent = self.root if lk.parent < 0 else self.links[lk.parent].name
            a = angles[:, self._slices[i]]
            xyz = np.broadcast_to(self.origin(lk, offsets), (u, 3))
            if lk.kind == HINGE:
                pairs.append((parent, lk.name))
                trans.append(xyz)
                quats.append(quat_axis_angle(np.asarray(lk.axis), a[:, 0]))
            else:
                chain = [parent, *lk.intermediate, lk.name]
                for n, ax in enumerate((_AXES[2], _AXES[1], _AXES[0])):
                    pairs.append((chain[n], chain[n + 1]))
                    trans.append(xyz if n == 0 else zero)
                    quats.append(quat_axis_angle(ax, a[:, n]))
        ident = np.broadcast_to(np.array([0.0, 0.0, 0.0, 1.0]), (u, 4))
        for j, name in self.fixed.items():
            k = SEGMENT_OF_JOINT[j]
            parent = self.root if k == self.root_segment else self.links[self.link_of_segment[k]].name
            pairs.append((parent, name))
            trans.append(np.broadcast_to(offsets[j], (u, 3)))
            quats.append(ident)
        return pairs, np.stack(trans, axis=1), np.stack(quats, axis=1)


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
    return np.stack([np.cross(y, z), y, z], axis=-1)


def segment_tree(root: str, name: Callable[[int], str], kinds: Dict[int, str] = None,
                 axes: Dict[int, tuple] = None, twists: Dict[int, tuple] = None,
                 fixed: Dict[int, str] = None, root_segment: int = -1,
                 joint_names: Callable[[int], Tuple[str, ...]] = None,
                 intermediate: Callable[[int], Tuple[str, str]] = None) -> Tree:
    """A :class:`Tree` with one link per segment, named ``name(k)`` (k: segment index);
    ``kinds[k]`` BALL (default) or HINGE with ``axes[k]``; ``twists[k]`` as :class:`Link`'s
    (a ``('hinge', k2)`` names the hinge's *segment*); ``joint_names(k)`` the revolute joints'
    names (3 for a ball, 1 for a hinge) and ``intermediate(k)`` a ball's two massless links."""
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
    return Tree(root, links, fixed, root_segment)


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
