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

from typing import Dict, List, Mapping, Tuple

import numpy as np
from skeleton_core.model import HAND_LEFT, HAND_RIGHT, JOINT_INDEX

from .feature_geometry import Geom, closest_hold_point

GRIP_HANDS = (HAND_LEFT, HAND_RIGHT)


def engaged_hands(effectors, features) -> Dict[int, str]:
    """{hand joint: feature} of an intention message's parallel lists (other effectors dropped;
    ``ValueError`` when the lists differ in length)."""
    effectors, features = list(effectors), list(features)
    if len(effectors) != len(features):
        raise ValueError(f'{len(effectors)} engaged effectors but {len(features)} features')
    return {JOINT_INDEX[e]: str(f) for e, f in zip(effectors, features)
            if JOINT_INDEX.get(e) in GRIP_HANDS}


def grip_changes(engaged: Mapping[int, str], held: Mapping[int, Tuple[str, np.ndarray]],
                 hand_points: Mapping[int, np.ndarray], features: Mapping[str, List[Geom]],
                 lift: float, reach: float):
    """What to change so the held hands follow ``engaged`` ({hand: feature}).

    ``held``: {hand: (feature, world point)} now; ``hand_points``: the simulated hands' joint
    points; ``features``: the world's geometry, raised by ``lift``. Returns ``(grab, release)``:
    ``grab`` {hand: (feature, point)} -- the closest point of the feature's holdable axes, only
    when the hand is within ``reach`` of it (otherwise it is tried again next time) --, and
    ``release`` the held hands no longer engaged (or engaged with another feature)."""
    release = [h for h, (f, _) in held.items() if engaged.get(h) != f]
    grab = {}
    for h, f in engaged.items():
        if h not in GRIP_HANDS or (h in held and held[h][0] == f):
            continue
        geoms = features.get(f)
        if not geoms:
            continue                      # an unknown feature, or one without geometry (water)
        dist, point = closest_hold_point(geoms, hand_points[h], lift)
        if point is not None and dist <= reach:
            grab[h] = (f, point)
    return grab, release


__all__ = ['grip_changes', 'engaged_hands', 'GRIP_HANDS']
