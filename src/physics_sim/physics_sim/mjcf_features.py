"""MJCF of the virtual features' static geometry in the physics character's world (the world file
named by ``feature_world``, :mod:`physics_sim.feature_geometry`) and of the hands' grips on them.

* every feature is one static body ``feat_<name>`` (no joint: welded to the world) holding its
  static primitives: capsules (bars), a box (the trampoline's surface at rest: static here, it
  springs only in the control node's model); planes (the world already has its floor) and volumes
  (water: no collision) add nothing. A rope is a chain of capsule bodies ``feat_<name>_<i>_seg<s>``
  with passive damped ball joints (the world file's ``segment_mass``, ``joint_damping``), as in
  the control node's model: the physics character swings it. Everything is raised by ``lift``
  (the sensor pose's lift of the targets, so the features sit where the targets composed on them
  arrive).
* ``<exclude>`` pairs between the holdable bodies (bars, rope segments) and each character's hand
  bodies: a held hand is on the bar's axis, as in the control node (the hand closes around it).
* per character, hand and holdable body (the world for bars, each rope segment) a ``connect``
  equality ``<p>grip_<Hand>_<body>``, inactive; its anchor is set when the hand grips
  (:mod:`physics_sim.feature_holds`).
"""
from __future__ import annotations

from typing import Dict, List, Sequence

import numpy as np
from skeleton_core.model import JOINT_NAMES

from .feature_geometry import ROCK_SIZE, Geom
from .mjcf_body import fmt

FEATURE_RGBA = '0.55 0.45 0.3 1'
# armature (kg m^2) of the rope's ball joints: 0.4 kg segments carrying a 75 kg character through a
# stiff grip are unstable without it (QACC blow-up at every step; 0.01 already holds, 0.05 margin)
ROPE_ARMATURE = 0.05


def feature_body(name: str) -> str:
    return f'feat_{name}'


def grip_name(prefix: str, hand: int, body: str = 'world') -> str:
    return f'{prefix}grip_{JOINT_NAMES[hand]}_{body}'


def rope_segment(name: str, i: int, s: int) -> str:
    """Body name of segment ``s`` of the rope that is primitive ``i`` of feature ``name``."""
    return f'feat_{name}_{i}_seg{s}'


def rope_xml(name: str, i: int, g: Geom, lift: float) -> str:
    """A rope: nested capsule bodies on damped ball joints, hanging from ``top``."""
    seg, r = g.num('length'), g.num('radius')
    mass, damp = g.num('segment_mass'), g.num('joint_damping', 0.1, positive=False)
    k = int(g.data['segments'])
    tags = []
    for s in range(k):
        b = rope_segment(name, i, s)
        pos = fmt(g.vec('top') + [0.0, 0.0, lift]) if s == 0 else f'0 0 {-seg:.6g}'
        tags.append(f'    <body name="{b}" pos="{pos}"><joint name="{b}_ball" type="ball" '
                    f'damping="{damp:.6g}" armature="{ROPE_ARMATURE:.6g}"/><geom name="{b}_geom" '
                    f'type="capsule" '
                    f'fromto="0 0 0 0 0 {-seg:.6g}" size="{r:.6g}" mass="{mass:.6g}" '
                    f'rgba="{FEATURE_RGBA}"/>')
    return '\n'.join(tags) + '</body>' * k


def holdable_bodies(features: Dict[str, List[Geom]]) -> List[str]:
    """Bodies a hand can grip: 'world' when there is a bar (the static features are welded to
    it; their grips anchor in the world), and every rope segment."""
    out = []
    for name, geoms in features.items():
        for i, g in enumerate(geoms):
            if g.type in ('capsule', 'rock') and 'world' not in out:
                out.insert(0, 'world')
            elif g.type == 'rope':
                out += [rope_segment(name, i, s) for s in range(int(g.data['segments']))]
    return out


def _capsule(name: str, a, b, r: float) -> str:
    return (f'      <geom name="{name}" type="capsule" fromto="{fmt(np.r_[a, b])}" '
            f'size="{r:.6g}" rgba="{FEATURE_RGBA}"/>')


def geom_xml(name: str, g: Geom, lift: float) -> List[str]:
    """The ``<geom>`` lines of one static primitive (none for planes, volumes and ropes)."""
    up = np.array([0.0, 0.0, lift])
    if g.type == 'capsule':
        return [_capsule(name, g.vec('from') + up, g.vec('to') + up, g.num('radius'))]
    if g.type == 'rock':
        return [f'      <geom name="{name}" type="sphere" pos="{fmt(g.vec("center") + up)}" '
                f'size="{g.num("size", ROCK_SIZE):.6g}" rgba="{FEATURE_RGBA}"/>']
    if g.type == 'box':
        return [f'      <geom name="{name}" type="box" pos="{fmt(g.vec("center") + up)}" '
                f'size="{fmt(g.vec("half"))}" rgba="{FEATURE_RGBA}"/>']
    return []


def features_xml(features: Dict[str, List[Geom]], lift: float = 0.0) -> str:
    """The static ``<body>`` of every feature with collision geometry (inside ``<worldbody>``)."""
    out = []
    for name, geoms in features.items():
        lines = [x for i, g in enumerate(geoms) for x in geom_xml(f'feat_{name}_{i}', g, lift)]
        if lines:
            out += [f'    <body name="{feature_body(name)}">', *lines, '    </body>']
        out += [rope_xml(name, i, g, lift) for i, g in enumerate(geoms) if g.type == 'rope']
    return '\n'.join(out)


def hand_excludes_xml(features: Dict[str, List[Geom]], hand_bodies: Sequence[str]) -> str:
    """``<exclude>`` lines (inside ``<contact>``) between holdable bodies and hand bodies."""
    held = [feature_body(n) for n, geoms in features.items()
            if any(g.type in ('capsule', 'rock') for g in geoms)]
    held += [b for b in holdable_bodies(features) if b != 'world']
    return '\n'.join(f'    <exclude body1="{f}" body2="{b}"/>' for f in held for b in hand_bodies)


def grip_equality_xml(prefix: str, hand: int, body: str, hand_local, solref,
                      target: str = 'world') -> str:
    """An inactive connect of a hand's joint point (``hand_local`` in ``body``) to ``target``."""
    return (f'    <connect name="{grip_name(prefix, hand, target)}" body1="{body}" '
            f'body2="{target}" anchor="{fmt(hand_local)}" active="false" solref="{fmt(solref)}"/>')


__all__ = ['features_xml', 'hand_excludes_xml', 'grip_equality_xml', 'grip_name', 'feature_body',
           'geom_xml', 'holdable_bodies', 'rope_segment', 'rope_xml']
