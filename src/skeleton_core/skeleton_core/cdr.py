"""CDR codec for ``skeleton_msgs/SkeletonArray`` straight to and from :class:`SkeletonFrame` s.

rclpy's (de)serializer goes through one Python object per joint point and quaternion (~0.7 ms per
two-user message each way, more than the reconstruction of a frame); this module reads and writes
the same bytes with ``struct`` and ``numpy`` (~20x faster), for offline tools that handle
serialized messages (bags). The layout is XCDR1 as Fast DDS writes it: a 4-byte encapsulation
header (``00 01`` little endian, ``00 00`` big endian), then the fields, each primitive aligned to
its size counted from the end of that header, sequences as a uint32 count followed by the
elements, strings as a uint32 length including the terminating NUL.

``frames_from_cdr(data, errors)`` returns exactly what ``frames_from_array_msg(deserialize(data))``
returns (same validation, same skipped skeletons and reasons); ``frames_to_cdr(...)`` gives bytes
rclpy deserializes to the message ``frames_to_array_msg(...)`` builds. A truncated or inconsistent
buffer raises :class:`CdrError` (a ``ValueError``).
"""
from __future__ import annotations

import struct
from typing import Iterable, List, Optional, Sequence, Tuple

import numpy as np

from .conversions import (MAX_ABS_COORDINATE, SkeletonFormatError, SkeletonFrame, collect_frames,
                          frame_from_arrays, validate_arrays)
from .model import NUM_JOINTS, TRACKING_STATES

SKELETON_ARRAY = 'skeleton_msgs/msg/SkeletonArray'
_IDENTITY = np.tile(np.array([0.0, 0.0, 0.0, 1.0]), (NUM_JOINTS, 1))
# per byte order: compiled structs and the wire dtypes (built once, not per field)
_U32 = {'<': struct.Struct('<I'), '>': struct.Struct('>I')}
_I32 = {'<': struct.Struct('<i'), '>': struct.Struct('>i')}
_STAMP_W = struct.Struct('<iI')
_WIRE = {(e, t): np.dtype(t).newbyteorder(e) for e in '<>' for t in ('f8', 'f4', 'u1')}
_ITEM = {t: np.dtype(t).itemsize for t in ('f8', 'f4', 'u1')}


class CdrError(ValueError):
    """A buffer that is not a serialized SkeletonArray (truncated, wrong counts)."""


class _Reader:
    def __init__(self, data: bytes):
        if len(data) < 4 or data[0] != 0 or data[1] not in (0, 1):
            raise CdrError('not a CDR buffer (bad encapsulation header)')
        self.buf = memoryview(data)
        self.n = len(self.buf)
        self.end = '<' if data[1] == 1 else '>'
        self._u32 = _U32[self.end]
        self._i32 = _I32[self.end]
        self.pos = 4

    def _align(self, n: int) -> None:
        self.pos += (-(self.pos - 4)) % n

    def _take(self, n: int) -> memoryview:
        if self.pos + n > len(self.buf):
            raise CdrError(f'truncated CDR buffer ({len(self.buf)} bytes)')
        out = self.buf[self.pos:self.pos + n]
        self.pos += n
        return out

    def _word(self, st: struct.Struct) -> int:
        pos = self.pos + (-(self.pos - 4)) % 4
        if pos + 4 > self.n:
            raise CdrError(f'truncated CDR buffer ({self.n} bytes)')
        self.pos = pos + 4
        return st.unpack_from(self.buf, pos)[0]

    def u32(self) -> int:
        return self._word(self._u32)

    def i32(self) -> int:
        return self._word(self._i32)

    def string(self) -> str:
        n = self.u32()
        raw = bytes(self._take(n))
        return raw[:-1].decode('utf-8', 'replace') if n else ''

    def array(self, dtype: str, count: int) -> np.ndarray:
        item = _ITEM[dtype]
        if count:
            self._align(item)
        if count > (self.n - self.pos) // item:
            raise CdrError(f'sequence of {count} does not fit the buffer')
        return np.frombuffer(self._take(count * item), dtype=_WIRE[self.end, dtype]).astype(dtype)

    def stamp_ns(self) -> int:
        sec = self.i32()
        return sec * 1_000_000_000 + self.u32()


def frames_from_cdr(data: bytes, errors: Optional[List[SkeletonFormatError]] = None
                    ) -> Tuple[int, str, List[SkeletonFrame]]:
    """(header stamp ns, header frame_id, valid frames) of a serialized SkeletonArray."""
    r = _Reader(data)
    stamp = r.stamp_ns()
    frame_id = r.string()
    n = r.u32()
    if n > len(data):
        raise CdrError(f'{n} skeletons cannot fit {len(data)} bytes')
    parsed = []
    for _ in range(n):
        sk_stamp = r.stamp_ns()
        sk_frame = r.string()
        uid = r.u32()
        pos = r.array('f8', 3 * r.u32()).reshape(-1, 3)
        ori = r.array('f8', 4 * r.u32()).reshape(-1, 4)
        ts = r.array('u1', r.u32())
        rel = r.array('f4', r.u32())
        parsed.append((pos, ts, rel, ori if len(ori) else None, uid, sk_stamp, sk_frame))
    checked = _checked_together(parsed)
    if checked is not None:   # every skeleton valid: the frames as frame_from_arrays makes them
        return stamp, frame_id, collect_frames(checked, lambda a: SkeletonFrame(*a), frame_id,
                                               errors)
    return stamp, frame_id, collect_frames(parsed, lambda a: frame_from_arrays(*a), frame_id,
                                           errors)


_NAN_RELIABILITY = np.full(NUM_JOINTS, np.nan, np.float32)


def _checked_together(parsed: list) -> Optional[list]:
    """The skeletons of one message checked at once, as :func:`validate_arrays` checks each:
    per skeleton the arguments of :class:`SkeletonFrame` (positions, tracking state,
    reliability, unit orientations, id, stamp, frame), the same values ``frame_from_arrays``
    returns for it; None when one of them is not valid (or not of the usual shapes): the caller
    then takes them one by one, which says why."""
    if not parsed:
        return None
    shape_p, n = (NUM_JOINTS, 3), NUM_JOINTS
    for pos, ts, rel, ori, *_ in parsed:
        if (pos.shape != shape_p or ts.shape[0] != n or rel.shape[0] not in (0, n)
                or (ori is not None and ori.shape[0] != n)):
            return None
    P = np.stack([a[0] for a in parsed])
    if not np.abs(P).max() <= MAX_ABS_COORDINATE:   # also False for NaN
        return None
    if np.stack([a[1] for a in parsed]).max() > max(TRACKING_STATES):
        return None
    rels = [a[2] for a in parsed if a[2].shape[0]]
    if rels:
        R = np.stack(rels)
        if not (R.min() >= 0.0 and R.max() <= 1.0) and np.logical_or(R < 0.0, R > 1.0).any():
            return None   # (NaN: unknown, allowed)
    oris = [a[3] for a in parsed if a[3] is not None]
    unit = iter(())
    if oris:
        Q = np.concatenate(oris)
        norm = np.sqrt(np.einsum('ij,ij->i', Q, Q))
        if not np.isfinite(norm).all():
            return None
        zero = norm < 1e-9   # a default-constructed message: identity
        if zero.any():
            Q[zero] = (0.0, 0.0, 0.0, 1.0)
            norm[zero] = 1.0
        unit = iter(np.split(Q / norm[:, None], len(oris)))
    return [(pos, ts, rel if rel.shape[0] else _NAN_RELIABILITY.copy(),
             None if ori is None else next(unit), int(uid), int(sk_stamp), sk_frame)
            for pos, ts, rel, ori, uid, sk_stamp, sk_frame in parsed]


class _Writer:
    def __init__(self):
        self.parts: List[bytes] = [b'\x00\x01\x00\x00']
        self.pos = 0   # bytes after the encapsulation header

    def _pad(self, n: int) -> None:
        k = (-self.pos) % n
        if k:
            self.parts.append(b'\x00' * k)
            self.pos += k

    def raw(self, b: bytes) -> None:
        self.parts.append(b)
        self.pos += len(b)

    def u32(self, v: int) -> None:
        self._pad(4)
        self.raw(_U32['<'].pack(v))

    def stamp(self, ns: int) -> None:
        self._pad(4)
        self.raw(_STAMP_W.pack(int(ns // 1_000_000_000), int(ns % 1_000_000_000)))

    def string(self, s: str) -> None:
        b = s.encode('utf-8') + b'\x00'
        self.u32(len(b))
        self.raw(b)

    def array(self, a: np.ndarray, dtype: str) -> None:
        a = np.ascontiguousarray(a, dtype=_WIRE['<', dtype])
        self.u32(a.shape[0] if a.ndim else 1)
        if a.size:
            self._pad(a.dtype.itemsize)
        self.raw(a.tobytes())

    def bytes(self) -> bytes:
        return b''.join(self.parts)


def frames_to_cdr(frames: Iterable[SkeletonFrame], stamp_ns: int, frame_id: str,
                  validated: bool = False) -> bytes:
    """Serialized SkeletonArray of ``frames`` (validated first, like ``frames_to_array_msg``;
    ``validated``: the frames' arrays are already what ``validate_arrays`` returns for them,
    e.g. a node checked every result, so they are written as they are)."""
    w = _Writer()
    w.stamp(stamp_ns)
    w.string(frame_id)
    frames = list(frames)
    w.u32(len(frames))
    for f in frames:
        if validated:
            p, t, rel, q = f.positions, f.tracking_state, f.reliability, f.orientations
        else:
            p, t, rel, q = validate_arrays(f.positions, f.tracking_state, f.reliability,
                                           f.orientations)
        w.stamp(f.stamp_ns)
        w.string(f.frame_id)
        w.u32(int(f.user_id))
        w.array(p, 'f8')
        w.array(_IDENTITY if q is None else q, 'f8')
        w.array(t, 'u1')
        w.array(rel, 'f4')
    return w.bytes()


def stamp_offsets(data: bytes) -> List[int]:
    """Byte offsets of every stamp of a little-endian serialized SkeletonArray (the header's,
    then each skeleton's): :func:`restamp_cdr` rewrites them without decoding the message."""
    r = _Reader(data)
    if r.end != '<':
        raise CdrError('stamp_offsets: a big-endian buffer')
    out = [r.pos]
    r.stamp_ns()
    r.string()
    for _ in range(r.u32()):
        r._align(4)
        out.append(r.pos)
        r.stamp_ns()
        r.string()
        r.u32()
        for dtype, per in (('f8', 3), ('f8', 4), ('u1', 1), ('f4', 1)):
            r.array(dtype, per * r.u32())
    return out


def restamp_cdr(data: bytes, offsets: Sequence[int], stamp_ns: int) -> bytes:
    """``data`` with every stamp at ``offsets`` (:func:`stamp_offsets`) set to ``stamp_ns``."""
    out = bytearray(data)
    sec, nsec = int(stamp_ns // 1_000_000_000), int(stamp_ns % 1_000_000_000)
    for off in offsets:
        _STAMP_W.pack_into(out, off, sec, nsec)
    return bytes(out)


__all__ = ['CdrError', 'SKELETON_ARRAY', 'frames_from_cdr', 'frames_to_cdr', 'restamp_cdr',
           'stamp_offsets']
