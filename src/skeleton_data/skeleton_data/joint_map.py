"""Joint maps: import mocap in another skeleton convention onto the 20 Kinect v1 joints.

A joint map is a YAML file (``config/joint_maps/*.yaml``) that says, for one capture convention,
where every joint of :mod:`skeleton_core.model` lies on the source skeleton, which source axes are
up and forward, and the source's length unit. Two source kinds (``format``):

``bvh`` — a BVH hierarchy (:mod:`skeleton_data.bvh`)::

    format: bvh
    axes: {up: +Y, forward: +Z, handedness: right}   # source axis the body's up / facing is
    units: cm                  # mm | cm | m | inches; optional ``scale`` (units per file unit)
    strip_namespace: true      # 'mixamorig:Hips' -> 'Hips' (optional)
    drop_first_frame: false    # cgspeed CMU files start with a synthetic T-pose frame
    zero_rotations: []         # source joints whose rotation channels are set to 0 (not captured)
    joints:                    # model joint <- source point(s)
      HipCenter: Hips                               # one source joint
      ShoulderCenter: {LeftArm: 0.5, RightArm: 0.5} # weighted source points (weights sum to 1)
      HandRight: {RightHand: 1.35, RightForeArm: -0.35}  # a negative weight extrapolates: 35 %
                                                    # of the forearm past the wrist
      Head: {Head: 0.5, Head/End: 0.5}              # 'J/End' = the End Site below joint J
      HandLeft: [LeftHandMiddle1, LeftHand/End]     # alternatives: the first the file has
    orientation:               # optional: model joint <- source bone whose global rotation
      ElbowLeft: LeftArm       # orients the segment ending at that joint (else from positions)

``markers`` — a marker trajectory file, joint centres by the Plug-in-Gait rules of
:mod:`skeleton_data.vicon` (the only ``marker_set`` so far: ``plug_in_gait``)::

    format: markers
    marker_set: plug_in_gait
    axes: {up: +Z, forward: +X, handedness: right}
    units: mm
    frame_rate: 100
    columns: [LFHD, RFHD, ...]  # the file's markers in column order, (x, y, z) each
    markers: {L_ASIS: LASI}     # optional: file label -> Plug-in-Gait marker (else identical)
    subject: {knee_width: 0.10} # optional: vicon.SubjectParams fields (m)

Axes: REP-103 (x forward, y left, z up) is ``x = forward``, ``z = up`` and ``y = up x forward`` for
a right-handed source (``-(up x forward)`` for a left-handed one, e.g. Unity's). ``forward`` is
the direction the body faces in the source's rest pose; the database removes the heading anyway,
so it matters for left/right only through the handedness.

Positions and orientations follow :mod:`skeleton_data.mocap` (orientation of the segment ending at
joint j, identity = standard T-pose facing +x). A joint with an ``orientation`` bone takes that
bone's global rotation, corrected once for the rest-pose direction and swung onto the actual segment
(the CMU rule); without one the orientation comes from positions (:func:`orientations_from_positions`).

Zero-length segments: an alternative whose point lies on its parent model joint in the source's
rest pose (an End Site at offset 0, a joint mapped onto its parent: the segment would have no
direction) is passed over for the next one; when none is left the map is refused with a line
naming the joint and the fix (an extrapolating point, e.g. the hand 35 % of the forearm past the
wrist, or a head centre above the neck: ``Head: {Head: 1.5, Neck: -0.5}``).

:func:`segment_table` prints a mapped clip's segment lengths against the standard body
(``build_db --check``).

Errors: :class:`JointMapError`, one line ``<file>:<line>: <key>: <reason>``, for unreadable YAML,
unknown or missing keys, unknown model joints, bad weights, axes or units; and (at import) for a
source joint the file does not have.
"""
from __future__ import annotations

import gzip
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Optional, Tuple

import numpy as np
import yaml

from skeleton_core.geometry import quat_multiply, quat_rotate
from skeleton_core.model import (HIP_CENTER, HIP_LEFT, HIP_RIGHT, JOINT_INDEX, JOINT_NAMES,
                                 NUM_JOINTS, PARENTS, SPINE, standard_body)

from . import vicon
from .bvh import Bvh

__all__ = ['JointMap', 'JointMapError', 'load_joint_map', 'parse_joint_map', 'maps_dir',
           'builtin_map', 'axes_matrix', 'bvh_frames', 'marker_joint_centres', 'read_markers',
           'orientations_from_positions', 'rest_directions', 'min_rotation', 'min_rotation_batch',
           'UNITS', 'segment_check', 'segment_table']

UNITS: Dict[str, float] = {'mm': 0.001, 'cm': 0.01, 'm': 1.0, 'inches': 0.0254}
FORMATS = ('bvh', 'markers')
MARKER_SETS = ('plug_in_gait',)
_KEYS = {
    'bvh': {'name', 'description', 'format', 'axes', 'units', 'scale', 'strip_namespace',
            'drop_first_frame', 'zero_rotations', 'joints', 'orientation', 'motion_class'},
    'markers': {'name', 'description', 'format', 'marker_set', 'axes', 'units', 'scale',
                'frame_rate', 'columns', 'markers', 'subject', 'motion_class'},
}
_AXIS_RE = re.compile(r'^([+-]?)([XYZxyz])$')
# a point may lie beyond its source joints (negative weights), but not absurdly far
MAX_WEIGHT = 5.0
# a model segment shorter than this in the source's rest pose is a zero-length segment
# (an End Site at offset 0, a joint mapped onto its parent): that alternative is not used
MIN_SEGMENT_M = 0.01


class JointMapError(ValueError):
    """A joint map that cannot be used; ``str(e)`` is one line naming the file, line and key."""

    def __init__(self, path, line: Optional[int], key: str, reason: str):
        self.path, self.line, self.key, self.reason = str(path), line, key, reason
        where = f'{path}:{line}' if line else f'{path}'
        super().__init__(f'{where}: {key}: {reason}' if key else f'{where}: {reason}')


# ------------------------------------------------------------------------------------------
# Geometry shared with the CMU importer
# ------------------------------------------------------------------------------------------
def rest_directions(body=None) -> np.ndarray:
    """(20, 3) unit direction of every segment in the standard T-pose (row 0: zeros)."""
    body = standard_body() if body is None else body
    off = body.rest_offsets.copy()
    n = np.linalg.norm(off, axis=1, keepdims=True)
    return np.where(n > 0, off / np.maximum(n, 1e-12), 0.0)


def min_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Quaternion (xyzw) of the smallest rotation taking unit vector a to unit vector b."""
    c = np.cross(a, b)
    d = float(np.dot(a, b))
    if d < -1.0 + 1e-9:  # opposite: any perpendicular axis
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return np.array([*axis, 0.0])
    q = np.array([c[0], c[1], c[2], 1.0 + d])
    return q / np.linalg.norm(q)


def min_rotation_batch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched smallest rotations taking unit vectors a to b (..., 3) -> (..., 4); for (near)
    opposite vectors (undefined axis) the identity."""
    c = np.cross(a, b)
    w = 1.0 + np.sum(a * b, -1, keepdims=True)
    q = np.concatenate([c, w], -1)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    ident = np.zeros_like(q)
    ident[..., 3] = 1.0
    return np.where(n > 1e-9, q / np.maximum(n, 1e-12), ident)


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def orientations_from_positions(positions: np.ndarray) -> np.ndarray:
    """Segment orientations (T, 20, 4) xyzw from joint positions (T, 20, 3), REP-103.

    Pelvis (joint 0): the frame whose y axis is HipRight -> HipLeft and whose z axis is HipCenter ->
    Spine made orthogonal to it (identity in the standard T-pose). Every other segment: its
    parent's orientation swung by the smallest rotation that carries the rest direction, as the
    parent holds it, onto the observed segment (no twist relative to the parent)."""
    from scipy.spatial.transform import Rotation   # (scipy.spatial: 0.3 s to import)
    p = np.asarray(positions, float)
    a_std = rest_directions()
    q = np.zeros(p.shape[:-1] + (4,))
    y = _unit(p[:, HIP_LEFT] - p[:, HIP_RIGHT])
    up = p[:, SPINE] - p[:, HIP_CENTER]
    z = _unit(up - np.sum(up * y, -1, keepdims=True) * y)
    x = np.cross(y, z)
    q[:, 0] = Rotation.from_matrix(np.stack([x, y, z], -1)).as_quat()
    for j in range(1, NUM_JOINTS):
        par = q[:, PARENTS[j]]
        carried = quat_rotate(par, np.broadcast_to(a_std[j], (len(p), 3)))
        seg = _unit(p[:, j] - p[:, PARENTS[j]])
        q[:, j] = quat_multiply(min_rotation_batch(carried, seg), par)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q * np.where(q[..., 3:4] < 0, -1.0, 1.0)


# ------------------------------------------------------------------------------------------
# The map
# ------------------------------------------------------------------------------------------
Point = Tuple[Tuple[str, float], ...]   # ((source point, weight), ...)


@dataclass
class JointMap:
    """A parsed joint map (see module docstring)."""

    path: str
    format: str
    rotation: np.ndarray                 # (3, 3): rep = rotation @ source (det -1: left-handed)
    scale: float                         # metres per file unit
    name: str = ''
    description: str = ''
    motion_class: str = 'other'
    # bvh
    joints: Dict[str, Tuple[Point, ...]] = field(default_factory=dict)  # alternatives per joint
    orientation: Dict[str, str] = field(default_factory=dict)
    strip_namespace: bool = False
    drop_first_frame: bool = False
    zero_rotations: Tuple[str, ...] = ()
    # markers
    marker_set: str = ''
    frame_rate: float = 0.0
    columns: Tuple[str, ...] = ()
    markers: Dict[str, str] = field(default_factory=dict)  # file label -> marker-set name
    subject: Dict[str, float] = field(default_factory=dict)
    lines: Dict[str, int] = field(default_factory=dict, repr=False)  # 'joints.Head' -> line

    def error(self, key: str, reason: str) -> JointMapError:
        line = self.lines.get(key) or self.lines.get(key.split('.')[0])
        return JointMapError(self.path, line, key, reason)

    def source_name(self, name: str) -> str:
        return name.rsplit(':', 1)[-1] if self.strip_namespace else name


def _compose(text: str, path: str):
    try:
        return yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        line = mark.line + 1 if mark is not None else None
        reason = ' '.join(str(x) for x in (e.context, e.problem) if x) or 'malformed YAML'
        raise JointMapError(path, line, '', f'not valid YAML ({reason})') from None
    except yaml.YAMLError as e:
        raise JointMapError(path, None, '', f'not valid YAML ({e})') from None


def _plain(node, path: str, key: str, lines: Dict[str, int]):
    """A composed YAML node -> Python value; records the line of every mapping key."""
    if isinstance(node, yaml.MappingNode):
        out = {}
        for k, v in node.value:
            if not isinstance(k, yaml.ScalarNode):
                raise JointMapError(path, k.start_mark.line + 1, key, 'keys must be plain names')
            name = k.value
            sub = f'{key}.{name}' if key else name
            if name in out:
                raise JointMapError(path, k.start_mark.line + 1, sub, 'given twice')
            lines[sub] = k.start_mark.line + 1
            out[name] = _plain(v, path, sub, lines)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_plain(v, path, f'{key}[{i}]', lines) for i, v in enumerate(node.value)]
    loader = yaml.SafeLoader('')
    try:
        return loader.construct_object(node, deep=True)
    finally:
        loader.dispose()


def axes_matrix(up: str, forward: str, handedness: str = 'right') -> np.ndarray:
    """(3, 3) matrix taking source coordinates to REP-103 (see module docstring)."""
    def vec(s, what):
        m = _AXIS_RE.match(str(s).strip())
        if not m:
            raise ValueError(f'{what} must be one of +X, -X, +Y, -Y, +Z, -Z, got {s!r}')
        v = np.zeros(3)
        v['XYZ'.index(m.group(2).upper())] = -1.0 if m.group(1) == '-' else 1.0
        return v
    u, f = vec(up, 'up'), vec(forward, 'forward')
    if abs(float(np.dot(u, f))) > 0.5:
        raise ValueError(f'up ({up}) and forward ({forward}) must be different axes')
    if handedness not in ('right', 'left'):
        raise ValueError(f"handedness must be 'right' or 'left', got {handedness!r}")
    left = np.cross(u, f) * (1.0 if handedness == 'right' else -1.0)
    return np.stack([f, left, u])


def _point(value, path, key, lines) -> Point:
    """One source point: 'Name' or {Name: weight, ...} (weights non-zero, sum 1; a negative
    weight extrapolates along a bone: {LeftHand: 1.35, LeftForeArm: -0.35} is 35 % of the
    forearm past the wrist)."""
    if isinstance(value, str) and value.strip():
        return ((value.strip(), 1.0),)
    if isinstance(value, dict) and value:
        pts = []
        for src, w in value.items():
            if isinstance(w, bool) or not isinstance(w, (int, float)) or not np.isfinite(w) \
                    or w == 0:
                raise JointMapError(path, lines.get(f'{key}.{src}', lines.get(key)), f'{key}.{src}',
                                    f'weight must be a non-zero number, got {w!r}')
            if abs(w) > MAX_WEIGHT:
                raise JointMapError(path, lines.get(f'{key}.{src}', lines.get(key)), f'{key}.{src}',
                                    f'weight {w:g} extrapolates too far (|weight| <= '
                                    f'{MAX_WEIGHT:g})')
            pts.append((str(src), float(w)))
        total = sum(w for _, w in pts)
        if abs(total - 1.0) > 1e-6:
            raise JointMapError(path, lines.get(key), key, f'weights sum to {total:g}, not 1')
        return tuple(pts)
    raise JointMapError(path, lines.get(key), key,
                        f'expected a source joint name or {{joint: weight, ...}}, got {value!r}')


def parse_joint_map(text: str, path: str = '<string>') -> JointMap:
    """Parse and validate joint-map YAML text (``path`` only names the file in errors)."""
    root = _compose(text, path)
    lines: Dict[str, int] = {}
    if root is None:
        raise JointMapError(path, None, '', 'empty file')
    data = _plain(root, path, '', lines)
    if not isinstance(data, dict):
        raise JointMapError(path, root.start_mark.line + 1, '', 'expected a mapping of keys')

    def err(key, reason):
        return JointMapError(path, lines.get(key), key, reason)

    def need(key):
        if key not in data:
            raise JointMapError(path, None, key, 'missing (required)')
        return data[key]

    fmt = need('format')
    if fmt not in FORMATS:
        raise err('format', f'must be one of {", ".join(FORMATS)}, got {fmt!r}')
    unknown = sorted(set(data) - _KEYS[fmt])
    if unknown:
        raise err(unknown[0], f'unknown key for format {fmt} (known: '
                              f'{", ".join(sorted(_KEYS[fmt]))})')
    axes = need('axes')
    if not isinstance(axes, dict) or set(axes) - {'up', 'forward', 'handedness'} \
            or not {'up', 'forward'} <= set(axes):
        raise err('axes', 'expected {up: <axis>, forward: <axis>, handedness: right|left}')
    try:
        rot = axes_matrix(axes['up'], axes['forward'], axes.get('handedness', 'right'))
    except ValueError as e:
        raise err('axes', str(e)) from None
    units = need('units')
    if units not in UNITS:
        raise err('units', f'must be one of {", ".join(UNITS)}, got {units!r}')
    scale = data.get('scale', 1.0)
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not np.isfinite(scale) \
            or scale <= 0:
        raise err('scale', f'must be a positive number, got {scale!r}')
    jm = JointMap(path=path, format=fmt, rotation=rot, scale=UNITS[units] * float(scale),
                  name=str(data.get('name', Path(path).stem)),
                  description=str(data.get('description', '')),
                  motion_class=str(data.get('motion_class', 'other')), lines=lines)
    if fmt == 'bvh':
        joints = need('joints')
        if not isinstance(joints, dict):
            raise err('joints', 'expected a mapping model joint -> source point(s)')
        for name in joints:
            if name not in JOINT_INDEX:
                raise err(f'joints.{name}', f'not a model joint (the 20 of skeleton_core.model: '
                                            f'{", ".join(JOINT_NAMES)})')
        missing = [n for n in JOINT_NAMES if n not in joints]
        if missing:
            raise err('joints', f'model joints without a source: {", ".join(missing)}')
        for name in JOINT_NAMES:
            key = f'joints.{name}'
            v = joints[name]
            alts = v if isinstance(v, list) else [v]
            if not alts:
                raise err(key, 'empty list of alternatives')
            jm.joints[name] = tuple(_point(a, path, f'{key}[{i}]' if isinstance(v, list) else key,
                                           lines) for i, a in enumerate(alts))
        ori = data.get('orientation', {}) or {}
        if not isinstance(ori, dict):
            raise err('orientation', 'expected a mapping model joint -> source bone')
        for name, bone in ori.items():
            if name not in JOINT_INDEX:
                raise err(f'orientation.{name}', 'not a model joint')
            if not isinstance(bone, str) or not bone:
                raise err(f'orientation.{name}', f'expected a source joint name, got {bone!r}')
        jm.orientation = dict(ori)
        for key in ('strip_namespace', 'drop_first_frame'):
            v = data.get(key, False)
            if not isinstance(v, bool):
                raise err(key, f'must be true or false, got {v!r}')
            setattr(jm, key, v)
        zr = data.get('zero_rotations', []) or []
        if not isinstance(zr, list) or not all(isinstance(s, str) for s in zr):
            raise err('zero_rotations', 'expected a list of source joint names')
        jm.zero_rotations = tuple(zr)
    else:
        ms = need('marker_set')
        if ms not in MARKER_SETS:
            raise err('marker_set', f'must be one of {", ".join(MARKER_SETS)}, got {ms!r}')
        jm.marker_set = ms
        fr = need('frame_rate')
        if isinstance(fr, bool) or not isinstance(fr, (int, float)) or not fr > 0:
            raise err('frame_rate', f'must be a positive number (Hz), got {fr!r}')
        jm.frame_rate = float(fr)
        cols = need('columns')
        if not isinstance(cols, list) or not cols or not all(isinstance(c, str) for c in cols):
            raise err('columns', 'expected the list of marker labels in column order')
        if len(set(cols)) != len(cols):
            dup = next(c for c in cols if cols.count(c) > 1)
            raise err('columns', f'label {dup!r} listed twice')
        jm.columns = tuple(cols)
        mk = data.get('markers', {}) or {}
        if not isinstance(mk, dict):
            raise err('markers', 'expected a mapping file label -> Plug-in-Gait marker')
        for label, target in mk.items():
            if label not in cols:
                raise err(f'markers.{label}', 'label is not in columns')
            if target not in vicon.MARKERS:
                raise err(f'markers.{label}', f'{target!r} is not a Plug-in-Gait marker')
        jm.markers = dict(mk)
        have = {jm.markers.get(c, c) for c in cols}
        lacking = [m for m in vicon.MARKERS if m not in have]
        if lacking:
            raise err('columns', f'Plug-in-Gait markers missing: {", ".join(lacking)}')
        subj = data.get('subject', {}) or {}
        fields = set(vicon.SubjectParams.__dataclass_fields__)
        if not isinstance(subj, dict):
            raise err('subject', f'expected a mapping of {", ".join(sorted(fields))}')
        for k, v in subj.items():
            if k not in fields:
                raise err(f'subject.{k}', f'unknown (known: {", ".join(sorted(fields))})')
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not v >= 0:
                raise err(f'subject.{k}', f'must be a number >= 0 (m), got {v!r}')
        jm.subject = {k: float(v) for k, v in subj.items()}
    return jm


def load_joint_map(path) -> JointMap:
    """Read and validate a joint-map file (:class:`JointMapError` on any problem)."""
    path = os.fspath(path)
    try:
        with open(path, encoding='utf-8') as f:
            text = f.read()
    except (OSError, UnicodeDecodeError) as e:
        raise JointMapError(path, None, '', f'cannot read ({getattr(e, "strerror", None) or e})') \
            from None
    return parse_joint_map(text, path)


def maps_dir() -> Path:
    """The folder of the shipped maps: ``$KP_JOINT_MAPS`` or ``config/joint_maps`` of the source
    tree."""
    env = os.environ.get('KP_JOINT_MAPS')
    if env:
        return Path(env)
    here = Path(__file__).resolve()
    for parent in here.parents:
        cand = parent / 'config' / 'joint_maps'
        if cand.is_dir():
            return cand
    return Path.cwd() / 'config' / 'joint_maps'


def builtin_map(name: str) -> JointMap:
    """A shipped map by name (``cmu_bvh``, ``generic_bvh``, ``plug_in_gait``)."""
    return load_joint_map(maps_dir() / f'{name}.yaml')


# ------------------------------------------------------------------------------------------
# BVH through a map
# ------------------------------------------------------------------------------------------
def _resolve(jm: JointMap, bvh: Bvh, source: str):
    """Source point name -> ('joint', index) or ('end', End Site index), or None."""
    names = {jm.source_name(n): i for i, n in enumerate(bvh.names)}
    if source.endswith('/End'):
        j = names.get(source[:-4])
        if j is None:
            return None
        for k, (p, _) in enumerate(bvh.end_sites):
            if p == j:
                return ('end', k)
        return None
    j = names.get(source)
    return None if j is None else ('joint', j)


def _describe(alt) -> str:
    return alt[0][0] if len(alt) == 1 else '{' + ', '.join(f'{s}: {w:g}' for s, w in alt) + '}'


def _points(jm: JointMap, bvh: Bvh, rest: Optional[Tuple[np.ndarray, np.ndarray]] = None):
    """Per model joint the chosen alternative as [(kind, index, weight)]: the first one the file
    holds that is not on top of its parent model joint in the rest pose (``rest``: the rest
    pose's joint and End Site positions; a zero-length segment, from an End Site at offset 0 or
    a joint mapped onto its parent, would have no direction). JointMapError when no alternative
    fits: the message names the joint and the fix."""
    out = []
    rest_pts = np.zeros((NUM_JOINTS, 3))
    for j, name in enumerate(JOINT_NAMES):
        chosen, zero = None, []
        for alt in jm.joints[name]:
            res = [(_resolve(jm, bvh, s), w) for s, w in alt]
            if not all(r is not None for r, _ in res):
                continue
            cand = [(r[0], r[1], w) for r, w in res]
            if rest is not None:
                pt = _kinect_points([cand], rest[0][None], rest[1][None])[0, 0]
                if j > 0 and np.linalg.norm(pt - rest_pts[PARENTS[j]]) < MIN_SEGMENT_M:
                    zero.append(alt)
                    continue
                rest_pts[j] = pt
            chosen = cand
            break
        if chosen is None and zero:
            parent = JOINT_NAMES[PARENTS[j]]
            hint = ''
            pj, gj = PARENTS[j], PARENTS[PARENTS[j]] if PARENTS[j] > 0 else None
            src_p = out[pj] if pj < len(out) else None
            src_g = out[gj] if gj is not None and gj < len(out) else None
            if src_p and src_g and len(src_p) == 1 and len(src_g) == 1 \
                    and src_p[0][0] == 'joint' and src_g[0][0] == 'joint':
                a = jm.source_name(bvh.names[src_p[0][1]])
                b = jm.source_name(bvh.names[src_g[0][1]])
                hint = (f', e.g. {name}: {{{a}: 1.35, {b}: -0.35}} (35 % of the '
                        f'{JOINT_NAMES[gj]}-{parent} segment past {parent})')
            raise jm.error(
                f'joints.{name}',
                f'{name} lands on its parent {parent} in {bvh.path} '
                f'({" / ".join(_describe(a) for a in zero)}: a zero-length segment, e.g. an End '
                f'Site at offset 0); place it beyond the joint with weights that extrapolate'
                f'{hint}, or map it onto another source joint')
        if chosen is None:
            opts = ' or '.join('+'.join(s for s, _ in alt) for alt in jm.joints[name])
            raise jm.error(f'joints.{name}', f'{bvh.path} has no {opts}')
        out.append(chosen)
    return out


def _kinect_points(points, pos: np.ndarray, ends: np.ndarray) -> np.ndarray:
    out = np.zeros(pos.shape[:1] + (NUM_JOINTS, 3))
    for j, pts in enumerate(points):
        for kind, idx, w in pts:
            out[:, j] += w * (ends[:, idx] if kind == 'end' else pos[:, idx])
    return out


def bvh_frames(bvh: Bvh, jm: JointMap) -> Tuple[np.ndarray, np.ndarray]:
    """Kinect joint positions (F, 20, 3) REP-103 metres and segment orientations (F, 20, 4) of a
    parsed BVH through the map (``drop_first_frame`` and ``zero_rotations`` applied)."""
    if jm.format != 'bvh':
        raise jm.error('format', f'a {jm.format} map cannot read a BVH file')
    zero = np.zeros((1, bvh.motion.shape[1]))
    pos0, _, ends0 = bvh.forward_kinematics(zero, scale=jm.scale)
    points = _points(jm, bvh, (pos0[0], ends0[0]))
    names = {jm.source_name(n): i for i, n in enumerate(bvh.names)}
    src_bone = {}
    for name, bone in jm.orientation.items():
        if bone not in names:
            raise jm.error(f'orientation.{name}', f'{bvh.path} has no joint {bone!r}')
        src_bone[JOINT_INDEX[name]] = names[bone]
    motion = bvh.motion[1:] if jm.drop_first_frame else bvh.motion
    motion = motion.copy()
    for nm in jm.zero_rotations:
        j = names.get(nm)
        if j is None:
            continue
        s = bvh.channel_start[j]
        for k, c in enumerate(bvh.channels[j]):
            if c.endswith('rotation'):
                motion[:, s + k] = 0.0
    c = jm.rotation
    pos, rot, ends = bvh.forward_kinematics(motion, scale=jm.scale)
    kin = _kinect_points(points, pos, ends) @ c.T
    q = orientations_from_positions(kin) if len(kin) else np.zeros((0, NUM_JOINTS, 4))
    if src_bone and len(kin):
        kin0 = (_kinect_points(points, pos0, ends0) @ c.T)[0]
        a_std = rest_directions()
        js = sorted(src_bone)
        r_rep = np.einsum('ij,fkjl,ml->fkim', c, rot[:, [src_bone[j] for j in js]], c)
        from scipy.spatial.transform import Rotation
        qb = Rotation.from_matrix(r_rep.reshape(-1, 3, 3)).as_quat().reshape(-1, len(js), 4)
        corr = np.zeros((len(js), 4))
        corr[:, 3] = 1.0
        for k, j in enumerate(js):
            if j == 0:
                continue
            d = kin0[j] - kin0[PARENTS[j]]
            corr[k] = min_rotation(a_std[j], d / np.linalg.norm(d))
        qb = quat_multiply(qb, corr)
        # segments spanning several source bones are not rigid with their source bone: swing by
        # the residual so the orientation points along the segment (twist from the bone)
        for k, j in enumerate(js):
            if j == 0:
                continue
            seg = _unit(kin[:, j] - kin[:, PARENTS[j]])
            pred = quat_rotate(qb[:, k], np.broadcast_to(a_std[j], seg.shape))
            qb[:, k] = quat_multiply(min_rotation_batch(pred, seg), qb[:, k])
        q[:, js] = qb
        q /= np.linalg.norm(q, axis=-1, keepdims=True)
        q *= np.where(q[..., 3:4] < 0, -1.0, 1.0)
    return kin, q


# ------------------------------------------------------------------------------------------
# Markers through a map
# ------------------------------------------------------------------------------------------
def read_markers(path, jm: JointMap) -> np.ndarray:
    """(N, M, 3) marker positions of a text file (optionally .gz; comma or blank separated, one
    frame per line, 3 numbers per ``columns`` label) in REP-103 metres, reordered to the marker
    set's order (:data:`vicon.MARKERS`). Samples written as exactly (0, 0, 0) (a gap) are NaN.
    Raises ``ValueError`` naming the file and line."""
    path = Path(path)
    opener = gzip.open if path.suffix == '.gz' else open
    try:
        with opener(path, 'rt') as f:
            text = f.read()
    except (OSError, EOFError, UnicodeDecodeError) as e:
        raise ValueError(f'{path}: cannot read ({type(e).__name__}: {e or "truncated"})') from None
    ncol = 3 * len(jm.columns)
    rows = []
    for ln, line in enumerate(text.splitlines(), 1):
        s = line.strip().rstrip(',')
        if not s:
            continue
        parts = re.split(r'[,\s]+', s)
        if len(parts) != ncol:
            raise ValueError(f'{path}:{ln}: {len(parts)} numbers, expected {ncol} '
                             f'(3 per marker of the joint map\'s columns)')
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            raise ValueError(f'{path}:{ln}: non-numeric value') from None
    if not rows:
        raise ValueError(f'{path}: no frames')
    m = np.asarray(rows).reshape(len(rows), len(jm.columns), 3)
    if not np.all(np.isfinite(m)):
        raise ValueError(f'{path}: NaN or infinite value')
    gap = np.all(m == 0.0, axis=-1)
    m = (m * jm.scale) @ jm.rotation.T
    m[gap] = np.nan
    order = [jm.markers.get(c, c) for c in jm.columns]
    idx = [order.index(name) for name in vicon.MARKERS]
    return m[:, idx]


def marker_joint_centres(markers: np.ndarray, jm: JointMap) -> np.ndarray:
    """Joint centres (N, 20, 3) from marker-set-ordered markers (N, 39, 3) by the Plug-in-Gait
    rules of :mod:`skeleton_data.vicon`, with the map's subject measurements."""
    params = vicon.SubjectParams(**jm.subject)
    return vicon.joint_centres(markers, params)


# ------------------------------------------------------------------------------------------
# Checking a mapped rig against the standard body
# ------------------------------------------------------------------------------------------
CHECK_RATIO = (0.6, 1.6)   # a segment outside this share of the standard body's is flagged


def segment_check(positions: np.ndarray) -> Tuple[np.ndarray, np.ndarray, list]:
    """(median segment lengths (19,) m of a mapped clip, the standard body's (19,), flagged
    segments [(name, length, standard)]: zero, or outside :data:`CHECK_RATIO` of the standard
    after scaling the clip to the standard body's height)."""
    from skeleton_core.model import SEGMENT_NAMES, segment_lengths
    got = np.nanmedian(segment_lengths(positions), axis=0)
    std = segment_lengths(standard_body().rest_positions())
    scale = float(np.nansum(std) / max(np.nansum(got), 1e-9))
    flagged = [(SEGMENT_NAMES[k], float(got[k]), float(std[k])) for k in range(len(got))
               if not got[k] > 1e-3 or not CHECK_RATIO[0] <= got[k] * scale / std[k]
               <= CHECK_RATIO[1]]
    return got, std, flagged


def segment_table(clips) -> str:
    """A text table of ``[(name, positions (F, 20, 3))]``: per clip its segment lengths (cm)
    against the standard body's; segments flagged by :func:`segment_check` marked ``!``."""
    from skeleton_core.model import SEGMENT_NAMES, segment_lengths
    short = [n.split('-')[1] for n in SEGMENT_NAMES]
    std = segment_lengths(standard_body().rest_positions())
    w = max([len(n) for n, _ in clips] + [14])
    lines = ['segment lengths (cm) of each mapped clip (median over frames) against the standard '
             f'body; ! = zero or outside {CHECK_RATIO[0]:g}-{CHECK_RATIO[1]:g}x of the standard '
             'after scaling to its height', '',
             'segment (ends at)'.ljust(w) + ' ' + ' '.join(f'{s[:9]:>9}' for s in short),
             'standard body'.ljust(w) + ' ' + ' '.join(f'{100 * v:9.1f}' for v in std)]
    for name, pos in clips:
        got, _, flagged = segment_check(pos)
        bad = {f[0] for f in flagged}
        lines.append(name.ljust(w) + ' ' + ' '.join(
            f'{100 * v:8.1f}' + ('!' if SEGMENT_NAMES[k] in bad else ' ')
            for k, v in enumerate(got)))
    return '\n'.join(lines)
