"""The geometry G of virtual features (Ishigaki et al. 2009, Sec. 4), read from a world YAML file.

One source of truth for both MuJoCo models that contain the features: ``performance_control``
(its world files, ``config/worlds/*.yaml``, whose parser validates every geometry with
:func:`check_geom`) and the physics character here (``feature_world``: only the geometry part of
the same file is read, :func:`load_geometry`). This module sits in ``physics_sim`` because the
physics is below ``performance_control`` in the package layers.

Primitives (world frame, floor at z = 0, metres): ``plane`` (the floor), ``capsule`` (``from``,
``to``, ``radius``), ``box`` (``center``, ``half``; with ``stiffness`` a trampoline on a spring),
``rope`` (a chain of ``segments`` capsules of ``length`` and ``radius`` hanging from ``top``),
``volume`` (water: no collision geometry), ``rock`` (a climbing hold, Ishigaki et al. 2009 Sec. 8.4:
one contact point ``center`` and the ``radius`` within which an effector may hold it; drawn and
collided as a small sphere of ``size``, default 0.04 m).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np
import yaml

GEOM_TYPES = ('plane', 'capsule', 'box', 'rope', 'volume', 'rock')
ROCK_SIZE = 0.04    # m: the radius of a rock's sphere (the hold itself; ``radius`` is its reach)


@dataclass
class Geom:
    """One primitive of a feature's geometry (world frame)."""

    type: str
    data: Dict
    # validated vectors by key (the control step reads them every frame): (source, array)
    _vecs: Dict = field(default_factory=dict, repr=False, compare=False)

    def vec(self, key: str, n: int = 3) -> np.ndarray:
        src = self.data[key]
        hit = self._vecs.get((key, n))
        if hit is not None and hit[0] is src:
            return hit[1].copy()
        v = np.asarray(src, float)
        if v.shape != (n,) or not np.all(np.isfinite(v)):
            raise ValueError(f'{self.type}.{key} must be {n} finite numbers')
        self._vecs[(key, n)] = (src, v.copy())
        return v

    def num(self, key: str, default: Optional[float] = None, positive: bool = True) -> float:
        v = self.data.get(key, default)
        if v is None:
            raise ValueError(f'{self.type} needs {key}')
        v = float(v)
        if not np.isfinite(v) or (positive and v <= 0):
            raise ValueError(f'{self.type}.{key} must be a positive number, got {v}')
        return v


def check_geom(g: Geom) -> None:
    """Raise ``ValueError`` (naming the field) for a primitive that cannot be built."""
    if g.type not in GEOM_TYPES:
        raise ValueError(f'geometry type must be one of {GEOM_TYPES}, got {g.type!r}')
    if g.type == 'capsule':
        a, b = g.vec('from'), g.vec('to')
        g.num('radius')
        if np.linalg.norm(b - a) < 1e-6:
            raise ValueError('capsule from and to coincide')
    elif g.type in ('box', 'volume'):
        g.vec('center')
        if np.any(g.vec('half') <= 0):
            raise ValueError(f'{g.type}.half must be positive')
        if 'stiffness' in g.data:
            for k in ('stiffness', 'damping', 'mass', 'travel'):
                g.num(k)
    elif g.type == 'rock':
        g.vec('center')
        g.num('radius')
        g.num('size', ROCK_SIZE)
    elif g.type == 'rope':
        g.vec('top')
        for k in ('length', 'radius', 'segment_mass'):
            g.num(k)
        g.num('joint_damping', 0.1, positive=False)
        n = int(g.data.get('segments', 0))
        if not 1 <= n <= 50:
            raise ValueError('rope.segments must be in [1, 50]')


def parse_geometry(doc: Dict, path: str = '<dict>') -> Dict[str, List[Geom]]:
    """{feature name: its validated primitives} of a world document (only ``features.*.geometry``
    is read); ``ValueError`` naming the file and the feature."""
    if not isinstance(doc, dict) or not isinstance(doc.get('features'), dict) or not doc['features']:
        raise ValueError(f'{path}: a world needs a non-empty mapping "features"')
    out: Dict[str, List[Geom]] = {}
    for name, fd in doc['features'].items():
        try:
            if not isinstance(fd, dict) or not fd.get('geometry'):
                raise ValueError('needs a non-empty "geometry" list')
            geoms = []
            for gd in fd['geometry']:
                gd = dict(gd)
                g = Geom(str(gd.pop('type', '')), gd)
                check_geom(g)
                geoms.append(g)
        except (ValueError, TypeError, KeyError) as e:
            raise ValueError(f'{path}: feature {name!r}: {e}') from None
        out[str(name)] = geoms
    return out


def load_geometry(path: str) -> Dict[str, List[Geom]]:
    """:func:`parse_geometry` of a world YAML file (a path: the launch file resolves world names)."""
    p = Path(path).expanduser()
    if not p.is_file():
        raise FileNotFoundError(f'feature_world: no file {p}')
    try:
        doc = yaml.safe_load(p.read_text())
    except yaml.YAMLError as e:
        raise ValueError(f'{p}: not valid YAML: {e}') from None
    return parse_geometry(doc, str(p))


def closest_on_segment(p, a, b) -> np.ndarray:
    ab = b - a
    t = float(np.clip(np.dot(p - a, ab) / max(float(ab @ ab), 1e-12), 0.0, 1.0))
    return a + t * ab


__all__ = ['Geom', 'GEOM_TYPES', 'ROCK_SIZE', 'check_geom', 'parse_geometry', 'load_geometry',
           'closest_on_segment']
