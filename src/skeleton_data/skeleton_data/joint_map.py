"""Import motion in another skeleton convention through a joint-map file (YAML).

A joint map says how a source's joints (a BVH skeleton) or markers (Plug-in-Gait) become the
model's 20 joints (:data:`skeleton_core.model.JOINT_NAMES`), in metres and REP-103 axes (x
forward, y left, z up)::

    format: kinect_posture.joint_map
    version: 1
    source: bvh                  # bvh | plug_in_gait
    units: cm                    # metres per source unit: a number or m, cm, mm, inch
    axes: [z, x, y]              # REP-103 x, y, z = these source axes (a '-' flips one)
    strip_prefix: 'mixamorig:'   # optional (bvh): removed from source joint names
    joints:                      # bvh: every model joint
      HipCenter: Hips            #   one source joint ('Joint/End' = its End Site),
      ShoulderCenter: [LeftArm, RightArm]    # the mean of several,
      HandLeft: {LeftHand: 0.5, LeftHandMiddle1: 0.5}   # or a weighted sum (weights sum to 1)
    markers: [LFHD, ...]         # plug_in_gait: the source's marker column order

Plug-in-Gait joint centres come from :func:`skeleton_data.vicon.joint_centres` (computed in the
source frame and units converted to metres first: its rules are in metres). Built-in maps:
``cmu_cgspeed`` (the CMU BVH files in ``../shared/mocap/cmu``), ``generic_bvh`` (Mixamo-style
names), ``plug_in_gait`` (:func:`builtin`). :func:`load` refuses a malformed map with one line
(:class:`JointMapError`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Tuple

import numpy as np

from skeleton_core.model import JOINT_NAMES, NUM_JOINTS

FORMAT = 'kinect_posture.joint_map'
SOURCES = ('bvh', 'plug_in_gait')
UNITS = {'m': 1.0, 'cm': 0.01, 'mm': 0.001, 'inch': 0.0254}
BUILTIN_DIR = Path(__file__).resolve().parent / 'joint_maps'


class JointMapError(ValueError):
    """A joint map that cannot be used (one line)."""


@dataclass
class JointMap:
    source: str
    scale: float                               # metres per source unit
    axes: np.ndarray                           # (3, 3): rep = axes @ source
    joints: Dict[str, List[Tuple[str, float]]] = field(default_factory=dict)
    markers: List[str] = field(default_factory=list)
    strip_prefix: str = ''
    name: str = ''

    def to_rep103(self, points: np.ndarray) -> np.ndarray:
        """Source-frame points (..., 3) in source units -> metres, REP-103 axes."""
        return (np.asarray(points, float) @ self.axes.T) * self.scale


def _axes(spec, where: str) -> np.ndarray:
    if not isinstance(spec, (list, tuple)) or len(spec) != 3:
        raise JointMapError(f'{where}: axes must list three source axes like [z, x, y]')
    m = np.zeros((3, 3))
    for row, a in enumerate(spec):
        a = str(a).strip().lower()
        sign = -1.0 if a.startswith('-') else 1.0
        a = a.lstrip('+-')
        if a not in ('x', 'y', 'z'):
            raise JointMapError(f'{where}: axis {spec[row]!r} is not x, y or z (with an optional -)')
        m[row, 'xyz'.index(a)] = sign
    if abs(abs(np.linalg.det(m)) - 1.0) > 1e-9:
        raise JointMapError(f'{where}: axes {list(spec)} repeat a source axis')
    if np.linalg.det(m) < 0:
        raise JointMapError(f'{where}: axes {list(spec)} mirror the skeleton (left-handed); '
                            'flip one axis')
    return m


def parse(data, name: str = '<joint map>') -> JointMap:
    """A :class:`JointMap` from the YAML's content (a dict); :class:`JointMapError` if invalid."""
    if not isinstance(data, dict):
        raise JointMapError(f'{name}: expected a mapping at the top level')
    if data.get('format') != FORMAT or data.get('version') != 1:
        raise JointMapError(f'{name}: not a version 1 {FORMAT} file')
    source = data.get('source')
    if source not in SOURCES:
        raise JointMapError(f'{name}: source must be one of {", ".join(SOURCES)}, got {source!r}')
    units = data.get('units')
    if isinstance(units, str):
        if units not in UNITS:
            raise JointMapError(f'{name}: units {units!r} is not a number or one of '
                                f'{", ".join(UNITS)}')
        scale = UNITS[units]
    elif isinstance(units, (int, float)) and not isinstance(units, bool) and units > 0:
        scale = float(units)
    else:
        raise JointMapError(f'{name}: units must be a positive number (metres per unit) or a name')
    jm = JointMap(source=source, scale=scale, axes=_axes(data.get('axes'), name), name=name,
                  strip_prefix=str(data.get('strip_prefix') or ''))
    if source == 'plug_in_gait':
        from .vicon import MARKERS
        markers = data.get('markers')
        if not isinstance(markers, list) or not all(isinstance(m, str) for m in markers):
            raise JointMapError(f'{name}: markers must list the source\'s marker names in order')
        missing = [m for m in MARKERS if m not in markers]
        if missing:
            raise JointMapError(f'{name}: Plug-in-Gait markers missing: {", ".join(missing)}')
        jm.markers = list(markers)
        return jm
    joints = data.get('joints')
    if not isinstance(joints, dict):
        raise JointMapError(f'{name}: joints must map every model joint to source joints')
    unknown = sorted(set(joints) - set(JOINT_NAMES))
    missing = [j for j in JOINT_NAMES if j not in joints]
    if unknown or missing:
        raise JointMapError(f'{name}: ' + '; '.join(
            ([f'unknown model joint(s) {", ".join(unknown)}'] if unknown else [])
            + ([f'model joint(s) not mapped: {", ".join(missing)}'] if missing else [])))
    for j, spec in joints.items():
        if isinstance(spec, str):
            terms = [(spec, 1.0)]
        elif isinstance(spec, list) and spec and all(isinstance(s, str) for s in spec):
            terms = [(s, 1.0 / len(spec)) for s in spec]
        elif isinstance(spec, dict) and spec and all(
                isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool)
                for k, v in spec.items()):
            terms = [(k, float(v)) for k, v in spec.items()]
            if abs(sum(v for _, v in terms) - 1.0) > 1e-6:
                raise JointMapError(f'{name}: the weights of {j} sum to '
                                    f'{sum(v for _, v in terms):g}, not 1')
        else:
            raise JointMapError(f'{name}: {j} must be a source joint, a list of them or '
                                '{joint: weight}')
        jm.joints[j] = terms
    return jm


def load(path) -> JointMap:
    """Read and validate a joint-map YAML (a file, or a built-in map's name)."""
    import yaml
    p = Path(path)
    if not p.suffix and (BUILTIN_DIR / f'{p}.yaml').is_file():
        p = BUILTIN_DIR / f'{p}.yaml'
    if not p.is_file():
        raise JointMapError(f'joint map {str(p)!r} does not exist (built-in: '
                            f'{", ".join(builtin_names())})')
    try:
        data = yaml.safe_load(p.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as e:
        raise JointMapError(f'joint map {str(p)!r} is not valid YAML: '
                            f'{str(e).splitlines()[0]}') from e
    return parse(data, str(p))


def builtin_names() -> List[str]:
    return sorted(p.stem for p in BUILTIN_DIR.glob('*.yaml'))


def builtin(name: str) -> JointMap:
    return load(BUILTIN_DIR / f'{name}.yaml')


def from_bvh(bvh, jm: JointMap) -> np.ndarray:
    """(F, 20, 3) model joints (m, REP-103) of a parsed BVH (:func:`skeleton_data.bvh.parse_bvh`)."""
    if jm.source != 'bvh':
        raise JointMapError(f'{jm.name}: a {jm.source} map cannot import a BVH file')
    names = [n[len(jm.strip_prefix):] if jm.strip_prefix and n.startswith(jm.strip_prefix) else n
             for n in bvh.names]
    pos, _, ends = bvh.forward_kinematics()
    out = np.zeros((bvh.num_frames, NUM_JOINTS, 3))
    for j, name in enumerate(JOINT_NAMES):
        for src, w in jm.joints[name]:
            end = src.endswith('/End')
            base = src[:-4] if end else src
            if base not in names:
                raise JointMapError(f'{jm.name}: {name} needs source joint {base!r}, not in '
                                    f'{bvh.path}')
            k = names.index(base)
            if end:
                sites = [i for i, (p, _) in enumerate(bvh.end_sites) if p == k]
                if not sites:
                    raise JointMapError(f'{jm.name}: {base!r} has no End Site in {bvh.path}')
                out[:, j] += w * ends[:, sites[0]]
            else:
                out[:, j] += w * pos[:, k]
    return jm.to_rep103(out)


def from_markers(markers: np.ndarray, jm: JointMap) -> np.ndarray:
    """(F, 20, 3) model joints (m, REP-103) from (F, M, 3) marker positions in source units and
    columns (``jm.markers`` order); NaN where a needed marker is NaN."""
    from .vicon import MARKERS, joint_centres
    if jm.source != 'plug_in_gait':
        raise JointMapError(f'{jm.name}: a {jm.source} map cannot import markers')
    m = np.asarray(markers, float)
    if m.ndim != 3 or m.shape[1:] != (len(jm.markers), 3):
        raise JointMapError(f'{jm.name}: expected (frames, {len(jm.markers)}, 3) markers, got '
                            f'{m.shape}')
    pig = m[:, [jm.markers.index(n) for n in MARKERS]]
    return joint_centres(jm.to_rep103(pig))


__all__ = ['JointMap', 'JointMapError', 'parse', 'load', 'builtin', 'builtin_names', 'from_bvh',
           'from_markers']
