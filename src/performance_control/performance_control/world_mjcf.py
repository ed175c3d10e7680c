"""MJCF of a feature world with the simplified character of the dynamic process (Ishigaki et al.
2009, Sec. 5).

The character is the paper's simplified rigid-body model: a COM body (3 slide joints: the global
position x; the orientation follows the user, see :mod:`dynamics`) and one small body per
end-effector (hands, feet; 3 slide joints each) that the intentional-contact springs (Eq. 2-4)
connect to the COM. An intentional contact is a MuJoCo ``connect`` equality between an effector
body and the feature's body (``world`` for static features, a rope segment, the trampoline),
inactive in the model and switched on at run time (``eq_active``) with its anchor set to the
contact point.

Features: static capsules/boxes/planes in the world body; a rope as a chain of capsule bodies with
passive damped ball joints; a trampoline as a box on a vertical slide joint with a spring
(``stiffness``, ``damping``); a water volume as a non-colliding box (the fluid forces are MuJoCo's
``density``/``viscosity``, switched on while the COM is inside it).

Collision bits: features contype 1 / conaffinity 2, the COM and foot bodies contype 2 /
conaffinity 1, hands none: the character touches features, features do not touch each other.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Tuple

import numpy as np
from physics_sim.feature_geometry import ROCK_SIZE
from physics_sim.mjcf_body import fmt

from .features import EFFECTORS, Feature, World

EFFECTOR_RADIUS = {'HandLeft': 0.04, 'HandRight': 0.04, 'FootLeft': 0.04, 'FootRight': 0.04}
# effector masses (kg): hand with forearm, foot with shank (the rest of the body is the COM body)
EFFECTOR_MASS = {'HandLeft': 2.5, 'HandRight': 2.5, 'FootLeft': 5.0, 'FootRight': 5.0}
# the COM body's inertia box (m): a torso-sized box, whose volume gives MuJoCo's buoyancy
TORSO_BOX = (0.35, 0.25, 0.8)
PADDLE_BOX = (0.15, 0.15, 0.15)   # effectors' inertia boxes (the hands' paddles in water)


@dataclass
class Anchor:
    """A body intentional contacts can attach to: ``body`` name and its feature."""

    body: str
    feature: str


def _box_inertia(mass: float, dims) -> Tuple[float, float, float]:
    a, b, c = dims
    return (mass / 12 * (b * b + c * c), mass / 12 * (a * a + c * c), mass / 12 * (a * a + b * b))


def _slides(prefix: str) -> str:
    return ''.join(f'<joint name="{prefix}_{ax}" type="slide" axis="{v}" damping="0"/>'
                   for ax, v in (('x', '1 0 0'), ('y', '0 1 0'), ('z', '0 0 1')))


def feature_xml(f: Feature) -> Tuple[List[str], List[Anchor]]:
    """(worldbody lines, anchor bodies) of one feature."""
    lines, anchors = [], []
    col = 'contype="1" conaffinity="2"'
    static = False
    for i, g in enumerate(f.geoms):
        n = f'f_{f.name}_{i}'
        if g.type == 'plane':
            lines.append(f'<geom name="{n}" type="plane" size="0 0 0.05" {col} '
                         f'rgba="0.8 0.8 0.8 1"/>')
            static = True
        elif g.type == 'capsule':
            lines.append(f'<geom name="{n}" type="capsule" fromto="{fmt(g.vec("from"))} '
                         f'{fmt(g.vec("to"))}" size="{g.num("radius"):.6g}" {col} '
                         f'rgba="0.55 0.55 0.6 1"/>')
            static = True
        elif g.type == 'box' and 'stiffness' not in g.data:
            lines.append(f'<geom name="{n}" type="box" pos="{fmt(g.vec("center"))}" '
                         f'size="{fmt(g.vec("half"))}" {col} rgba="0.5 0.4 0.3 1"/>')
            static = True
        elif g.type == 'box':   # trampoline: a damped spring attached to the floor
            tr = g.num('travel')
            lines.append(
                f'<body name="{n}" pos="{fmt(g.vec("center"))}">'
                f'<joint name="{n}_spring" type="slide" axis="0 0 1" '
                f'stiffness="{g.num("stiffness"):.6g}" damping="{g.num("damping"):.6g}" '
                f'limited="true" range="{-tr:.6g} {tr:.6g}"/>'
                f'<geom name="{n}_geom" type="box" size="{fmt(g.vec("half"))}" '
                f'mass="{g.num("mass"):.6g}" {col} rgba="0.2 0.5 0.9 1"/></body>')
            anchors.append(Anchor(n, f.name))
        elif g.type == 'rock':   # a climbing hold: a point to hold, no collision
            lines.append(f'<geom name="{n}" type="sphere" pos="{fmt(g.vec("center"))}" '
                         f'size="{g.num("size", ROCK_SIZE):.6g}" contype="0" conaffinity="0" '
                         f'rgba="0.6 0.35 0.2 1"/>')
            static = True
        elif g.type == 'volume':
            lines.append(f'<geom name="{n}" type="box" pos="{fmt(g.vec("center"))}" '
                         f'size="{fmt(g.vec("half"))}" contype="0" conaffinity="0" '
                         f'rgba="0.2 0.4 0.9 0.25"/>')
        elif g.type == 'rope':
            seg = g.num('length')
            r = g.num('radius')
            m = g.num('segment_mass')
            damp = g.num('joint_damping', 0.1, positive=False)
            k = int(g.data['segments'])
            open_tags = []
            for s in range(k):
                pos = fmt(g.vec('top')) if s == 0 else f'0 0 {-seg:.6g}'
                open_tags.append(
                    f'<body name="{n}_seg{s}" pos="{pos}"><joint name="{n}_ball{s}" type="ball" '
                    f'damping="{damp:.6g}"/><geom name="{n}_geom{s}" type="capsule" '
                    f'fromto="0 0 0 0 0 {-seg:.6g}" size="{r:.6g}" mass="{m:.6g}" {col} '
                    f'rgba="0.7 0.55 0.3 1"/>')
                anchors.append(Anchor(f'{n}_seg{s}', f.name))
            lines.append(''.join(open_tags) + '</body>' * k)
    if static:
        anchors.insert(0, Anchor('world', f.name))
    return lines, anchors


def world_model_xml(world: World, spawn_com, total_mass: float,
                    effector_offsets: Dict[str, np.ndarray]) -> Tuple[str, List[Anchor]]:
    """(MJCF, anchors) of ``world`` with one character whose COM starts at ``spawn_com`` and
    whose effectors start at COM + ``effector_offsets``."""
    lines, anchors = [], []
    for f in world.features.values():
        fl, fa = feature_xml(f)
        lines += fl
        anchors += [a for a in fa if not any(b.body == a.body for b in anchors)]
    m_eff = sum(EFFECTOR_MASS.values())
    m_com = total_mass - m_eff
    if m_com <= 10.0:
        raise ValueError(f'body mass {total_mass:.1f} kg is too small for the character model')
    com = np.asarray(spawn_com, float)
    ch = [f'<body name="com" pos="{fmt(com)}">{_slides("com")}'
          f'<inertial pos="0 0 0" mass="{m_com:.6g}" '
          f'diaginertia="{fmt(_box_inertia(m_com, TORSO_BOX))}"/>'
          f'<geom name="com_geom" type="sphere" size="0.15" mass="0" contype="2" conaffinity="1" '
          f'rgba="0.85 0.6 0.45 0.6"/></body>']
    for e in EFFECTORS:
        m = EFFECTOR_MASS[e]
        foot = e.startswith('Foot')
        bits = 'contype="2" conaffinity="1"' if foot else 'contype="0" conaffinity="0"'
        ch.append(f'<body name="eff_{e}" pos="{fmt(com + effector_offsets[e])}">{_slides(e)}'
                  f'<inertial pos="0 0 0" mass="{m:.6g}" '
                  f'diaginertia="{fmt(_box_inertia(m, PADDLE_BOX))}"/>'
                  f'<geom name="eff_{e}_geom" type="sphere" size="{EFFECTOR_RADIUS[e]:.6g}" '
                  f'mass="0" {bits} rgba="0.9 0.3 0.3 1"/></body>')
    eqs = []
    for e in EFFECTORS:
        for a in anchors:
            eqs.append(f'<connect name="c_{e}_{a.body}" body1="eff_{e}" body2="{a.body}" '
                       f'anchor="0 0 0" active="false" solref="0.005 1"/>')
    xml = '\n'.join([
        f'<mujoco model="{world.name}">',
        f'  <option timestep="{world.timestep:.6g}" integrator="Euler" density="0" viscosity="0"/>',
        '  <worldbody>', *('    ' + x for x in lines), *('    ' + x for x in ch), '  </worldbody>',
        '  <equality>', *('    ' + x for x in eqs), '  </equality>', '</mujoco>'])
    return xml, anchors


__all__ = ['world_model_xml', 'feature_xml', 'Anchor', 'EFFECTOR_MASS', 'EFFECTOR_RADIUS',
           'TORSO_BOX', 'PADDLE_BOX']
