"""MJCF for the whole world: floor, gravity, contact options, characters and environment objects
(Shum & Ho 2012, Sec. 4 and 8: boxes, balls, a held mace).

Collision filtering: the capsules of one character do not collide with each other (the paper's
characters are a chain of overlapping capsules), but characters collide with each other, with the
floor and with objects. MuJoCo collides two geoms when ``contype1 & conaffinity2`` or
``contype2 & conaffinity1`` is non-zero, so character ``i`` gets its own bit ``b_i`` as contype and
every other bit as conaffinity; the floor and objects use all bits.

Constraint islands are disabled (``<flag island="disable"/>``): nothing here steps islands on
separate threads, and with one island (characters touching: the Newton solve is the same
arithmetic, bit for bit) MuJoCo's per-island copies of the constraint Jacobian are pure overhead,
3-5 % of the CPU of a step at 2-6 characters; characters apart cost a fraction of an iteration more
(the solver stops when the worst island has converged) and still step 2-3 % faster.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Optional, Sequence, Tuple

import numpy as np
from skeleton_core.model import Body

from .mjcf_body import (ORIGIN_SITE, CharacterParams, ElementNames, character_actuator_xml,
                        character_xml_parts, fmt)
from .mjcf_features import (features_xml, grip_equality_xml, hand_excludes_xml,
                            holdable_bodies)
from dataclasses import replace
from skeleton_core.model import HAND_LEFT, HAND_RIGHT, SEGMENT_CHILDREN
from .mjcf_body import joint_anchor

ALL_BITS = 0x7FFFFFFF
OBJECT_KINDS = ('box', 'ball', 'mace')


def character_bits(slot: int) -> Tuple[int, int]:
    """(contype, conaffinity) of the character in collision slot ``slot`` (0..29)."""
    bit = 1 << (1 + slot % 30)
    return bit, ALL_BITS & ~bit


@dataclass
class ObjectSpec:
    """An environment object. ``size``: box half-extents (3,), ball radius (1,), mace
    (handle half-length, head radius). ``grip`` is the point (object frame) a hand holds."""

    name: str
    kind: str = 'box'
    pos: Tuple[float, float, float] = (1.0, 0.0, 0.5)
    size: Tuple[float, ...] = (0.15, 0.15, 0.15)
    mass: float = 1.0
    vel: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat_wxyz: Tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    rgba: Tuple[float, float, float, float] = (0.3, 0.5, 0.9, 1.0)
    holdable: bool = False

    def __post_init__(self):
        if self.kind not in OBJECT_KINDS:
            raise ValueError(f'object kind must be one of {OBJECT_KINDS}, got {self.kind!r}')
        vals = np.asarray(tuple(self.pos) + tuple(self.size) + (self.mass,) + tuple(self.vel), float)
        if not np.all(np.isfinite(vals)):
            raise ValueError(f'object {self.name}: non-finite position/size/mass/velocity')
        if self.mass <= 0 or min(self.size) <= 0:
            raise ValueError(f'object {self.name}: mass and sizes must be positive')
        need = {'box': 3, 'ball': 1, 'mace': 2}[self.kind]
        if len(self.size) != need:
            raise ValueError(f'object {self.name}: a {self.kind} needs {need} size values')
        if self.kind == 'mace':
            self.holdable = True

    @property
    def grip(self) -> np.ndarray:
        if self.kind == 'mace':
            return np.array([0.0, 0.0, -self.size[0]])  # end of the handle
        return np.zeros(3)


def object_body(name: str) -> str:
    """The MuJoCo body name of the object ``name`` (its joint and geoms add a suffix)."""
    return f'obj_{name}'


def object_xml(o: ObjectSpec) -> str:
    rgba = fmt(o.rgba)
    b = object_body(o.name)
    head = (f'    <body name="{b}" pos="{fmt(o.pos)}" quat="{fmt(o.quat_wxyz)}">\n'
            f'      <freejoint name="{b}_free"/>\n')
    if o.kind == 'box':
        geoms = (f'      <geom name="{b}_geom" type="box" size="{fmt(o.size)}" '
                 f'mass="{o.mass:.6g}" rgba="{rgba}"/>\n')
    elif o.kind == 'ball':
        geoms = (f'      <geom name="{b}_geom" type="sphere" size="{fmt(o.size)}" '
                 f'mass="{o.mass:.6g}" rgba="{rgba}"/>\n')
    else:  # mace: a handle along local z with a heavy ball at the top
        half, rh = o.size
        geoms = (f'      <geom name="{b}_geom" type="capsule" size="0.015 {half:.6g}" '
                 f'mass="{0.25 * o.mass:.6g}" rgba="0.4 0.3 0.2 1"/>\n'
                 f'      <geom name="{b}_head" type="sphere" size="{rh:.6g}" '
                 f'pos="0 0 {half:.6g}" mass="{0.75 * o.mass:.6g}" rgba="{rgba}"/>\n')
    return head + geoms + '    </body>'


@dataclass
class CharacterEntry:
    """What the world builder needs to know about one character."""

    prefix: str
    body: Body
    root_pos: Tuple[float, float, float]
    slot: int = 0
    target_positions: Optional[np.ndarray] = None


@dataclass
class WorldParams:
    timestep: float = 0.002
    integrator: str = 'implicitfast'
    solver: str = 'newton'          # MuJoCo constraint solver: pgs, cg or newton
    # Euler: MuJoCo integrates joint damping implicitly unless this is False (eulerdamp flag)
    euler_implicit_damping: bool = True
    gravity: Tuple[float, float, float] = (0.0, 0.0, -9.81)
    floor_friction: float = 1.0
    contact_solref: Tuple[float, float] = (0.02, 1.0)
    hold_solref: Tuple[float, float] = (0.01, 1.0)
    character: CharacterParams = field(default_factory=CharacterParams)


def hold_equality_xml(prefix: str, hand: int, hand_local: np.ndarray, obj: ObjectSpec,
                      hold_solref) -> str:
    names = ElementNames(prefix)
    return (f'    <connect name="{names.hold(obj.name, hand)}" body1="{names.body(hand)}" '
            f'body2="{object_body(obj.name)}" anchor="{fmt(hand_local)}" active="false" '
            f'solref="{fmt(hold_solref)}"/>')


def world_xml(characters: Sequence[CharacterEntry], objects: Sequence[ObjectSpec] = (),
              params: Optional[WorldParams] = None, features: Optional[Dict] = None,
              feature_lift: float = 0.0) -> str:
    """The complete MJCF (string) of a world with ``characters`` and ``objects``; with
    ``features`` ({name: [Geom]}, :mod:`physics_sim.feature_geometry`) their static geometry
    (raised by ``feature_lift``), the hands' grips and contact excludes
    (:mod:`physics_sim.mjcf_features`); without, the model is exactly as before."""
    params = params or WorldParams()
    integ = {'euler': 'Euler', 'implicitfast': 'implicitfast', 'implicit': 'implicit',
             'rk4': 'RK4'}[params.integrator]
    solver = {'pgs': 'PGS', 'cg': 'CG', 'newton': 'Newton'}[params.solver]
    bodies, mocaps, eqs, acts = [], [], [], []
    hand_bodies = []
    names = set()
    for c in characters:
        if c.prefix in names:
            raise ValueError(f'duplicate character prefix {c.prefix}')
        names.add(c.prefix)
        ct, ca = character_bits(c.slot)
        cp = replace(params.character, contype=ct, conaffinity=ca)
        b, m, e = character_xml_parts(c.prefix, c.body, c.root_pos, cp, c.target_positions)
        bodies.append(b)
        if m:
            mocaps.append(m)
        eqs.append(e)
        acts.append(character_actuator_xml(c.prefix, cp))
        if features:
            cn = ElementNames(c.prefix)
            for hand in (HAND_LEFT, HAND_RIGHT):
                k, local = joint_anchor(c.body, hand)
                body = cn.body(SEGMENT_CHILDREN[k])
                hand_bodies.append(body)
                eqs += [grip_equality_xml(c.prefix, hand, body, local, params.hold_solref, t)
                        for t in holdable_bodies(features)]
        for o in objects:
            if o.holdable:
                for hand in (HAND_LEFT, HAND_RIGHT):
                    k, local = joint_anchor(c.body, hand)
                    eqs.append(hold_equality_xml(c.prefix, hand, local, o,
                                                 params.hold_solref))
    onames = [o.name for o in objects]
    if len(set(onames)) != len(onames):
        raise ValueError('duplicate object names')
    objs = [object_xml(o) for o in objects]
    eq_block = '\n'.join(x for x in eqs if x)
    act_block = '\n'.join(x for x in acts if x)
    feat_block = features_xml(features, feature_lift) if features else ''
    excl_block = hand_excludes_xml(features, hand_bodies) if features else ''
    return '\n'.join([
        '<mujoco model="kinect_physics">',
        f'  <option timestep="{params.timestep:.6g}" integrator="{integ}" '
        f'solver="{solver}" gravity="{fmt(params.gravity)}">'
        + '<flag island="disable"' + ('' if params.euler_implicit_damping else ' eulerdamp="disable"')
        + '/></option>',
        f'  <default><geom solref="{fmt(params.contact_solref)}" condim="3" '
        f'contype="{ALL_BITS}" conaffinity="{ALL_BITS}"/></default>',
        '  <worldbody>',
        f'    <geom name="floor" type="plane" size="0 0 0.05" friction="{params.floor_friction:.6g} '
        f'0.005 0.0001" rgba="0.8 0.8 0.8 1"/>',
        f'    <site name="{ORIGIN_SITE}" size="0.01"/>',
        *bodies, *mocaps, *objs, *([feat_block] if feat_block else []),
        '  </worldbody>',
        *(['  <contact>', excl_block, '  </contact>'] if excl_block else []),
        *(['  <equality>', eq_block, '  </equality>'] if eq_block else []),
        *(['  <actuator>', act_block, '  </actuator>'] if act_block else []),
        '</mujoco>'])


__all__ = ['ObjectSpec', 'CharacterEntry', 'WorldParams', 'world_xml', 'object_xml',
           'character_bits', 'OBJECT_KINDS', 'ALL_BITS']
