"""Intentional contacts of the physics character (Ishigaki et al. 2009, Sec. 5): a hand that the
control node reports engaged with a feature (``/control/intention``: engaged effectors and their
features) is connected to the feature where it touches it -- the point of the feature's axis
closest to the simulated hand, when it is within ``grip_reach`` -- and let go when the control
node releases it. Plain functions, no MuJoCo: :class:`physics_sim.world.World` switches the
grips' ``connect`` equalities (``eq_active``) with what :func:`grip_changes` decides.

Only hands grip: feet on the floor or the trampoline stand on the geometry and are pinned by the
foot pins (:mod:`physics_sim.pins`); water has no geometry to hold.
"""
from __future__ import annotations

from typing import Dict, List, Mapping

import numpy as np
from skeleton_core.model import HAND_LEFT, HAND_RIGHT, JOINT_INDEX

from .feature_geometry import closest_on_segment

GRIP_HANDS = (HAND_LEFT, HAND_RIGHT)


def engaged_hands(effectors, features) -> Dict[int, str]:
    """{hand joint: feature} of an intention message's parallel lists (other effectors dropped;
    ``ValueError`` when the lists differ in length)."""
    effectors, features = list(effectors), list(features)
    if len(effectors) != len(features):
        raise ValueError(f'{len(effectors)} engaged effectors but {len(features)} features')
    return {JOINT_INDEX[e]: str(f) for e, f in zip(effectors, features)
            if JOINT_INDEX.get(e) in GRIP_HANDS}


def closest_axis_point(axes, p):
    """(distance, point, body) of the point of ``axes`` [(a, b, body)] closest to ``p``
    ((inf, None, None) for no axes)."""
    p = np.asarray(p, float)
    best = (float('inf'), None, None)
    for a, b, body in axes:
        c = closest_on_segment(p, np.asarray(a, float), np.asarray(b, float))
        dist = float(np.linalg.norm(p - c))
        if dist < best[0]:
            best = (dist, c, body)
    return best


def grip_changes(engaged: Mapping[int, str], held: Mapping[int, tuple],
                 hand_points: Mapping[int, np.ndarray], axes: Mapping[str, List[tuple]],
                 reach: float):
    """What to change so the gripping hands follow ``engaged`` ({hand: feature}).

    ``held``: {hand: (feature, ...)} now; ``hand_points``: the simulated hands' joint points;
    ``axes``: {feature: [(a, b, body)]}, the axes a hand holds now in the world (bars; rope
    segments where they swung to) and the body each belongs to. Returns ``(grab, release)``:
    ``grab`` {hand: (feature, body, world point)} -- the closest point of the feature's axes, only
    when the hand is within ``reach`` of it (otherwise it is tried again next time) --, and
    ``release`` the held hands no longer engaged (or engaged with another feature)."""
    release = [h for h, x in held.items() if engaged.get(h) != x[0]]
    grab = {}
    for h, f in engaged.items():
        if h not in GRIP_HANDS or (h in held and held[h][0] == f):
            continue
        dist, point, body = closest_axis_point(axes.get(f, ()), hand_points[h])
        if point is not None and dist <= reach:   # nothing for water or an unknown feature
            grab[h] = (f, body, point)
    return grab, release


__all__ = ['grip_changes', 'closest_axis_point', 'engaged_hands', 'GRIP_HANDS']
