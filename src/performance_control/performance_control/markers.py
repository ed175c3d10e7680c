"""RViz markers of a feature world and of the intentional contacts (visualization_msgs, built
from plain data so the node stays thin). World coordinates are converted to the output frame by
the caller's ``to_frame`` (the sensor frame of the skeletons)."""
from __future__ import annotations

from typing import Callable, Dict, List, Optional, Tuple

import numpy as np
from physics_sim.feature_geometry import ROCK_SIZE

from .composition import Obstacles
from .features import World

Shape = Tuple[str, np.ndarray, np.ndarray, np.ndarray, Tuple[float, float, float, float], str]


def _quat_z_to(v: np.ndarray) -> np.ndarray:
    """Quaternion (x y z w) rotating +z onto ``v``."""
    z = np.array([0.0, 0.0, 1.0])
    v = v / max(np.linalg.norm(v), 1e-12)
    c = np.cross(z, v)
    w = 1.0 + float(z @ v)
    if w < 1e-9:
        return np.array([1.0, 0.0, 0.0, 0.0])
    q = np.array([c[0], c[1], c[2], w])
    return q / np.linalg.norm(q)


def world_shapes(world: World, obstacles: Optional[Obstacles] = None) -> List[Shape]:
    """(type 'cylinder'|'cube'|'sphere', position, orientation xyzw, scale, rgba, name) of every
    feature's geometry; the rope and trampoline at their simulated pose when ``obstacles`` is
    given (as :class:`Obstacles` holds them)."""
    out: List[Shape] = []
    ident = np.array([0.0, 0.0, 0.0, 1.0])
    for f in world.features.values():
        for g in f.geoms:
            if g.type == 'capsule':
                a, b, r = g.vec('from'), g.vec('to'), g.num('radius')
                out.append(('cylinder', 0.5 * (a + b), _quat_z_to(b - a),
                            np.array([2 * r, 2 * r, np.linalg.norm(b - a)]),
                            (0.55, 0.55, 0.6, 1.0), f.name))
            elif g.type in ('box', 'volume'):
                rgba = (0.2, 0.4, 0.9, 0.25) if g.type == 'volume' else (0.2, 0.5, 0.9, 1.0)
                out.append(('cube', g.vec('center'), ident, 2 * g.vec('half'), rgba, f.name))
            elif g.type == 'rock':
                d = 2 * g.num('size', ROCK_SIZE)
                out.append(('sphere', g.vec('center'), ident, np.array([d, d, d]),
                            (0.6, 0.35, 0.2, 1.0), f.name))
            elif g.type == 'plane':
                out.append(('cube', np.array([0.0, 0.0, -0.005]), ident,
                            np.array([20.0, 20.0, 0.01]), (0.8, 0.8, 0.8, 0.3), f.name))
            elif g.type == 'rope' and obstacles is None:
                top, seg, r = g.vec('top'), g.num('length'), g.num('radius')
                k = int(g.data['segments'])
                out.append(('cylinder', top - [0, 0, 0.5 * k * seg], ident,
                            np.array([2 * r, 2 * r, k * seg]), (0.7, 0.55, 0.3, 1.0), f.name))
    if obstacles is not None:
        for a, b, r, name in obstacles.capsules:
            if world.features[name].kind == 'rope':
                out.append(('cylinder', 0.5 * (a + b), _quat_z_to(b - a),
                            np.array([2 * r, 2 * r, np.linalg.norm(b - a)]),
                            (0.7, 0.55, 0.3, 1.0), name))
        for c, h, name in obstacles.boxes:
            if world.features[name].kind == 'trampoline':
                for i, s in enumerate(out):
                    if s[5] == name:
                        out[i] = ('cube', c, ident, 2 * h, s[4], name)
    return out


def contact_shapes(points: Dict[str, np.ndarray]) -> List[Shape]:
    return [('sphere', np.asarray(p, float), np.array([0.0, 0.0, 0.0, 1.0]),
             np.full(3, 0.1), (1.0, 0.2, 0.2, 0.9), e) for e, p in points.items()]


def to_marker_array(shapes: List[Shape], ns: str, frame_id: str, stamp,
                    to_frame: Callable[[np.ndarray], np.ndarray], quat_to_frame=None,
                    id0: int = 0):
    """visualization_msgs/MarkerArray with a DELETEALL of ``ns`` first."""
    from skeleton_core.rosnode import fill_marker
    from visualization_msgs.msg import Marker, MarkerArray
    out = MarkerArray()
    clear = Marker()
    clear.action = Marker.DELETEALL
    clear.ns = ns
    out.markers.append(clear)
    types = {'cylinder': Marker.CYLINDER, 'cube': Marker.CUBE, 'sphere': Marker.SPHERE}
    for i, (kind, pos, quat, scale, rgba, name) in enumerate(shapes):
        m = Marker()
        m.header.frame_id = frame_id
        m.header.stamp = stamp
        m.ns = ns
        m.id = id0 + i
        m.type = types[kind]
        m.action = Marker.ADD
        fill_marker(m, to_frame(np.asarray(pos, float)),
                    quat if quat_to_frame is None else quat_to_frame(quat), scale, rgba, name)
        out.markers.append(m)
    return out


__all__ = ['world_shapes', 'contact_shapes', 'to_marker_array']
