"""Conversions between ``skeleton_msgs`` messages and numpy arrays, with validation.

The library works on :class:`SkeletonFrame` (numpy arrays); nodes convert at the boundary with
:func:`skeleton_from_msg` / :func:`skeleton_to_msg`. Message classes are imported lazily, so this
module imports no rclpy and the rest of the library can be used without a ROS 2 installation.

Malformed input raises :class:`SkeletonFormatError` with a short, user-readable cause
(``SkeletonFormatError.cause`` is a stable key nodes use to log once per cause and count drops).
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Iterable, List, Optional

import numpy as np

from .model import NUM_JOINTS, TRACKING_STATES

MAX_ABS_COORDINATE = 50.0  # m; anything farther from the sensor is garbage, not a person


class SkeletonFormatError(ValueError):
    """A skeleton message or array that cannot be used. ``cause`` is a short stable key."""

    def __init__(self, cause: str, detail: str):
        super().__init__(f'{cause}: {detail}')
        self.cause = cause
        self.detail = detail


@dataclass
class SkeletonFrame:
    """One user's skeleton as arrays (REP-103, metres, in ``frame_id``)."""

    positions: np.ndarray                     # (20, 3) float64
    tracking_state: np.ndarray                # (20,) uint8
    reliability: np.ndarray = field(default_factory=lambda: np.full(NUM_JOINTS, np.nan, np.float32))
    orientations: Optional[np.ndarray] = None  # (20, 4) x, y, z, w; None = unknown (identity)
    user_id: int = 0
    stamp_ns: int = 0
    frame_id: str = ''

    def copy(self, **changes) -> 'SkeletonFrame':
        """A copy with its own arrays; ``changes`` replace fields (their values are taken as
        given, not copied). One constructor call: only the arrays not replaced are copied."""
        unknown = changes.keys() - _FRAME_FIELDS
        if unknown:  # what dataclasses.replace says
            raise TypeError(f'unexpected field(s) {sorted(unknown)}')
        ch = changes.get
        ori = self.orientations
        return type(self)(
            positions=ch('positions') if 'positions' in changes else self.positions.copy(),
            tracking_state=(ch('tracking_state') if 'tracking_state' in changes
                            else self.tracking_state.copy()),
            reliability=ch('reliability') if 'reliability' in changes else self.reliability.copy(),
            orientations=(ch('orientations') if 'orientations' in changes
                          else None if ori is None else ori.copy()),
            user_id=ch('user_id', self.user_id), stamp_ns=ch('stamp_ns', self.stamp_ns),
            frame_id=ch('frame_id', self.frame_id))


_FRAME_FIELDS = frozenset(f.name for f in fields(SkeletonFrame))


def validate_arrays(positions, tracking_state=None, reliability=None, orientations=None):
    """Check shapes and values; return them as arrays or raise :class:`SkeletonFormatError`.

    Every node calls this on every skeleton it takes and sends: the common valid case costs one
    reduction per array; the causes are worked out only when a check fails."""
    p = np.asarray(positions, dtype=float)
    if p.shape != (NUM_JOINTS, 3):
        raise SkeletonFormatError('wrong length', f'positions must be ({NUM_JOINTS}, 3), got {p.shape}')
    if not np.abs(p).max() <= MAX_ABS_COORDINATE:  # also False for NaN
        if not np.all(np.isfinite(p)):
            bad = np.flatnonzero(~np.isfinite(p).all(axis=1)).tolist()
            raise SkeletonFormatError('non-finite position', f'joints {bad} are NaN or infinite')
        raise SkeletonFormatError('coordinate out of range',
                                  f'|coordinate| > {MAX_ABS_COORDINATE} m')
    if tracking_state is None:
        t = np.full(NUM_JOINTS, 2, np.uint8)
    else:
        t = np.asarray(tracking_state)
        if t.shape != (NUM_JOINTS,):
            raise SkeletonFormatError('wrong length',
                                      f'tracking_state must have {NUM_JOINTS} entries, got {t.shape}')
        if t.dtype != np.uint8 or t.max() > max(TRACKING_STATES):
            if (t.min() < min(TRACKING_STATES) or t.max() > max(TRACKING_STATES)
                    or (t.dtype.kind not in 'iub' and np.any(t != np.round(t)))):
                raise SkeletonFormatError('unknown tracking state',
                                          f'values {sorted(set(t.tolist()) - set(TRACKING_STATES))}')
            t = t.astype(np.uint8)
    if reliability is None or len(reliability) == 0:
        r = np.full(NUM_JOINTS, np.nan, np.float32)
    else:
        r = np.asarray(reliability, dtype=np.float32)
        if r.shape != (NUM_JOINTS,):
            raise SkeletonFormatError('wrong length',
                                      f'reliability must have {NUM_JOINTS} entries, got {r.shape}')
        if not (r.min() >= 0.0 and r.max() <= 1.0):  # NaN (allowed: unknown) takes this branch
            # an infinity or a finite value outside [0, 1] (NaN compares False both ways)
            if np.logical_or(r < 0.0, r > 1.0).any():
                raise SkeletonFormatError('reliability out of range',
                                          'values must be NaN or in [0, 1]')
    q = None
    if orientations is not None and len(orientations) > 0:
        q = np.asarray(orientations, dtype=float)
        if q.shape != (NUM_JOINTS, 4):
            raise SkeletonFormatError('wrong length',
                                      f'orientations must be ({NUM_JOINTS}, 4), got {q.shape}')
        n = np.sqrt(np.einsum('ij,ij->i', q, q))
        if not np.isfinite(n).all():  # a NaN or infinite component
            raise SkeletonFormatError('non-finite orientation', 'NaN or infinite quaternion')
        zero = n < 1e-9  # a default-constructed message: identity
        if zero.any():
            q = q.copy()
            q[zero] = (0.0, 0.0, 0.0, 1.0)
            n[zero] = 1.0
        q = q / n[:, None]
    return p, t, r, q


def stamp_to_ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(ns: int, stamp=None):
    if stamp is None:
        from builtin_interfaces.msg import Time
        stamp = Time()
    stamp.sec = int(ns // 1_000_000_000)
    stamp.nanosec = int(ns % 1_000_000_000)
    return stamp


def frame_from_arrays(positions, tracking_state, reliability, orientations, user_id: int,
                      stamp_ns: int, frame_id: str) -> SkeletonFrame:
    """A validated :class:`SkeletonFrame` from the fields of a ``Skeleton`` message as arrays
    (``orientations`` None or empty = unknown)."""
    p = np.asarray(positions, float)
    if p.ndim != 2 or len(p) != NUM_JOINTS:
        raise SkeletonFormatError('wrong length',
                                  f'positions must have {NUM_JOINTS} entries, got {len(p)}')
    q = None if orientations is None or len(orientations) == 0 else np.asarray(orientations, float)
    t = np.asarray(tracking_state)
    # uint8 (a message's bytes) as it is, anything else through int64 (range checked below)
    t = t.copy() if t.dtype == np.uint8 else t.astype(np.int64)
    p, t, r, q = validate_arrays(p, t, np.asarray(reliability, dtype=np.float32), q)
    return SkeletonFrame(positions=p, tracking_state=t, reliability=r, orientations=q,
                         user_id=int(user_id), stamp_ns=int(stamp_ns), frame_id=frame_id)


def skeleton_from_msg(msg) -> SkeletonFrame:
    """``skeleton_msgs/Skeleton`` -> :class:`SkeletonFrame` (validated)."""
    pos = [(pt.x, pt.y, pt.z) for pt in msg.positions]
    if len(pos) != NUM_JOINTS:
        raise SkeletonFormatError('wrong length',
                                  f'positions must have {NUM_JOINTS} entries, got {len(pos)}')
    quats = [(q.x, q.y, q.z, q.w) for q in msg.orientations]
    ts = msg.tracking_state
    ts = np.frombuffer(ts, dtype=np.uint8) if isinstance(ts, (bytes, bytearray)) else np.asarray(ts)
    return frame_from_arrays(pos, ts, msg.reliability, quats, msg.user_id,
                             stamp_to_ns(msg.header.stamp), msg.header.frame_id)


def skeleton_to_msg(frame: SkeletonFrame, msg=None):
    """:class:`SkeletonFrame` -> ``skeleton_msgs/Skeleton`` (validated first)."""
    from geometry_msgs.msg import Point, Quaternion
    from skeleton_msgs.msg import Skeleton

    p, t, r, q = validate_arrays(frame.positions, frame.tracking_state, frame.reliability,
                                 frame.orientations)
    msg = Skeleton() if msg is None else msg
    msg.header.frame_id = frame.frame_id
    ns_to_stamp(frame.stamp_ns, msg.header.stamp)
    msg.user_id = int(frame.user_id)
    msg.positions = [Point(x=float(a), y=float(b), z=float(c)) for a, b, c in p]
    if q is None:
        msg.orientations = [Quaternion(x=0.0, y=0.0, z=0.0, w=1.0) for _ in range(NUM_JOINTS)]
    else:
        msg.orientations = [Quaternion(x=float(a), y=float(b), z=float(c), w=float(d))
                            for a, b, c, d in q]
    msg.tracking_state = t.tobytes() if isinstance(msg.tracking_state, bytes) else t.tolist()
    msg.reliability = r.astype(np.float32).tolist()
    return msg


def frames_to_array_msg(frames: Iterable[SkeletonFrame], stamp_ns: int, frame_id: str):
    """A list of frames -> ``skeleton_msgs/SkeletonArray``."""
    from skeleton_msgs.msg import SkeletonArray

    out = SkeletonArray()
    out.header.frame_id = frame_id
    ns_to_stamp(stamp_ns, out.header.stamp)
    out.skeletons = [skeleton_to_msg(f) for f in frames]
    return out


def collect_frames(items, build, header_frame_id: str,
                   errors: Optional[List[SkeletonFormatError]] = None) -> List[SkeletonFrame]:
    """``build(item)`` for every skeleton of a SkeletonArray: malformed skeletons are skipped and,
    when ``errors`` is given, appended to it; duplicate user ids keep the first skeleton; a
    skeleton without a frame id takes the array's."""
    out: List[SkeletonFrame] = []
    seen = set()
    for item in items:
        try:
            f = build(item)
        except SkeletonFormatError as e:
            if errors is not None:
                errors.append(e)
            continue
        if f.user_id in seen:
            if errors is not None:
                errors.append(SkeletonFormatError('duplicate user id', f'user {f.user_id}'))
            continue
        seen.add(f.user_id)
        if not f.frame_id:
            f.frame_id = header_frame_id
        out.append(f)
    return out


def frames_from_array_msg(msg, errors: Optional[List[SkeletonFormatError]] = None
                          ) -> List[SkeletonFrame]:
    """``skeleton_msgs/SkeletonArray`` -> frames. Malformed skeletons are skipped and, when
    ``errors`` is given, appended to it; duplicate user ids keep the first skeleton."""
    return collect_frames(msg.skeletons, skeleton_from_msg, msg.header.frame_id, errors)
