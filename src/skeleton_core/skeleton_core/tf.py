"""Frames without tf2: rigid transforms, a buffer of static transforms, sensor-pose files.

ROS-free (the ``tf2_msgs/TFMessage`` adapter is :mod:`skeleton_core.tf_ros`). Conventions as tf2's:

* A transform ``parent -> child`` (``Transform``) maps a point expressed in ``child`` into
  ``parent``: ``p_parent = R p_child + t`` (``t`` = the child's origin in the parent, ``R`` = its
  axes). Quaternions are ``(x, y, z, w)``.
* ``yaw pitch roll`` are the intrinsic z-y'-x'' angles of ``static_transform_publisher`` (yaw
  about z, then pitch about the new y, then roll about the new x); with REP-103 axes (x forward,
  z up) a positive pitch tilts the sensor *down*. Files and launch arguments give them in degrees.
* :class:`TfBuffer` holds a tree (each frame has one parent) and looks up the chain between any
  two frames through their common ancestor.

The sensor-pose file (hand-measured or written by ``calibrate_extrinsics``; the launch files turn
it into the static transforms)::

    transforms:
    - parent: world
      child: kinect_1_link
      xyz: [0.0, 0.0, 0.8]           # m
      ypr_deg: [0.0, 0.0, 0.0]       # or quat_xyzw: [x, y, z, w]
    - ...

Extra keys (``time_offset_s``, residuals, the method) are kept as information.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

from .geometry import quat_conjugate, quat_multiply

WORLD_FRAME = 'world'
# the one sensor's frame and pose in world when nothing else is given (launch files' sensor_pose)
SENSOR_FRAME = 'kinect_link'
DEFAULT_SENSOR_POSE = '0 0 0.8 0 0 0'   # x y z (m) yaw pitch roll (deg): 0.8 m up, level


def _quat_normalised(q) -> np.ndarray:
    q = np.asarray(q, float).reshape(4)
    n = float(np.linalg.norm(q))
    if not np.isfinite(n) or n < 1e-9:
        raise ValueError(f'not a rotation quaternion: {q.tolist()}')
    q = q / n
    return q if q[3] >= 0 else -q


def quat_from_matrix(m: np.ndarray) -> np.ndarray:
    """(x, y, z, w) of a 3x3 rotation matrix (Shepperd's method)."""
    m = np.asarray(m, float)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    return _quat_normalised(q)


def matrix_from_quat(q) -> np.ndarray:
    x, y, z, w = _quat_normalised(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def matrix_from_ypr(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) (radians)."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return rz @ ry @ rx


def ypr_from_matrix(m: np.ndarray) -> Tuple[float, float, float]:
    """(yaw, pitch, roll) in radians of :func:`matrix_from_ypr`."""
    m = np.asarray(m, float)
    pitch = math.asin(float(np.clip(-m[2, 0], -1.0, 1.0)))
    if abs(m[2, 0]) < 1.0 - 1e-9:
        yaw = math.atan2(m[1, 0], m[0, 0])
        roll = math.atan2(m[2, 1], m[2, 2])
    else:   # gimbal lock: roll folded into yaw
        yaw = math.atan2(-m[0, 1], m[1, 1])
        roll = 0.0
    return yaw, pitch, roll


@dataclass(frozen=True)
class Transform:
    """A rigid transform ``parent -> child``: ``p_parent = R p_child + translation``."""

    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))

    def __post_init__(self):
        t = np.array(self.translation, float).reshape(3)
        if not np.isfinite(t).all():
            raise ValueError(f'not a translation: {t.tolist()}')
        q = _quat_normalised(self.rotation)
        t.flags.writeable = False
        q.flags.writeable = False
        object.__setattr__(self, 'translation', t)
        object.__setattr__(self, 'rotation', q)
        r = matrix_from_quat(q)
        r.flags.writeable = False
        object.__setattr__(self, '_r', r)

    # -------------------------------------------------------------- constructors
    @classmethod
    def identity(cls) -> 'Transform':
        return cls()

    @classmethod
    def from_xyz_ypr(cls, x: float, y: float, z: float, yaw: float = 0.0, pitch: float = 0.0,
                     roll: float = 0.0, degrees: bool = True) -> 'Transform':
        a = [yaw, pitch, roll]
        if degrees:
            a = [math.radians(float(v)) for v in a]
        return cls((x, y, z), quat_from_matrix(matrix_from_ypr(*a)))

    @classmethod
    def from_matrix(cls, rotation: np.ndarray, translation) -> 'Transform':
        return cls(translation, quat_from_matrix(rotation))

    # -------------------------------------------------------------- algebra
    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 rotation matrix (read-only)."""
        return self._r

    def ypr(self, degrees: bool = True) -> Tuple[float, float, float]:
        a = ypr_from_matrix(self._r)
        return tuple(math.degrees(v) for v in a) if degrees else a

    def xyz_ypr(self, degrees: bool = True) -> List[float]:
        """``[x, y, z, yaw, pitch, roll]`` (the launch argument's order)."""
        return [float(v) for v in self.translation] + [float(v) for v in self.ypr(degrees)]

    def __mul__(self, other: 'Transform') -> 'Transform':
        """``a * b``: first ``b`` then ``a`` (``(parent->mid) * (mid->child) = parent->child``)."""
        return Transform(self._r @ other.translation + self.translation,
                         quat_multiply(self.rotation, other.rotation))

    def inverse(self) -> 'Transform':
        return Transform(-(self._r.T @ self.translation), quat_conjugate(self.rotation))

    def apply(self, points) -> np.ndarray:
        """Points (..., 3) from the child frame into the parent frame."""
        return np.asarray(points, float) @ self._r.T + self.translation

    def apply_quat(self, quats) -> np.ndarray:
        """Orientations (..., 4) from the child frame into the parent frame."""
        q = np.asarray(quats, float)
        if q.ndim == 2 and len(q) and q.shape[1] == 4 and (q[:, 3] == 1.0).all() \
                and not q[:, :3].any():
            # identity orientations (a tracker without any: the message carries identities):
            # the rotation itself, the product's value, without its cost (a third of the
            # fusion's per-view time with six users)
            out = np.empty_like(q)
            out[:] = self.rotation
            return out
        return quat_multiply(np.broadcast_to(self.rotation, q.shape), q)

    def is_identity(self, tol: float = 1e-12) -> bool:
        return (float(np.abs(self.translation).max()) <= tol
                and abs(1.0 - float(self.rotation[3])) <= tol)

    def distance(self, other: 'Transform') -> Tuple[float, float]:
        """(translation difference in m, rotation difference in degrees)."""
        dq = quat_multiply(quat_conjugate(self.rotation), other.rotation)
        ang = 2.0 * math.degrees(math.atan2(float(np.linalg.norm(dq[:3])), abs(float(dq[3]))))
        return float(np.linalg.norm(self.translation - other.translation)), ang

    def __repr__(self) -> str:
        x, y, z, yw, p, r = self.xyz_ypr()
        return (f'Transform(xyz=({x:.4f}, {y:.4f}, {z:.4f}) m, '
                f'ypr=({yw:.3f}, {p:.3f}, {r:.3f}) deg)')


class TfBuffer:
    """The static transform tree: ``set(parent, child, T)``, ``lookup(target, source)``.

    Each frame has at most one parent (a new transform for a child replaces the old one, as
    tf2's static broadcaster does); a transform that would close a cycle is refused."""

    def __init__(self):
        self._parent: Dict[str, Tuple[str, Transform]] = {}
        self.version = 0   # increments on every change (consumers cache their lookups)

    def set(self, parent: str, child: str, transform: Transform) -> None:
        parent, child = str(parent).lstrip('/'), str(child).lstrip('/')
        if not parent or not child:
            raise ValueError('a transform needs a parent and a child frame')
        if parent == child:
            raise ValueError(f'transform from {child!r} to itself')
        up = parent
        while up in self._parent:   # refuse a cycle: the child must not be above the parent
            up = self._parent[up][0]
            if up == child:
                raise ValueError(f'{parent!r} -> {child!r} would close a cycle in the TF tree')
        old = self._parent.get(child)
        if old is not None and old[0] == parent and np.array_equal(
                old[1].translation, transform.translation) and np.array_equal(
                old[1].rotation, transform.rotation):
            return
        self._parent[child] = (parent, transform)
        self.version += 1

    def update(self, items: Iterable[Tuple[str, str, Transform]]) -> None:
        for parent, child, t in items:
            self.set(parent, child, t)

    def frames(self) -> List[str]:
        out = set(self._parent)
        out.update(p for p, _ in self._parent.values())
        return sorted(out)

    def items(self) -> List[Tuple[str, str, Transform]]:
        return [(p, c, t) for c, (p, t) in sorted(self._parent.items())]

    def _chain(self, frame: str) -> List[str]:
        out = [frame]
        while out[-1] in self._parent:
            out.append(self._parent[out[-1]][0])
        return out

    def _to_ancestor(self, frame: str, ancestor: str) -> Transform:
        t = Transform()
        f = frame
        while f != ancestor:
            p, step = self._parent[f]
            t = step * t
            f = p
        return t

    def can_transform(self, target: str, source: str) -> bool:
        try:
            self.lookup(target, source)
            return True
        except LookupError:
            return False

    def lookup(self, target: str, source: str) -> Transform:
        """The transform mapping points in ``source`` into ``target`` (``p_target = T p_source``).
        Raises ``LookupError`` with a one-line reason when the frames are not connected."""
        target, source = str(target).lstrip('/'), str(source).lstrip('/')
        if target == source:
            return Transform()
        known = self.frames()
        for f in (target, source):
            if f not in known:
                raise LookupError(f'frame {f!r} is not on TF (known: {", ".join(known) or "none"})')
        up_t, up_s = self._chain(target), self._chain(source)
        common = next((f for f in up_s if f in set(up_t)), None)
        if common is None:
            raise LookupError(f'frames {source!r} and {target!r} are not connected on TF '
                              f'(roots {up_s[-1]!r} and {up_t[-1]!r})')
        return self._to_ancestor(target, common).inverse() * self._to_ancestor(source, common)


class HeldUntilTf:
    """Input that came before TF knew its frame, held until it does (nothing of a sensor's first
    frames is lost to a static transform that arrives a little after them, as a latched
    ``/tf_static`` can). Bounded: the newest ``limit`` items are kept; :meth:`hold` returns the one
    it had to let go (a drop for the caller to count), :meth:`take` the held items, oldest first."""

    def __init__(self, limit: int = 30):
        if limit < 1:
            raise ValueError(f'limit must be >= 1, got {limit}')
        self.limit = int(limit)
        self._items: List = []

    def __len__(self) -> int:
        return len(self._items)

    def hold(self, item):
        self._items.append(item)
        return self._items.pop(0) if len(self._items) > self.limit else None

    def take(self) -> List:
        out, self._items = self._items, []
        return out


def transforms_from_msg(msg) -> List[Tuple[str, str, 'Transform']]:
    """The ``(parent, child, Transform)`` items of a ``tf2_msgs/TFMessage`` (an rclpy message or
    any object with its fields, e.g. one decoded from a bag); a transform that is not one (NaN,
    zero quaternion, empty frame) raises ``ValueError`` naming it."""
    out = []
    for m in msg.transforms:
        tr, q = m.transform.translation, m.transform.rotation
        if not m.header.frame_id or not m.child_frame_id:
            raise ValueError('transform without a frame name')
        try:
            t = Transform((tr.x, tr.y, tr.z), (q.x, q.y, q.z, q.w))
        except ValueError as e:
            raise ValueError(f'{m.header.frame_id} -> {m.child_frame_id}: {e}') from None
        out.append((m.header.frame_id.lstrip('/'), m.child_frame_id.lstrip('/'), t))
    return out


# ------------------------------------------------------------------ files and launch arguments
def parse_pose(text: Union[str, Sequence[float]]) -> Transform:
    """``'x y z yaw pitch roll'`` (m, degrees; commas allowed; 3 values = no rotation)."""
    if isinstance(text, str):
        parts = text.replace(',', ' ').split()
    else:
        parts = list(text)
    try:
        v = [float(p) for p in parts]
    except ValueError:
        raise ValueError(f'sensor pose {text!r}: expected "x y z yaw pitch roll" (m, deg)') from None
    if len(v) not in (3, 6) or not all(math.isfinite(a) for a in v):
        raise ValueError(f'sensor pose {text!r}: expected "x y z yaw pitch roll" (m, deg)')
    return Transform.from_xyz_ypr(*(v + [0.0] * (6 - len(v))))


def format_pose(t: Transform) -> str:
    return ' '.join(f'{v:.6g}' for v in t.xyz_ypr())


def transforms_to_yaml(items: Sequence[Tuple[str, str, Transform]],
                       extra: Optional[Dict[str, Dict]] = None, header: str = '') -> str:
    """The sensor-pose file's text. ``extra``: per child frame, information kept beside it."""
    import yaml
    out = []
    for parent, child, t in items:
        d = {'parent': parent, 'child': child,
             'xyz': [round(float(v), 6) for v in t.translation],
             'ypr_deg': [round(float(v), 5) for v in t.ypr()],
             'quat_xyzw': [round(float(v), 9) for v in t.rotation]}
        d.update((extra or {}).get(child, {}))
        out.append(d)
    text = yaml.safe_dump({'transforms': out}, sort_keys=False, default_flow_style=None)
    if header:
        text = ''.join(f'# {line}\n' for line in header.splitlines()) + text
    return text


def load_transforms(path: Union[str, Path]) -> List[Tuple[str, str, Transform]]:
    """The transforms of a sensor-pose file. Raises ``ValueError`` naming the file and the entry."""
    import yaml
    p = Path(path).expanduser()
    if not p.is_file():
        raise ValueError(f'sensor pose file {p} not found')
    try:
        data = yaml.safe_load(p.read_text())
    except yaml.YAMLError as e:
        raise ValueError(f'sensor pose file {p}: not YAML ({str(e).splitlines()[0]})') from None
    entries = data.get('transforms') if isinstance(data, dict) else None
    if not isinstance(entries, list) or not entries:
        raise ValueError(f'sensor pose file {p}: expected a "transforms:" list')
    out = []
    for i, e in enumerate(entries):
        where = f'sensor pose file {p}, transform {i + 1}'
        if not isinstance(e, dict) or not e.get('child'):
            raise ValueError(f'{where}: needs "child" (and "parent", default world)')
        try:
            xyz = [float(v) for v in e.get('xyz', [0.0, 0.0, 0.0])]
            if 'quat_xyzw' in e:
                t = Transform(xyz, [float(v) for v in e['quat_xyzw']])
            else:
                ypr = [float(v) for v in e.get('ypr_deg', [0.0, 0.0, 0.0])]
                if len(ypr) != 3:
                    raise ValueError('ypr_deg needs 3 values')
                t = Transform.from_xyz_ypr(*xyz, *ypr)
        except (TypeError, ValueError) as err:
            raise ValueError(f'{where}: {err}') from None
        out.append((str(e.get('parent', WORLD_FRAME)), str(e['child']), t))
    return out


def sensor_frame(index: int, count: int) -> str:
    """The frame of sensor ``index`` (1-based) of ``count``: ``kinect_link`` when there is one
    sensor (today's name), else ``kinect_<index>_link``."""
    return 'kinect_link' if count <= 1 else f'kinect_{int(index)}_link'


def sensor_namespace(index: int, count: int) -> str:
    """'' for a single sensor (topics ``/kinect/...``), else ``kinect_<index>``."""
    return '' if count <= 1 else f'kinect_{int(index)}'


def default_sensor_poses(count: int, height: float = 0.8, distance: float = 2.5) -> List[Transform]:
    """Where the synthetic people are seen from when no pose is given: sensor 1 at the origin
    ``height`` m above the floor looking along x, the others on the circle of radius ``distance``
    around the play-space centre (``distance`` m in front of sensor 1), 90 degrees apart and
    facing it (sensor 2 on the +y side: front + side at 90 degrees)."""
    out = []
    for k in range(int(count)):
        ang = math.pi - k * math.pi / 2 - (k // 4) * math.pi / 4
        x = distance + distance * math.cos(ang)
        y = distance * math.sin(ang)
        yaw = math.degrees(ang + math.pi)
        yaw = (yaw + 180.0) % 360.0 - 180.0
        out.append(Transform.from_xyz_ypr(round(x, 9), round(y, 9), height, yaw, 0.0, 0.0))
    return out


__all__ = ['Transform', 'TfBuffer', 'WORLD_FRAME', 'transforms_from_msg', 'parse_pose', 'format_pose',
           'transforms_to_yaml', 'load_transforms', 'sensor_frame', 'sensor_namespace',
           'default_sensor_poses', 'quat_from_matrix', 'matrix_from_quat', 'matrix_from_ypr',
           'ypr_from_matrix']
