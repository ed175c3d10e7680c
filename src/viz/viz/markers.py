"""Marker geometry for the RViz layers, as plain Python (no rclpy): the node only converts the
:class:`MarkerSpec` s built here into ``visualization_msgs/Marker`` messages.

Layers (one marker namespace per layer and user, ``<layer>/user_<id>``):

* ``raw`` — the Kinect skeleton as the papers draw it: purple joint spheres, yellow bones.
  INFERRED joints are drawn with a lower alpha; NOT_TRACKED joints are hidden (or grey).
* ``reliability`` — a red square on every joint, side proportional to ``1 - reliability``
  (Shum et al. 2013, Fig. 3: "unreliable parts indicated as red square"). The square faces the
  sensor (it lies in the y-z plane of the sensor frame, REP-103 x forward).
* ``reconstructed`` / ``completed`` — the reconstructed postures (green / blue).
* ``character`` — the simulated character as capsules (a CYLINDER and two SPHEREs per segment),
  oriented along the segment, radius from :func:`skeleton_core.model.standard_body` scaled to the
  character's height, i.e. the sizes the MuJoCo model uses.

:class:`SceneState` keeps the latest frames of every layer, which marker ids were last shown per
namespace, and turns everything into one list of specs per publish, including DELETE specs for
markers that are no longer shown (a user disappeared, a joint became reliable, a layer was hidden).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np

from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import (INFERRED, NOT_TRACKED, NUM_JOINTS, SEGMENTS, SEGMENT_CHILD_INDEX,
                                 SEGMENT_PARENT_INDEX, estimate_height, standard_body)
from skeleton_core.params import param

LAYERS: Tuple[str, ...] = ('raw', 'reliability', 'reconstructed', 'completed', 'character')

# Marker types (names; the node maps them to visualization_msgs/Marker constants)
SPHERE, CYLINDER, CUBE = 'SPHERE', 'CYLINDER', 'CUBE'
SPHERE_LIST, LINE_LIST = 'SPHERE_LIST', 'LINE_LIST'
ADD, DELETE = 'ADD', 'DELETE'

# Capsule radius per metre of body height (standard_body radii are proportional to the height)
_RADIUS_PER_HEIGHT = standard_body().segment_radii / standard_body().height

# Marker ids inside one skeleton namespace
JOINTS_ID, BONES_ID = 0, 1


def _color_ok(v) -> Optional[str]:
    v = list(v)
    if len(v) != 4 or not all(isinstance(x, float) and 0.0 <= x <= 1.0 for x in v):
        return 'a colour must be 4 numbers (r, g, b, a) in [0, 1]'
    return None


def _offset_ok(v) -> Optional[str]:
    v = list(v)
    if len(v) != 3 or not all(isinstance(x, float) and abs(x) <= 20.0 for x in v):
        return 'an offset must be 3 numbers (x, y, z) in metres, |v| <= 20'
    return None


def _color(default, description):
    return param(list(default), description, validator=_color_ok, public=False)


@dataclass
class Style:
    """Colours (RGBA in [0, 1]) and sizes (m) of every layer: parameters of the viz node."""

    joint_diameter: float = param(0.05, 'joint sphere diameter (m)', range=(0.001, 0.5),
                                  public=False)
    bone_width: float = param(0.015, 'bone line width (m)', range=(0.001, 0.2), public=False)
    inferred_alpha: float = param(0.35, 'alpha multiplier of INFERRED joints', range=(0.0, 1.0),
                                  public=False)
    not_tracked: str = param('hide', 'NOT_TRACKED joints: hide | grey', choices=('hide', 'grey'),
                             public=False)
    reliability_square_max: float = param(0.15, 'side (m) of the square at reliability 0',
                                          range=(0.005, 1.0), public=False)
    reliability_square_min: float = param(0.005, 'smaller squares are not drawn (m)',
                                          range=(0.0, 0.5), public=False)
    reliability_thickness: float = param(0.004, 'thickness (m) of the reliability squares',
                                         range=(0.0005, 0.1), public=False)
    character_height: float = param(
        0.0, 'character height for capsule radii (m); 0 = estimate from its segments',
        range=(0.0, 2.6), validator=lambda v: None if v == 0.0 or v > 0.5 else
        'character_height must be 0 (auto) or in (0.5, 2.6]', public=False)
    raw_joint_color: List[float] = _color((0.58, 0.20, 0.80, 1.0), 'raw joints RGBA (purple)')
    raw_bone_color: List[float] = _color((1.0, 0.90, 0.10, 1.0), 'raw bones RGBA (yellow)')
    not_tracked_color: List[float] = _color((0.5, 0.5, 0.5, 0.5),
                                            'NOT_TRACKED joints RGBA (grey mode)')
    reliability_color: List[float] = _color((1.0, 0.0, 0.0, 0.8),
                                            'unreliable-joint squares RGBA (red)')
    reconstructed_color: List[float] = _color((0.10, 0.85, 0.25, 1.0),
                                              'reconstructed skeleton RGBA (green)')
    completed_color: List[float] = _color((0.20, 0.55, 1.0, 1.0), 'completed skeleton RGBA (blue)')
    character_color: List[float] = _color((0.90, 0.72, 0.55, 0.9), 'character capsules RGBA')
    reconstructed_offset: List[float] = param(
        [0.0, 0.0, 0.0], 'shift (m) of the reconstructed/completed layers, e.g. to draw them side '
        'by side', validator=_offset_ok)
    character_offset: List[float] = param([0.0, 0.0, 0.0], 'shift (m) of the character layer',
                                          validator=_offset_ok)
    offsets: Dict[str, Tuple[float, float, float]] = field(default_factory=dict)  # layer -> shift

    def layer_offset(self, layer: str):
        """The shift of ``layer``: ``offsets[layer]`` if given, else the offset parameters."""
        off = self.offsets.get(layer)
        if off is not None:
            return off
        if layer in ('reconstructed', 'completed'):
            off = self.reconstructed_offset
        elif layer == 'character':
            off = self.character_offset
        return None if off is None or not any(off) else off


@dataclass
class MarkerSpec:
    """Everything a ``visualization_msgs/Marker`` needs, as plain values."""

    ns: str
    id: int
    type: str = SPHERE
    action: str = ADD
    frame_id: str = ''
    stamp_ns: int = 0
    position: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: Tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)  # x, y, z, w
    scale: Tuple[float, float, float] = (1.0, 1.0, 1.0)
    color: Tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    points: Optional[np.ndarray] = None   # (N, 3) for *_LIST types
    colors: Optional[np.ndarray] = None   # (N, 4) per point, or None


def namespace(layer: str, user_id: int) -> str:
    return f'{layer}/user_{int(user_id)}'


# --------------------------------------------------------------------------------------------
# Geometry helpers
# --------------------------------------------------------------------------------------------
def quats_z_to(directions: np.ndarray) -> np.ndarray:
    """Unit quaternions (K, 4) (x, y, z, w) rotating the +z axis onto each of ``directions``
    (K, 3) (the axis of an RViz CYLINDER is its local z). A zero direction gives the identity,
    the -z direction a half turn about x."""
    d = np.asarray(directions, dtype=float).reshape(-1, 3)
    n = np.linalg.norm(d, axis=1)
    out = np.tile(np.array([0.0, 0.0, 0.0, 1.0]), (len(d), 1))
    ok = n > 1e-12
    u = d[ok] / n[ok, None]
    c = u[:, 2]  # cos of the angle between z and u
    flip = c < -1.0 + 1e-9
    # q = (sin(a/2) axis, cos(a/2)) without trig: w = sqrt((1+c)/2), xyz = (z x u) / (2w)
    w = np.sqrt(np.maximum(0.5 * (1.0 + c), 1e-300))
    q = np.stack([-u[:, 1] / (2 * w), u[:, 0] / (2 * w), np.zeros_like(w), w], axis=1)
    q[flip] = (1.0, 0.0, 0.0, 0.0)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    out[ok] = q
    return out


def quat_z_to(direction: np.ndarray) -> Tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) rotating the +z axis onto ``direction``."""
    return tuple(float(v) for v in quats_z_to(np.asarray(direction, dtype=float)[None])[0])


def reliability_square_side(reliability: np.ndarray, max_side: float) -> np.ndarray:
    """Side of the red square per joint: ``max_side * (1 - r)``; NaN (unknown) gives NaN."""
    r = np.asarray(reliability, dtype=float)
    return max_side * (1.0 - np.clip(r, 0.0, 1.0))


def _rgba(c: Sequence[float], alpha: Optional[float] = None) -> Tuple[float, float, float, float]:
    c = tuple(float(v) for v in c)
    if len(c) == 3:
        c = c + (1.0,)
    if alpha is not None:
        c = c[:3] + (c[3] * alpha,)
    return c


def _shift(style: Style, layer: str, positions: np.ndarray) -> np.ndarray:
    off = style.layer_offset(layer)
    return positions if off is None else positions + np.asarray(off, dtype=float)


# --------------------------------------------------------------------------------------------
# One layer of one user
# --------------------------------------------------------------------------------------------
def skeleton_markers(frame: SkeletonFrame, layer: str, joint_color: Sequence[float],
                     bone_color: Sequence[float], style: Style,
                     use_tracking_state: bool = True) -> List[MarkerSpec]:
    """Joints (SPHERE_LIST, per-joint colours) and bones (LINE_LIST) of one skeleton.

    With ``use_tracking_state`` INFERRED joints get ``style.inferred_alpha`` and NOT_TRACKED joints
    are hidden (``style.not_tracked == 'hide'``) or drawn grey; a bone is drawn with the dimmest of
    its two joints, and hidden when either is hidden."""
    ns = namespace(layer, frame.user_id)
    p = _shift(style, layer, np.asarray(frame.positions, dtype=float))
    ts = np.asarray(frame.tracking_state) if use_tracking_state else np.full(NUM_JOINTS, 2)
    visible = np.ones(NUM_JOINTS, bool)
    jc = np.tile(np.array(_rgba(joint_color)), (NUM_JOINTS, 1))
    alpha = np.ones(NUM_JOINTS)
    grey = np.zeros(NUM_JOINTS, bool)
    alpha[ts == INFERRED] = style.inferred_alpha
    jc[ts == INFERRED, 3] *= style.inferred_alpha
    nt = ts == NOT_TRACKED
    if style.not_tracked == 'hide':
        visible[nt] = False
    else:
        jc[nt] = _rgba(style.not_tracked_color)
        grey[nt] = True
    common = dict(ns=ns, frame_id=frame.frame_id, stamp_ns=frame.stamp_ns)
    out = [MarkerSpec(id=JOINTS_ID, type=SPHERE_LIST,
                      scale=(style.joint_diameter,) * 3, color=_rgba(joint_color),
                      points=p[visible], colors=jc[visible], **common)]
    bc = np.array(_rgba(bone_color))
    pts, cols = [], []
    for a, b in SEGMENTS:
        if not (visible[a] and visible[b]):
            continue
        if grey[a] or grey[b]:
            c = np.array(_rgba(style.not_tracked_color))
        else:
            c = bc.copy()
            c[3] *= min(alpha[a], alpha[b])
        pts += [p[a], p[b]]
        cols += [c, c]
    out.append(MarkerSpec(id=BONES_ID, type=LINE_LIST, scale=(style.bone_width, 0.0, 0.0),
                          color=tuple(bc), points=np.array(pts).reshape(-1, 3),
                          colors=np.array(cols).reshape(-1, 4), **common))
    return out


def reliability_markers(frame: SkeletonFrame, style: Style, layer: str = 'reliability'
                        ) -> Tuple[List[MarkerSpec], List[int]]:
    """Red squares (flat CUBEs facing the sensor), id = joint index, side ∝ 1 - reliability.

    Returns (specs, ids_without_square): joints with unknown (NaN) reliability or a square smaller
    than ``style.reliability_square_min`` get no marker (the caller deletes a stale one)."""
    ns = namespace(layer, frame.user_id)
    p = _shift(style, layer, np.asarray(frame.positions, dtype=float))
    side = reliability_square_side(frame.reliability, style.reliability_square_max)
    specs, none = [], []
    for j in range(NUM_JOINTS):
        s = side[j]
        if not np.isfinite(s) or s < style.reliability_square_min:
            none.append(j)
            continue
        specs.append(MarkerSpec(ns=ns, id=j, type=CUBE, frame_id=frame.frame_id,
                                stamp_ns=frame.stamp_ns, position=tuple(float(v) for v in p[j]),
                                scale=(style.reliability_thickness, float(s), float(s)),
                                color=_rgba(style.reliability_color)))
    return specs, none


def character_height(frame: SkeletonFrame, style: Style) -> float:
    h = style.character_height
    if h > 0:
        return h
    h = estimate_height(frame.positions)
    return float(np.clip(h, 0.6, 2.5)) if np.isfinite(h) else 1.75


def capsule_markers(frame: SkeletonFrame, style: Style, layer: str = 'character'
                    ) -> List[MarkerSpec]:
    """Three markers per segment k: CYLINDER (id 3k) between the two joints, oriented along the
    segment, and SPHERE caps (ids 3k+1, 3k+2) at both ends; radius = the standard body's segment
    radius at the character's height (the MuJoCo model's capsule sizes)."""
    ns = namespace(layer, frame.user_id)
    p = _shift(style, layer, np.asarray(frame.positions, dtype=float))
    radii = (_RADIUS_PER_HEIGHT * character_height(frame, style)).tolist()
    color = _rgba(style.character_color)
    pa, pb = p[SEGMENT_PARENT_INDEX], p[SEGMENT_CHILD_INDEX]
    d = pb - pa
    lengths = np.maximum(np.linalg.norm(d, axis=1), 1e-4).tolist()
    mids = (0.5 * (pa + pb)).tolist()
    quats = quats_z_to(d).tolist()
    pa, pb = pa.tolist(), pb.tolist()
    out = []
    common = dict(ns=ns, frame_id=frame.frame_id, stamp_ns=frame.stamp_ns, color=color)
    for k in range(len(radii)):
        dia = 2.0 * radii[k]
        out.append(MarkerSpec(id=3 * k, type=CYLINDER, position=tuple(mids[k]),
                              orientation=tuple(quats[k]), scale=(dia, dia, lengths[k]), **common))
        out.append(MarkerSpec(id=3 * k + 1, type=SPHERE, position=tuple(pa[k]),
                              scale=(dia, dia, dia), **common))
        out.append(MarkerSpec(id=3 * k + 2, type=SPHERE, position=tuple(pb[k]),
                              scale=(dia, dia, dia), **common))
    return out


def layer_markers(layer: str, frame: SkeletonFrame, style: Style
                  ) -> Tuple[List[MarkerSpec], List[int]]:
    """Markers of one layer for one user, and ids of that namespace to delete now."""
    if layer == 'raw':
        return skeleton_markers(frame, layer, style.raw_joint_color, style.raw_bone_color,
                                style), []
    if layer == 'reliability':
        return reliability_markers(frame, style, layer)
    if layer == 'reconstructed':
        return skeleton_markers(frame, layer, style.reconstructed_color, style.reconstructed_color,
                                style, use_tracking_state=False), []
    if layer == 'completed':
        return skeleton_markers(frame, layer, style.completed_color, style.completed_color,
                                style, use_tracking_state=False), []
    if layer == 'character':
        return capsule_markers(frame, style, layer), []
    raise ValueError(f'unknown layer {layer!r}')


# --------------------------------------------------------------------------------------------
# Scene: latest frames per layer -> markers (with deletes)
# --------------------------------------------------------------------------------------------
class SceneState:
    """Latest skeletons of every layer; :meth:`build` returns the markers to publish now.

    Only layers whose input changed since the last build are rebuilt (RViz keeps the others until
    their lifetime ends; :meth:`invalidate` forces a full rebuild, e.g. after a style change).
    Markers that were shown before and are not shown now (user gone, layer hidden or stale, joint
    square vanished) come back once as DELETE specs, so RViz never keeps a stale marker.
    """

    def __init__(self, style: Optional[Style] = None, layers: Iterable[str] = LAYERS,
                 stale_timeout_s: float = 1.0, default_frame_id: str = 'kinect_link'):
        self.style = style or Style()
        self.enabled: Dict[str, bool] = {name: name in set(layers) for name in LAYERS}
        self.stale_timeout_s = stale_timeout_s
        self.default_frame_id = default_frame_id
        self._frames: Dict[str, List[SkeletonFrame]] = {}
        self._received_at: Dict[str, float] = {}
        self._version: Dict[str, int] = {name: 0 for name in LAYERS}
        self._built: Dict[str, int] = {name: -1 for name in LAYERS}
        # layer -> ns -> (frame_id, ids shown)
        self._shown: Dict[str, Dict[str, Tuple[str, set]]] = {name: {} for name in LAYERS}

    def update(self, layer: str, frames: Sequence[SkeletonFrame], now_s: float) -> None:
        """Replace the layer's skeletons by ``frames`` (all users seen in one message)."""
        if layer not in LAYERS:
            raise ValueError(f'unknown layer {layer!r}')
        self._frames[layer] = list(frames)
        self._received_at[layer] = now_s
        self._version[layer] += 1

    def invalidate(self) -> None:
        """Rebuild every layer at the next :meth:`build` (style or frame changed)."""
        self._built = {name: -1 for name in LAYERS}

    def _active(self, layer: str, now_s: float) -> bool:
        t = self._received_at.get(layer)
        return bool(self.enabled.get(layer)) and t is not None and now_s - t <= self.stale_timeout_s

    def build(self, now_s: float) -> List[MarkerSpec]:
        out: List[MarkerSpec] = []
        for layer in LAYERS:
            active = self._active(layer, now_s)
            if active and self._built[layer] == self._version[layer]:
                continue  # unchanged since the last build
            shown: Dict[str, Tuple[str, set]] = {}
            if active:
                for f in self._frames.get(layer, []):
                    if not f.frame_id:
                        f = f.copy(frame_id=self.default_frame_id)
                    specs, _ = layer_markers(layer, f, self.style)
                    if not specs:
                        continue
                    shown[specs[0].ns] = (f.frame_id, {s.id for s in specs})
                    out.extend(specs)
                self._built[layer] = self._version[layer]
            else:
                self._built[layer] = -1
            # deletes: whatever this layer showed before and does not show now
            for ns, (frame_id, ids) in self._shown[layer].items():
                now_ids = shown.get(ns, (frame_id, set()))[1]
                for i in sorted(ids - now_ids):
                    out.append(MarkerSpec(ns=ns, id=i, action=DELETE, frame_id=frame_id))
            self._shown[layer] = shown
        return out

    def has_stale(self, now_s: float) -> bool:
        """True when a layer with markers shown is hidden or has not been updated for
        ``stale_timeout_s`` (the next :meth:`build` deletes its markers)."""
        return any(shown and not self._active(layer, now_s)
                   for layer, shown in self._shown.items())

    def shown_namespaces(self) -> List[str]:
        return sorted(ns for shown in self._shown.values() for ns in shown)
