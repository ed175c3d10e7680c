"""MJCF for one simulated character, generated from the skeleton model (Shum & Ho 2012, Sec. 4).

The character has one rigid body per skeleton segment (19, ``model.SEGMENTS``), each a capsule from
the segment's parent joint to its child joint, with the segment's mass and radius from
:func:`skeleton_core.model.standard_body`. Bodies are connected by ball joints at the joint points;
the root body (the HipCenter-Spine segment) carries a free joint at HipCenter. Every body frame has
its origin at the segment's parent joint and is aligned with the world in the T-pose (facing +x,
z up), so a body's world quaternion *is* the segment's rotation from the rest posture -- the
convention of ``Skeleton.orientations``.

Names are prefixed per character (``u<id>_``) so several characters live in one world:

* body ``<p>seg_<ChildJoint>`` for every segment (e.g. ``u3_seg_ElbowLeft``),
* joint ``<p>root`` (free) and ``<p>ball_<ChildJoint>`` (ball),
* mocap body ``<p>target_<Joint>`` for each of the 20 joints (only for the constraint controller),
* equality ``<p>track_<Joint>`` (soft connect to the mocap target) and ``<p>pin_<Foot>`` (virtual
  joint pinning a foot to the floor; its world anchor is set at run time).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np
from skeleton_core.model import (JOINT_NAMES, NUM_JOINTS, PARENTS, ROOT, SEGMENT_CHILDREN,
                                 SEGMENT_OF_JOINT, SEGMENTS, SPINE, FOOT_LEFT, FOOT_RIGHT, Body)

ROOT_SEGMENT = SEGMENT_OF_JOINT[SPINE]  # the HipCenter-Spine segment is the root body
PIN_JOINTS = (FOOT_LEFT, FOOT_RIGHT)


def character_prefix(user_id: int) -> str:
    """The name prefix of the character of user ``user_id``."""
    return f'u{int(user_id)}_'


@dataclass(frozen=True)
class ElementNames:
    """The MuJoCo element names of one character (module docstring): written by the builders
    here and mjcf_world, looked up by ``Character.bind`` and the simulation. ``j`` is a joint
    index; a segment's elements are named by its child joint."""

    prefix: str

    def body(self, j: int) -> str:
        return f'{self.prefix}seg_{JOINT_NAMES[j]}'

    def root_joint(self) -> str:
        return f'{self.prefix}root'

    def ball_joint(self, j: int) -> str:
        return f'{self.prefix}ball_{JOINT_NAMES[j]}'

    def geom(self, j: int) -> str:
        return f'{self.prefix}geom_{JOINT_NAMES[j]}'

    def axis_site(self, j: int) -> str:
        return f'{self.prefix}axis_{JOINT_NAMES[j]}'

    def joint_site(self, j: int) -> str:
        return f'{self.prefix}site_{JOINT_NAMES[j]}'

    def target(self, j: int) -> str:
        return f'{self.prefix}target_{JOINT_NAMES[j]}'

    def pin(self, j: int) -> str:
        return f'{self.prefix}pin_{JOINT_NAMES[j]}'

    def track(self, j: int) -> str:
        return f'{self.prefix}track_{JOINT_NAMES[j]}'

    def twist_actuator(self, j: int) -> str:
        return f'{self.prefix}twist_{JOINT_NAMES[j]}'

    def pd_actuator(self, j: int, axis: str) -> str:
        return f'{self.prefix}pd_{JOINT_NAMES[j]}_{axis}'

    def hold(self, object_name: str, hand: int) -> str:
        return f'{self.prefix}hold_{object_name}_{JOINT_NAMES[hand]}'


def fmt(v) -> str:
    """Numbers for MJCF attributes (compact, round-trip enough for metres and kilograms)."""
    return ' '.join(f'{float(x):.6g}' for x in np.atleast_1d(v))


def segment_parent_body(k: int) -> int:
    """Segment index of the body that segment ``k`` hangs from (-1 for the root segment)."""
    if k == ROOT_SEGMENT:
        return -1
    parent_joint = SEGMENTS[k][0]
    if parent_joint == ROOT:
        return ROOT_SEGMENT
    return SEGMENT_OF_JOINT[parent_joint]


def body_order() -> List[int]:
    """Segments in an order where every body comes after the body it hangs from."""
    order, done = [], set()
    while len(order) < len(SEGMENTS):
        for k in range(len(SEGMENTS)):
            pb = segment_parent_body(k)
            if k not in done and (pb < 0 or pb in done):
                order.append(k)
                done.add(k)
    return order


@dataclass(frozen=True)
class CharacterParams:
    """Parameters of the generated character (everything a builder needs besides the body)."""

    joint_damping: float = 2.0      # N m s / rad, ball joints (integrated implicitly)
    joint_armature: float = 0.02    # kg m^2, ball joints (adds rotor-like inertia: stability)
    friction: float = 1.0           # sliding friction of the capsules
    contype: int = 2                # collision bits (see mjcf_world: one bit per character)
    conaffinity: int = 1
    rgba: Tuple[float, float, float, float] = (0.85, 0.6, 0.45, 1.0)
    mocap_targets: bool = False     # add mocap target bodies + soft connect equalities
    track_solref: Tuple[float, float] = (0.03, 1.0)   # timeconst (s), damping ratio
    track_solimp: Tuple[float, float, float] = (0.9, 0.95, 0.001)
    pin_solref: Tuple[float, float] = (0.01, 1.0)
    # actuator_pd controller: a site at every joint point and three actuators per joint (world
    # x, y, z) realising Eq. 1 in MuJoCo (kp = Ke, kv = Kd, force bounded per axis)
    pd_actuators: bool = False
    pd_kp: float = 4000.0
    pd_kv: float = 100.0
    pd_force_limit: float = 800.0


def segment_local_end(body: Body, k: int) -> np.ndarray:
    """The segment's child joint point in its body frame (T-pose offset)."""
    return np.asarray(body.rest_offsets[SEGMENT_CHILDREN[k]], float)


def joint_anchor(body: Body, j: int) -> Tuple[int, np.ndarray]:
    """(segment, local point) where joint ``j`` lives: the child end of the segment ending at ``j``;
    the root joint is the origin of the root body."""
    if j == ROOT:
        return ROOT_SEGMENT, np.zeros(3)
    k = SEGMENT_OF_JOINT[j]
    return k, segment_local_end(body, k)


def character_bodies_xml(prefix: str, body: Body, root_pos, params: CharacterParams,
                         root_quat_wxyz=(1.0, 0.0, 0.0, 0.0)) -> str:
    """The ``<body>`` tree of one character (to place inside ``<worldbody>``)."""
    children = {k: [] for k in range(len(SEGMENTS))}
    for k in body_order():
        pb = segment_parent_body(k)
        if pb >= 0:
            children[pb].append(k)
    rgba = fmt(params.rgba)
    names = ElementNames(prefix)

    def emit(k: int, depth: int) -> List[str]:
        ind = '  ' * depth
        child = SEGMENT_CHILDREN[k]
        pb = segment_parent_body(k)
        if pb < 0:
            head = (f'{ind}<body name="{names.body(child)}" pos="{fmt(root_pos)}" '
                    f'quat="{fmt(root_quat_wxyz)}">')
            joint = f'{ind}  <freejoint name="{names.root_joint()}"/>'
        else:
            # this body starts at its parent joint = the child end of the parent body
            pos = segment_local_end(body, pb) if SEGMENTS[k][0] != ROOT else np.zeros(3)
            head = f'{ind}<body name="{names.body(child)}" pos="{fmt(pos)}">'
            joint = (f'{ind}  <joint name="{names.ball_joint(child)}" type="ball" '
                     f'damping="{params.joint_damping:.6g}" armature="{params.joint_armature:.6g}"/>')
        end = segment_local_end(body, k)
        r = float(body.segment_radii[k])
        geom = (f'{ind}  <geom name="{names.geom(child)}" type="capsule" fromto="0 0 0 {fmt(end)}" '
                f'size="{r:.6g}" mass="{float(body.segment_masses[k]):.6g}" '
                f'contype="{params.contype}" conaffinity="{params.conaffinity}" '
                f'friction="{params.friction:.6g} 0.005 0.0001" rgba="{rgba}"/>')
        lines = [head, joint, geom]
        if params.pd_actuators:
            axis = end / max(float(np.linalg.norm(end)), 1e-9)
            lines.append(f'{ind}  <site name="{names.axis_site(child)}" pos="0 0 0" '
                         f'zaxis="{fmt(axis)}" size="0.01"/>')
        # a site at every joint point (the actuators' point, and where MuJoCo computes the joint
        # positions the simulation reads at every step)
        for j in range(NUM_JOINTS):
            seg, local = joint_anchor(body, j)
            if seg == k:
                lines.append(f'{ind}  <site name="{names.joint_site(j)}" '
                             f'pos="{fmt(local)}" size="0.01"/>')
        for c in children[k]:
            lines += emit(c, depth + 1)
        lines.append(f'{ind}</body>')
        return lines

    return '\n'.join(emit(ROOT_SEGMENT, 2))


def character_mocap_xml(prefix: str, positions: np.ndarray) -> str:
    """One mocap body per joint (targets of the constraint controller), at ``positions`` (20, 3)."""
    names = ElementNames(prefix)
    return '\n'.join(f'    <body name="{names.target(j)}" mocap="true" '
                     f'pos="{fmt(positions[j])}"/>' for j in range(NUM_JOINTS))


def character_equality_xml(prefix: str, body: Body, params: CharacterParams) -> str:
    """Foot pins (inactive) and, with mocap targets, the soft tracking connects (active)."""
    lines = []
    names = ElementNames(prefix)
    for j in PIN_JOINTS:
        k, local = joint_anchor(body, j)
        lines.append(f'    <connect name="{names.pin(j)}" '
                     f'body1="{names.body(SEGMENT_CHILDREN[k])}" body2="world" '
                     f'anchor="{fmt(local)}" active="false" solref="{fmt(params.pin_solref)}"/>')
    if params.mocap_targets:
        for j in range(NUM_JOINTS):
            k, local = joint_anchor(body, j)
            lines.append(f'    <connect name="{names.track(j)}" '
                         f'body1="{names.body(SEGMENT_CHILDREN[k])}" '
                         f'body2="{names.target(j)}" anchor="{fmt(local)}" '
                         f'solref="{fmt(params.track_solref)}" solimp="{fmt(params.track_solimp)}"/>')
    return '\n'.join(lines)


AXES = ('x', 'y', 'z')
ORIGIN_SITE = 'origin'   # world site the PD actuators measure their length from


def character_actuator_xml(prefix: str, params: CharacterParams) -> str:
    """Eq. 1 and 2 as MuJoCo actuators (``actuator_pd``): for joint j and world axis a, actuator
    ``<p>pd_<Joint>_<a>`` pulls the joint's site along a with ``kp (act - x_a) - kv x'_a``, x_a the
    site's coordinate relative to the world origin site. ``act`` is an integrator state: the
    simulation sets it to the target ``p_t + (Kd/Ke) p'_t`` and its rate ``ctrl`` to the target's
    slope, so MuJoCo interpolates the target at every step itself; that is exactly ``Ke (p_t - p)
    + Kd (p'_t - p')`` per axis, bounded by ``forcerange``. Per segment, ``<p>twist_<Joint>``
    applies Eq. 2's torque about the segment axis with its damping evaluated at every step.
    Empty unless ``params.pd_actuators``."""
    if not params.pd_actuators:
        return ''
    lim = float(params.pd_force_limit)
    kp, kv = float(params.pd_kp), float(params.pd_kv)
    lines = []
    names = ElementNames(prefix)
    for k in range(len(SEGMENTS)):
        # Eq. 2 about the segment's own axis (the site's z): torque = ctrl - Kd_i * twist rate,
        # ctrl = Ke_i * twist error + Kd_i * target twist rate (set by the simulation); the gains
        # and the torque bound are set at run time (per segment inertia, see Simulation)
        child = SEGMENT_CHILDREN[k]
        lines.append(f'    <general name="{names.twist_actuator(child)}" '
                     f'site="{names.axis_site(child)}" '
                     f'gear="0 0 0 0 0 1" gainprm="1" biastype="affine" biasprm="0 0 0" '
                     f'forcelimited="true" forcerange="-1 1"/>')
    for j in range(NUM_JOINTS):
        for a, axis in enumerate(AXES):
            gear = ['0'] * 6
            gear[a] = '1'
            lines.append(f'    <general name="{names.pd_actuator(j, axis)}" '
                         f'site="{names.joint_site(j)}" refsite="{ORIGIN_SITE}" '
                         f'gear="{" ".join(gear)}" dyntype="integrator" gainprm="{kp:.6g}" '
                         f'biastype="affine" biasprm="0 {-kp:.6g} {-kv:.6g}" '
                         f'forcelimited="true" forcerange="{-lim:.6g} {lim:.6g}"/>')
    return '\n'.join(lines)


def character_xml_parts(prefix: str, body: Body, root_pos, params: Optional[CharacterParams] = None,
                        target_positions: Optional[np.ndarray] = None):
    """(bodies, mocap bodies, equalities) MJCF fragments for one character."""
    params = params or CharacterParams()
    bodies = character_bodies_xml(prefix, body, root_pos, params)
    mocap = ''
    if params.mocap_targets:
        tp = body.rest_positions() if target_positions is None else target_positions
        mocap = character_mocap_xml(prefix, tp)
    return bodies, mocap, character_equality_xml(prefix, body, params)


def standalone_character_xml(body: Body, params: Optional[CharacterParams] = None,
                             prefix: str = 'u0_') -> str:
    """A complete MJCF with just one character (root at the T-pose height) and a floor, for tests."""
    params = params or CharacterParams()
    b, m, e = character_xml_parts(prefix, body, (0.0, 0.0, body.root_height), params)
    return (f'<mujoco model="character">\n  <option timestep="0.002" integrator="implicitfast"/>\n'
            f'  <worldbody>\n    <geom name="floor" type="plane" size="0 0 0.05"/>\n{b}\n{m}\n'
            f'    <site name="{ORIGIN_SITE}"/>\n'
            f'  </worldbody>\n  <equality>\n{e}\n  </equality>\n'
            f'  <actuator>\n{character_actuator_xml(prefix, params)}\n  </actuator>\n</mujoco>')


__all__ = ['CharacterParams', 'ElementNames', 'character_prefix', 'ROOT_SEGMENT', 'PIN_JOINTS',
           'body_order', 'segment_parent_body',
           'joint_anchor', 'segment_local_end', 'character_bodies_xml', 'character_mocap_xml',
           'character_equality_xml', 'character_xml_parts', 'character_actuator_xml',
           'ORIGIN_SITE', 'AXES', 'standalone_character_xml', 'fmt',
           'PARENTS']
