"""Virtual features as data (Ishigaki et al. 2009, Sec. 4 and 8): one YAML file per world.

A feature has a geometry G (MuJoCo geoms), engage conditions C, an optional example motion Q and
dynamic parameters D. :func:`load_world` reads and validates a world file (``config/worlds/*.yaml``
of this package, or any path); every error names the file and the feature.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np
import yaml
from physics_sim.feature_geometry import GEOM_TYPES, Geom  # noqa: F401 -- re-exported
from physics_sim.feature_geometry import parse_geometry
from skeleton_core.model import JOINT_INDEX

EFFECTORS = ('HandLeft', 'HandRight', 'FootLeft', 'FootRight')
DYNAMICS_DEFAULTS = {'ks': 9000.0, 'kd': 900.0, 'ka': 3000.0, 'kad': 600.0, 'kb': 0.0,
                     'kbd': 80.0}


class WorldError(ValueError):
    """A world file that cannot be used (the message names the file and the feature)."""


@dataclass
class Engage:
    """Engage conditions C (Sec. 4, 8): an effector may hold the feature when it is within
    ``distance`` of the geometry, the user's hand is above ``hand_above`` (a joint name; the
    paper's "hand closed") and the effector is slower than ``max_speed``; ``com_inside``: the
    feature engages when the character's COM is inside its volume; ``regrab``: while the other
    hand holds, a hand the user raises faster than the controller's ``regrab_speed`` lets go (and
    grabs again higher up: hand over hand)."""

    effectors: Tuple[str, ...] = ()
    distance: float = 0.1
    hand_above: Optional[str] = None
    max_speed: float = float('inf')
    com_inside: bool = False
    regrab: bool = False     # a held hand the user moves up fast lets go to grab higher (climb)


@dataclass
class Example:
    """Example motion Q: a generator in :mod:`performance_control.examples` (with its params) or
    a BVH file; ``effectors``: the unconstrained end-effectors compared (Sec. 6.1);
    ``max_change_share``: the largest share of the user's recent hand displacement outside the
    directions the example moves in (a one-handed punch against a two-handed stroke; 1 = off).
    ``bvh`` (optionally cut to ``frames``) is the real mocap example where the file exists (a
    relative path is looked up next to the world file, then in ``../shared``); without it the
    ``generator`` makes one, so a world runs without ``../shared``. ``own_posture`` (a cyclic
    example: the walk): Eq. 5's e1 about the user's own mean posture (low-passed over the
    example's ``period``) instead of the example's mean, so that a user's constant posture
    offset -- elbows bent more, shoulders flexed -- is a style, not another motion."""

    generator: str = ''
    params: Dict = field(default_factory=dict)
    effectors: Tuple[str, ...] = ('HandLeft', 'HandRight')
    components: int = 3
    bvh: str = ''
    max_change_share: float = 1.0   # the recognizer's change-share gate for this feature (1 = off)
    frames: Tuple[Tuple[int, int], ...] = ()   # [first, stop) segments of the BVH file used as Q
    own_posture: bool = False       # e1 about the user's own mean posture (a cyclic example)


@dataclass
class Feature:
    name: str
    geoms: List[Geom]
    engage: Engage
    example: Optional[Example]
    dynamics: Dict[str, float]
    start: Optional[Dict] = None

    @property
    def kind(self) -> str:
        """'floor' (a plane), 'rope', 'trampoline' (a box on a spring), 'water' (a volume),
        'rocks' (climbing holds: points with a reach radius) or 'bars' (static capsules /
        boxes)."""
        types = {g.type for g in self.geoms}
        if 'rock' in types:
            return 'rocks'
        if 'rope' in types:
            return 'rope'
        if 'volume' in types:
            return 'water'
        if 'plane' in types:
            return 'floor'
        if any(g.type == 'box' and 'stiffness' in g.data for g in self.geoms):
            return 'trampoline'
        return 'bars'


@dataclass
class World:
    name: str
    path: str
    features: Dict[str, Feature]
    spawn: Tuple[float, float] = (0.0, 0.0)
    timestep: float = 0.002

    def with_example(self) -> List[Feature]:
        return [f for f in self.features.values() if f.example is not None]


def worlds_dir() -> Path:
    """The installed ``share/performance_control/config/worlds`` (or the source tree's)."""
    try:
        from ament_index_python.packages import get_package_share_directory
        p = Path(get_package_share_directory('performance_control')) / 'config' / 'worlds'
        if p.is_dir():
            return p
    except Exception:  # noqa: BLE001 -- not installed: the source tree
        pass
    return Path(__file__).resolve().parent.parent / 'config' / 'worlds'


def world_path(name_or_path: str) -> Path:
    """A world name (``playground``) in :func:`worlds_dir`, or a path to a YAML file."""
    p = Path(os.path.expanduser(name_or_path))
    if p.suffix in ('.yaml', '.yml') or os.sep in name_or_path:
        if not p.is_file():
            raise FileNotFoundError(f'world file {p} does not exist')
        return p
    p = worlds_dir() / f'{name_or_path}.yaml'
    if not p.is_file():
        names = sorted(x.stem for x in worlds_dir().glob('*.yaml'))
        raise FileNotFoundError(f'no world {name_or_path!r} (available: {names})')
    return p


def _frames(v) -> Tuple[Tuple[int, int], ...]:
    """``example.frames``: [first, stop) or a list of them (segments of the BVH file, 30 fps)."""
    if not v:
        return ()
    v = list(v)
    ranges = [v] if not isinstance(v[0], (list, tuple)) else v
    out = []
    for r in ranges:
        if len(r) != 2 or not 0 <= int(r[0]) < int(r[1]):
            raise ValueError('example.frames must be [first, stop) (or a list of them), '
                             'first < stop')
        out.append((int(r[0]), int(r[1])))
    return tuple(out)


def parse_world(doc: Dict, path: str = '<dict>') -> World:
    try:  # the geometry, as the physics character's world reads it
        geometry = parse_geometry(doc, path)
    except ValueError as e:
        raise WorldError(str(e)) from None
    feats: Dict[str, Feature] = {}
    for name, fd in doc['features'].items():
        where = f'{path}: feature {name!r}'
        geoms = geometry[str(name)]
        try:
            ed = dict(fd.get('engage') or {})
            eff = tuple(ed.get('effectors', ()))
            for e in eff:
                if e not in EFFECTORS:
                    raise ValueError(f'engage effector {e!r} is not one of {EFFECTORS}')
            above = ed.get('hand_above')
            if above is not None and above not in JOINT_INDEX:
                raise ValueError(f'engage.hand_above {above!r} is not a joint name')
            engage = Engage(eff, float(ed.get('distance', 0.1)), above,
                            float(ed.get('max_speed', float('inf'))), bool(ed.get('com_inside', False)),
                            bool(ed.get('regrab', False)))
            if not engage.distance > 0:
                raise ValueError('engage.distance must be positive')
            ex = None
            if fd.get('example'):
                xd = dict(fd['example'])
                ex = Example(str(xd.get('generator', '')), dict(xd.get('params') or {}),
                             tuple(xd.get('effectors', ('HandLeft', 'HandRight'))),
                             int(xd.get('components', 3)), str(xd.get('bvh', '')),
                             float(xd.get('max_change_share', 1.0)),
                             _frames(xd.get('frames', ())), bool(xd.get('own_posture', False)))
                if not ex.generator and not ex.bvh:
                    raise ValueError('example needs a generator or a bvh file')
                for e in ex.effectors:
                    if e not in JOINT_INDEX:
                        raise ValueError(f'example effector {e!r} is not a joint name')
                if not 0.0 < ex.max_change_share <= 1.0:
                    raise ValueError('example.max_change_share must be in (0, 1]')
                if not 1 <= ex.components <= 12:
                    raise ValueError('example.components must be in [1, 12]')
            dyn = dict(DYNAMICS_DEFAULTS)
            for k, v in (fd.get('dynamics') or {}).items():
                v = float(v)
                if not np.isfinite(v) or v < 0:
                    raise ValueError(f'dynamics.{k} must be a finite number >= 0')
                dyn[k] = v
            feats[str(name)] = Feature(str(name), geoms, engage, ex, dyn, fd.get('start'))
        except (ValueError, TypeError, KeyError) as e:
            raise WorldError(f'{where}: {e}') from None
    spawn = tuple(float(x) for x in doc.get('spawn', (0.0, 0.0)))
    if len(spawn) != 2:
        raise WorldError(f'{path}: spawn must be [x, y]')
    ts = float(doc.get('timestep', 0.002))
    if not 0.0005 <= ts <= 0.01:
        raise WorldError(f'{path}: timestep must be in [0.0005, 0.01] s')
    return World(str(doc.get('name', Path(path).stem)), str(path), feats, spawn, ts)


def load_world(name_or_path: str = 'playground') -> World:
    """Read and validate a world (a name in :func:`worlds_dir` or a YAML path)."""
    p = world_path(name_or_path)
    try:
        doc = yaml.safe_load(p.read_text())
    except yaml.YAMLError as e:
        raise WorldError(f'{p}: not valid YAML: {e}') from None
    return parse_world(doc, str(p))


__all__ = ['World', 'Feature', 'Geom', 'Engage', 'Example', 'WorldError', 'load_world',
           'parse_world', 'world_path', 'worlds_dir', 'EFFECTORS']
