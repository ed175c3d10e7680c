"""The physics character as a robot: its URDF and joint states (ROS-free).

The same body model as its MJCF (:mod:`physics_sim.mjcf_body`): one link per segment, named as the
MuJoCo body (``u<id>_seg_<ChildJoint>``), the root link ``u<id>_seg_Spine`` (the HipCenter-Spine
segment, origin at HipCenter: where the free joint is) and every MuJoCo ball joint as three
revolute joints ``u<id>_ball_<ChildJoint>_{z,y,x}`` (yaw, pitch, roll; ``R = Rz Ry Rx`` is the
ball joint's rotation relative to its parent body). Each joint point is a fixed frame named as its
MuJoCo site, ``u<id>_site_<Joint>``. The body offsets are the character's
``Body.rest_offsets``, so forward kinematics of the URDF with the joint states gives the joint
points MuJoCo computes (``/character/skeletons``). The root pose goes on TF (``world`` ->
``u<id>_seg_Spine``): URDF has no free joint.
"""
from __future__ import annotations

from typing import Dict, Tuple

import numpy as np
from skeleton_core.kinematic_tree import Tree, quat_from_matrices, segment_tree
from skeleton_core.model import NUM_JOINTS, SEGMENT_CHILDREN, SEGMENTS, Body

from .mjcf_body import ROOT_SEGMENT, ElementNames, character_prefix


def character_tree(user_id: int) -> Tree:
    """The kinematic tree of user ``user_id``'s character (module docstring)."""
    names = ElementNames(character_prefix(user_id))

    def link(k):
        return names.body(SEGMENTS[k][1])

    def joints(k):
        ball = names.ball_joint(SEGMENTS[k][1])
        return (f'{ball}_z', f'{ball}_y', f'{ball}_x')

    def intermediate(k):
        ball = names.ball_joint(SEGMENTS[k][1])
        return (f'{ball}_z', f'{ball}_y')   # (links and joints have separate names in URDF)

    sites = {j: names.joint_site(j) for j in range(NUM_JOINTS)}
    return segment_tree(link(ROOT_SEGMENT), link, root_segment=ROOT_SEGMENT, joint_names=joints,
                        intermediate=intermediate, fixed=sites)


def character_urdf(user_id: int, body: Body) -> str:
    """The URDF of user ``user_id``'s character with ``body``'s offsets and capsule radii."""
    return character_tree(user_id).urdf(body.rest_offsets, f'character_u{int(user_id)}',
                                        radii=body.segment_radii, rgba='0.85 0.6 0.45 1')


def character_joint_states(tree: Tree, orientations: np.ndarray
                           ) -> Tuple[np.ndarray, np.ndarray]:
    """(root quaternions x y z w (U, 4), joint angles (U, n)) of characters from the world
    orientations (U, 20, 4, x y z w) of their ``CharacterState`` s (by joint: the segment ending
    at the joint; the root's is the root body's). Every character's tree has the same shape:
    ``tree`` is any of them."""
    q = np.asarray(orientations, float)[:, list(SEGMENT_CHILDREN)]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    world = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)
    root = world[:, ROOT_SEGMENT]
    return quat_from_matrices(root), tree.angles_from_world(root, world)


def description_topic(user_id: int) -> str:
    """The latched topic of user ``user_id``'s character URDF."""
    return f'/character/u{int(user_id)}/robot_description'


class CharacterRobots:
    """Every character as a robot, frame by frame: :meth:`update` takes the simulation's states
    and characters and returns ``(urdf, names, angles, roots)``: the URDF of each character that
    is new or got a new body, the joint names and angles of all characters (one JointState),
    and each root's ``(child frame, translation, quaternion x y z w)`` in ``world``."""

    def __init__(self):
        self._trees: Dict[int, Tree] = {}
        self._bodies: Dict[int, Body] = {}

    def update(self, states: Dict, characters: Dict, lift: np.ndarray, angles: bool = True):
        """(``angles=False``: only the URDFs, the rest empty.)"""
        urdf = {}
        for uid in [u for u in self._trees if u not in states]:
            del self._trees[uid], self._bodies[uid]
        if not states:
            return urdf, [], np.zeros(0), []
        uids = list(states)
        for uid in uids:
            body = characters[uid].body
            if uid not in self._trees:
                self._trees[uid] = character_tree(uid)
            if self._bodies.get(uid) is not body:
                self._bodies[uid] = body
                urdf[uid] = character_urdf(uid, body)
        if not angles:
            return urdf, [], np.zeros(0), []
        q, a = character_joint_states(self._trees[uids[0]],
                                      np.stack([states[u].orientations for u in uids]))
        names = [n for u in uids for n in self._trees[u].joint_names]
        roots = [(self._trees[u].root, states[u].positions[0] - lift, q[i])
                 for i, u in enumerate(uids)]
        return urdf, names, a.reshape(-1), roots


__all__ = ['character_tree', 'character_urdf', 'character_joint_states', 'description_topic',
           'CharacterRobots']
