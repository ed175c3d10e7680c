"""REP-155 (ROS4HRI) bodies from skeleton streams: frame and joint names, the per-body URDF, joint
states and TF, and which bodies are tracked (ROS-free; the node is ``viz.hri_node``).

A body ``<id>`` (``u<user id>`` for the reconstruction, ``c<user id>`` for the physics character)
is the kinematic tree of :mod:`skeleton_core.kinematic_tree` under the frame ``body_<id>`` (at the
hip centre, x forward, z up), with the link and joint names of ROS4HRI's body model
(``hri_fullbody``): ball joints as three revolute joints ``<side>_y_<name>``, ``<side>_p_<name>``,
``<side>_r_<name>`` (yaw about z, pitch about y, roll about x), elbows and knees as hinges.
The frame at each of the 20 Kinect joints (:data:`JOINT_FRAMES`):

=============  ==============  =============  =================
Kinect joint   frame           Kinect joint   frame
=============  ==============  =============  =================
HipCenter      ``body_<id>``   HipLeft        ``l_hip_<id>``
Spine          ``torso_<id>``  KneeLeft       ``l_knee_<id>``
ShoulderCenter ``neck_<id>``   AnkleLeft      ``l_ankle_<id>``
Head           ``head_<id>``   FootLeft       ``l_foot_<id>``
ShoulderLeft   ``l_shoulder_`` ElbowLeft      ``l_elbow_<id>``
WristLeft      ``l_wrist_<id>`` HandLeft      ``l_hand_<id>``
=============  ==============  =============  =================

(right side: ``r_``). The segments from the hip centre to each hip and from the shoulder centre to
each shoulder are the links ``l_pelvis_<id>`` and ``l_collar_<id>``; the lower back is
``waist_<id>`` (from the hip centre to Spine).

openni2_tracker's frames (``head_1``, ``left_hand_1``, ...; 15 NiTE joints, ``left_hand`` is the
wrist as NiTE reports it) are :func:`openni_frames`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import model as m
from .kinematic_tree import BALL, HINGE, Tree, body_heading, quat_from_matrices, segment_tree

TRACKED_TOPIC = '/humans/bodies/tracked'


def body_topic(body_id: str, leaf: str) -> str:
    """``/humans/bodies/<id>/<leaf>`` (leaf: ``urdf``, ``joint_states``)."""
    return f'/humans/bodies/{body_id}/{leaf}'


# the REP-155 name of the link carrying each segment, by the segment's child joint; side '' / l / r
_SEGMENT_LINK = {
    'Spine': ('', 'waist'), 'ShoulderCenter': ('', 'torso'), 'Head': ('', 'neck'),
    'ShoulderLeft': ('l', 'collar'), 'ElbowLeft': ('l', 'shoulder'), 'WristLeft': ('l', 'elbow'),
    'HandLeft': ('l', 'wrist'), 'HipLeft': ('l', 'pelvis'), 'KneeLeft': ('l', 'hip'),
    'AnkleLeft': ('l', 'knee'), 'FootLeft': ('l', 'ankle'),
    'ShoulderRight': ('r', 'collar'), 'ElbowRight': ('r', 'shoulder'), 'WristRight': ('r', 'elbow'),
    'HandRight': ('r', 'wrist'), 'HipRight': ('r', 'pelvis'), 'KneeRight': ('r', 'hip'),
    'AnkleRight': ('r', 'knee'), 'FootRight': ('r', 'ankle'),
}
_LEAF_FRAME = {m.HEAD: ('', 'head'), m.HAND_LEFT: ('l', 'hand'), m.HAND_RIGHT: ('r', 'hand'),
               m.FOOT_LEFT: ('l', 'foot'), m.FOOT_RIGHT: ('r', 'foot')}
# hinges (elbows, knees) and their axes in the rest (T-) posture: positive angle = flexion
_HINGE_AXIS = {'WristLeft': (0.0, 0.0, -1.0), 'WristRight': (0.0, 0.0, 1.0),
               'AnkleLeft': (0.0, 1.0, 0.0), 'AnkleRight': (0.0, 1.0, 0.0)}
# the segment above each hinge takes its twist from the plane of the limb
_ABOVE_HINGE = {'ElbowLeft': 'WristLeft', 'ElbowRight': 'WristRight',
                'KneeLeft': 'AnkleLeft', 'KneeRight': 'AnkleRight'}


def _name(side: str, base: str, body_id: str, axis: str = '') -> str:
    parts = [p for p in (side, axis, base) if p]
    return '_'.join(parts) + f'_{body_id}'


def human_tree(body_id: str) -> Tree:
    """The REP-155 kinematic tree of body ``body_id`` (module docstring)."""
    seg = {m.JOINT_NAMES[c]: k for k, (_, c) in enumerate(m.SEGMENTS)}

    def name(k):
        return _name(*_SEGMENT_LINK[m.JOINT_NAMES[m.SEGMENTS[k][1]]], body_id)

    def joints(k):
        child = m.JOINT_NAMES[m.SEGMENTS[k][1]]
        side, base = _SEGMENT_LINK[child]
        if child in _HINGE_AXIS:
            return (_name(side, base, body_id),)
        return tuple(_name(side, base, body_id, a) for a in ('y', 'p', 'r'))

    def intermediate(k):
        side, base = _SEGMENT_LINK[m.JOINT_NAMES[m.SEGMENTS[k][1]]]
        return tuple(_name(side, base, body_id, a) for a in ('y', 'p'))

    kinds = {seg[c]: HINGE for c in _HINGE_AXIS}
    axes = {seg[c]: ax for c, ax in _HINGE_AXIS.items()}
    twists = {seg[a]: ('hinge', seg[h]) for a, h in _ABOVE_HINGE.items()}
    twists[seg['ShoulderCenter']] = ('line', m.SHOULDER_LEFT, m.SHOULDER_RIGHT, (0.0, 1.0, 0.0))
    fixed = {j: _name(s, b, body_id) for j, (s, b) in _LEAF_FRAME.items()}
    def stretch(k):
        side, base = _SEGMENT_LINK[m.JOINT_NAMES[m.SEGMENTS[k][1]]]
        return (_name(side, base + '_length', body_id), _name(side, base + '_end', body_id))

    return segment_tree(f'body_{body_id}', name, kinds=kinds, axes=axes, twists=twists,
                        fixed=fixed, joint_names=joints, intermediate=intermediate,
                        stretch=stretch)


def joint_frames(tree: Tree) -> Tuple[str, ...]:
    """The frame at each of the 20 joints (model order) of a tree from :func:`human_tree`."""
    out = []
    for j in range(m.NUM_JOINTS):
        if j in tree.fixed:
            out.append(tree.fixed[j])
        elif j == m.ROOT:
            out.append(tree.root)
        else:   # the link whose segment starts at j (the limb's, not the collar's or pelvis's)
            starts = [lk for lk in tree.links if lk.parent_joint == j]
            out.append(starts[-1].name if j != m.SHOULDER_CENTER else
                       next(lk.name for lk in starts if lk.child_joint == m.HEAD))
    return tuple(out)


JOINT_FRAMES = tuple(f.replace('_<id>', '') for f in joint_frames(human_tree('<id>')))


def openni_frames(user_id: int) -> List[Tuple[str, int]]:
    """(frame name, Kinect joint) of openni2_tracker's 15 frames of user ``user_id``."""
    return [(f'{m.NITE_TF_NAMES[k]}_{int(user_id)}', j) for k, j in enumerate(m.NITE_TO_KINECT)]


# ------------------------------------------------------------------ bodies over a stream
@dataclass
class Body:
    """One tracked body: its tree, the lengths its URDF was made with, recent lengths."""

    body_id: str
    tree: Tree
    window: int
    lengths: Optional[np.ndarray] = None          # (19,) the published URDF's lengths
    urdf_time: float = -np.inf
    history: List[np.ndarray] = field(default_factory=list)
    pairs: List[Tuple[str, str]] = field(default_factory=list)   # its TF (parent, child)
    translations: Optional[np.ndarray] = None     # (J, 3) for ``lengths``

    def observe(self, lengths: np.ndarray) -> None:
        self.history.append(lengths)
        if len(self.history) > self.window:
            del self.history[0]

    def estimate(self) -> np.ndarray:
        return np.median(np.asarray(self.history), axis=0)


@dataclass
class Output:
    """What one input message turns into (the node publishes it as it is). A body's joint states
    are its revolute joints' angles (rad) then its segments' lengths in this frame (m, prismatic
    joints ``<segment link>_length``: the URDF's lengths are the estimate its cylinders show)."""

    stamp_ns: int
    frame_id: str
    tracked: List[str]
    urdf: Dict[str, str]                 # body id -> URDF, for bodies whose URDF is new or changed
    left: List[str]                      # bodies that left with this message
    joint_names: Dict[str, List[str]]    # body id -> joint names
    angles: Dict[str, np.ndarray]        # body id -> joint positions (rad, then m)
    tf_pairs: List[Tuple[str, str]]      # (parent, child) of every transform
    tf_translations: np.ndarray          # (T, 3)
    tf_rotations: np.ndarray             # (T, 4) x y z w


class BodyTracker:
    """Skeleton frames -> REP-155 bodies. ``id_prefix`` names bodies (``u`` -> ``u<user id>``);
    a body's URDF is made from the median segment lengths of its last ``window`` frames and made
    again when they move more than ``length_tolerance`` (m), at most every ``min_urdf_period`` s;
    ``openni`` adds openni2_tracker's frames under the input's frame."""

    def __init__(self, id_prefix: str = 'u', window: int = 30, length_tolerance: float = 0.01,
                 min_urdf_period: float = 1.0, openni: bool = False, rep155: bool = True):
        self.id_prefix = id_prefix
        self.window = int(window)
        self.length_tolerance = float(length_tolerance)
        self.min_urdf_period = float(min_urdf_period)
        self.openni = openni
        self.rep155 = rep155
        self.bodies: Dict[int, Body] = {}

    def body_id(self, user_id: int) -> str:
        return f'{self.id_prefix}{int(user_id)}'

    def clear(self) -> List[str]:
        """Forget every body (input stopped); returns the ids that left."""
        left = [b.body_id for b in self.bodies.values()]
        self.bodies.clear()
        return left

    def update(self, frames: Sequence, stamp_ns: int, frame_id: str, now_s: float) -> Output:
        """One message's frames (``SkeletonFrame``: ``user_id``, ``positions`` (20, 3))."""
        frames = [f for f in frames if np.isfinite(f.positions).all()]
        uids = [int(f.user_id) for f in frames]
        left = [self.bodies.pop(u).body_id for u in list(self.bodies) if u not in uids]
        out = Output(stamp_ns, frame_id, [], {}, left, {}, {}, [], np.zeros((0, 3)),
                     np.zeros((0, 4)))
        if not frames:
            return out
        x = np.stack([f.positions for f in frames]).astype(float)
        lengths_now = m.segment_lengths(x)
        trans, rots = [], []
        if self.rep155:
            bodies = []
            for f, lengths in zip(frames, lengths_now):
                b = self.bodies.get(int(f.user_id))
                if b is None:
                    b = self.bodies[int(f.user_id)] = Body(
                        self.body_id(f.user_id), human_tree(self.body_id(f.user_id)), self.window)
                b.observe(lengths)
                est = b.estimate()
                if b.lengths is None or (
                        np.abs(est - b.lengths).max() > self.length_tolerance
                        and now_s - b.urdf_time >= self.min_urdf_period):
                    b.lengths = est
                    b.urdf_time = now_s
                    out.urdf[b.body_id] = b.tree.urdf(est, f'human_{b.body_id}')
                    b.translations = b.tree.tf_translations(est)
                    if not b.pairs:
                        b.pairs = b.tree.tf_pairs()
                bodies.append(b)
            out.tracked = [b.body_id for b in bodies]
            # every body has the same tree shape: solved and turned into transforms together
            tree = bodies[0].tree
            w_root, angles, _ = tree.solve(x)
            q_root = quat_from_matrices(w_root)
            q_all = tree.tf_rotations(angles)
            for i, b in enumerate(bodies):
                stretch = tree.stretch_of(lengths_now[i])
                out.joint_names[b.body_id] = b.tree.joint_names + b.tree.stretch_names
                out.angles[b.body_id] = np.concatenate([angles[i], stretch])
                out.tf_pairs.append((frame_id, b.tree.root))
                out.tf_pairs.extend(b.pairs)
                trans += [x[i:i + 1, m.ROOT], tree.stretched(b.translations, stretch)]
                rots += [q_root[i:i + 1], q_all[i]]
        else:
            for u in uids:
                self.bodies.setdefault(u, Body(self.body_id(u), None, self.window))
        if self.openni:
            for f, xi in zip(frames, x):
                names = openni_frames(f.user_id)
                out.tf_pairs.extend((frame_id, n) for n, _ in names)
                idx = [j for _, j in names]
                trans.append(xi[idx])
                if f.orientations is not None and np.isfinite(f.orientations).all():
                    q = np.asarray(f.orientations, float)[idx]
                    q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)
                else:
                    q = np.tile([0.0, 0.0, 0.0, 1.0], (len(idx), 1))
                rots.append(q)
        if trans:
            out.tf_translations = np.concatenate(trans)
            out.tf_rotations = np.concatenate(rots)
        return out


# ------------------------------------------------------------------ TF on the wire
class TfEncoder:
    """``tf2_msgs/TFMessage`` bytes (XCDR1, little endian, as ``skeleton_core.cdr`` writes) of
    many transforms at once: the frame names are laid out once per set of (parent, child) pairs,
    each message then only writes its stamp and 7 numbers per transform with numpy (an rclpy
    message costs ~10 us per transform to fill and serialize: ~5 ms for 6 users' bodies)."""

    def __init__(self):
        self._key = None

    def _layout(self, pairs: Sequence[Tuple[str, str]]) -> None:
        buf = bytearray(b'\x00\x01\x00\x00')
        floats, stamps = [], []

        def align(n):
            buf.extend(b'\x00' * ((-(len(buf) - 4)) % n))

        def string(s):
            b = s.encode() + b'\x00'
            align(4)
            buf.extend(len(b).to_bytes(4, 'little'))
            buf.extend(b)
        buf.extend(len(pairs).to_bytes(4, 'little'))
        for parent, child in pairs:
            align(4)
            stamps.append(len(buf) - 4)
            buf.extend(b'\x00' * 8)          # sec, nanosec
            string(parent)
            string(child)
            align(8)
            floats.append(len(buf) - 4)
            buf.extend(b'\x00' * 56)         # translation x y z, rotation x y z w
        size = len(buf)
        buf.extend(b'\x00' * ((-(len(buf) - 4)) % 8))
        self._template = np.frombuffer(bytes(buf), np.uint8)
        self._size = size
        self._floats = (np.array(floats)[:, None] // 8 + np.arange(7)).astype(np.intp)
        self._stamps = np.array(stamps, np.intp) // 4

    def encode(self, pairs: Sequence[Tuple[str, str]], stamp_ns: int, translations: np.ndarray,
               rotations: np.ndarray) -> bytes:
        """Bytes of the TFMessage of ``pairs`` (parent, child) at ``stamp_ns``."""
        key = tuple(pairs)
        if key != self._key:
            self._layout(pairs)
            self._key = key
        buf = self._template.copy()
        body = buf[4:]
        body.view('<f8')[self._floats] = np.concatenate(
            [np.asarray(translations, float), np.asarray(rotations, float)], axis=1)
        u32 = body.view('<u4')
        u32[self._stamps] = int(stamp_ns // 1_000_000_000)
        u32[self._stamps + 1] = int(stamp_ns % 1_000_000_000)
        return buf[:self._size].tobytes()


__all__ = ['TRACKED_TOPIC', 'body_topic', 'human_tree', 'joint_frames', 'JOINT_FRAMES',
           'openni_frames', 'Body', 'BodyTracker', 'Output', 'TfEncoder', 'body_heading', 'BALL']
