"""MJCF of the virtual features' static geometry in the physics character's world (the world file
named by ``feature_world``, :mod:`physics_sim.feature_geometry`) and of the hands' grips on them.

* every feature is one static body ``feat_<name>`` (no joint: welded to the world) holding its
  primitives: capsules (bars), the rope as a chain of capsules **at rest** (hanging straight down:
  static here, it swings only in the control node's model), a box (the trampoline's surface at
  rest, static); planes (the world already has its floor) and volumes (water: no collision) add
  nothing. Everything is raised by ``lift`` (the sensor pose's lift of the targets, so the
  features sit where the targets composed on them arrive).
* ``<exclude>`` pairs between the holdable features (capsules, ropes) and each character's hand
  bodies: a held hand is on the bar's axis, as in the control node (the hand closes around it).
* per character and hand a ``connect`` equality ``<p>grip_<Hand>`` to the world, inactive; its
  world anchor is set when the hand holds a feature (:mod:`physics_sim.feature_holds`).
"""
from __future__ import annotations

from typing import Dict, List, Sequence

import numpy as np
from skeleton_core.model import JOINT_NAMES

from .feature_geometry import HOLDABLE_TYPES, Geom
from .mjcf_body import fmt

FEATURE_RGBA = '0.55 0.45 0.3 1'


def feature_body(name: str) -> str:
    return f'feat_{name}'


def grip_name(prefix: str, hand: int) -> str:
    return f'{prefix}grip_{JOINT_NAMES[hand]}'


def _capsule(name: str, a, b, r: float) -> str:
    return (f'      <geom name="{name}" type="capsule" fromto="{fmt(np.r_[a, b])}" '
            f'size="{r:.6g}" rgba="{FEATURE_RGBA}"/>')


def geom_xml(name: str, g: Geom, lift: float) -> List[str]:
    """The ``<geom>`` lines of one primitive (none for planes and volumes)."""
    up = np.array([0.0, 0.0, lift])
    if g.type == 'capsule':
        return [_capsule(name, g.vec('from') + up, g.vec('to') + up, g.num('radius'))]
    if g.type == 'rope':
        top, seg, r = g.vec('top') + up, g.num('length'), g.num('radius')
        n = int(g.data['segments'])
        return [_capsule(f'{name}_seg{s}', top - [0, 0, s * seg], top - [0, 0, (s + 1) * seg], r)
                for s in range(n)]
    if g.type == 'box':
        return [f'      <geom name="{name}" type="box" pos="{fmt(g.vec("center") + up)}" '
                f'size="{fmt(g.vec("half"))}" rgba="{FEATURE_RGBA}"/>']
    return []


def holdable(geoms: Sequence[Geom]) -> bool:
    return any(g.type in HOLDABLE_TYPES for g in geoms)


def features_xml(features: Dict[str, List[Geom]], lift: float = 0.0) -> str:
    """The static ``<body>`` of every feature with collision geometry (inside ``<worldbody>``)."""
    out = []
    for name, geoms in features.items():
        lines = [x for i, g in enumerate(geoms) for x in geom_xml(f'feat_{name}_{i}', g, lift)]
        if lines:
            out += [f'    <body name="{feature_body(name)}">', *lines, '    </body>']
    return '\n'.join(out)


def hand_excludes_xml(features: Dict[str, List[Geom]], hand_bodies: Sequence[str]) -> str:
    """``<exclude>`` lines (inside ``<contact>``) between holdable features and hand bodies."""
    return '\n'.join(f'    <exclude body1="{feature_body(n)}" body2="{b}"/>'
                     for n, geoms in features.items() if holdable(geoms) for b in hand_bodies)


def grip_equality_xml(prefix: str, hand: int, body: str, hand_local, solref) -> str:
    """An inactive connect of a hand's joint point (``hand_local`` in ``body``) to the world."""
    return (f'    <connect name="{grip_name(prefix, hand)}" body1="{body}" body2="world" '
            f'anchor="{fmt(hand_local)}" active="false" solref="{fmt(solref)}"/>')


__all__ = ['features_xml', 'hand_excludes_xml', 'grip_equality_xml', 'grip_name', 'feature_body',
           'geom_xml', 'holdable']
