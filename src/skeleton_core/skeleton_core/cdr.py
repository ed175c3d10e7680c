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

The usual message (little endian, every skeleton with NUM_JOINTS of each array) is read and written
in blocks: one Python pass over the skeletons' headers, every skeleton's arrays gathered from (or
written into) one numpy array, checked across skeletons at once (``_decode_blocks``,
``_encode_blocks``); anything else goes field by field (``_frames_from_cdr_general``,
``_frames_to_cdr_general``), which also says what is wrong. Both give the same bytes, frames and
errors (tests/test_cdr.py compares them).
"""
from __future__ import annotations

import struct
import sys
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
    fast = _decode_blocks(data)
    if fast is not None:
        stamp, frame_id, parsed, checked = fast
        if checked is not None:
            return stamp, frame_id, collect_frames(checked, lambda a: SkeletonFrame(*a),
                                                   frame_id, errors)
        return stamp, frame_id, collect_frames(parsed, lambda a: frame_from_arrays(*a),
                                               frame_id, errors)
    return _frames_from_cdr_general(data, errors)


def _frames_from_cdr_general(data: bytes, errors: Optional[List[SkeletonFormatError]] = None
                             ) -> Tuple[int, str, List[SkeletonFrame]]:
    """Any buffer field by field (big endian, unusual joint counts, malformed): what
    :func:`frames_from_cdr` falls back to when :func:`_decode_blocks` declines."""
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


# The usual message read in blocks: a little-endian buffer (what Fast DDS and this module write on
# x86 / ARM hosts) whose skeletons all have NUM_JOINTS positions and tracking states and NUM_JOINTS
# or no orientations and reliabilities. walk_cdr finds the offsets of every skeleton's
# fields; each kind of array is then gathered for all skeletons at once from one numpy view of
# the buffer (positions, orientations, tracking states, reliabilities: four gathers a message) and
# checked at once. Anything else (or any inconsistency: a count that does not fit, a truncated
# buffer) is left to the field-by-field reader, which says what is wrong.
_BLOCKS_OK = sys.byteorder == 'little'
_U_L = struct.Struct('<I')
_J = NUM_JOINTS
_J3, _J4 = np.arange(3 * _J), np.arange(4 * _J)
_J1 = np.arange(_J)
# a complete skeleton from its positions on: positions, orientation count (+4 to align),
# orientations, tracking state count, states, reliability count, reliabilities; its byte
# offsets then 4 repeated bytes (rows of a multiple of 8 bytes, never past the buffer's end)
_ORI_AT = 24 * _J + 8
_TS_AT = _ORI_AT + 32 * _J + 4
_REL_AT = _TS_AT + _J + (-_J) % 4 + 4
_BLOCK = _REL_AT + 4 * _J
_BLOCK_AT = np.concatenate([np.arange(_BLOCK), np.arange(_BLOCK - 8 + _BLOCK % 8, _BLOCK)]
                           if _BLOCK % 8 else [np.arange(_BLOCK)])


# One walk of a buffer's offsets (any byte order, any counts), for the block decoder below and
# the light scan (cdr_scan). It checks no bound on the way (a read past the end is a struct.error,
# a sequence past the end puts the next read or the end past it): on any of them the buffer is
# left to the field-by-field reader, which raises the error frames_from_cdr raises.
_HEAD_AT = {e: struct.Struct(e + 'iII').unpack_from for e in '<>'}   # stamp, a string's length
_U_AT = {e: struct.Struct(e + 'I').unpack_from for e in '<>'}
_UU_AT = {e: struct.Struct(e + 'II').unpack_from for e in '<>'}
_NP, _NQ = 3 * NUM_JOINTS, 4 * NUM_JOINTS


def walk_cdr(data) -> tuple:
    """Where the fields of a serialized SkeletonArray are, nothing decoded but the counts, ids,
    stamps and frame ids; :class:`CdrError`, as :func:`frames_from_cdr` raises it, when the
    buffer is not one. A tuple ``(end, stamp_ns, frame_id, heads, pos_at, ori_at, ts_at, rel_at,
    usual)``:

    - ``end``: the byte order, ``'<'`` or ``'>'``; ``stamp_ns``, ``frame_id``: the header's;
    - ``heads``: per skeleton ``(user id, stamp ns, frame_id, then the counts of positions and
      orientations (float64 values), tracking states and reliabilities)``;
    - ``pos_at``, ``ori_at``, ``ts_at``, ``rel_at``: per skeleton the offset of each sequence
      (``ori_at``, ``rel_at``: -1 for an empty one);
    - ``usual``: every skeleton has NUM_JOINTS positions and tracking states and NUM_JOINTS or
      no orientations and reliabilities."""
    out = _walk(data if isinstance(data, (bytes, bytearray)) else bytes(data))   # (str slices)
    if out is None:
        _frames_from_cdr_general(data)   # raises the reader's CdrError
        raise CdrError('inconsistent CDR buffer')   # (not reached: the reader finds it)
    return out


def _walk(data) -> Optional[tuple]:
    """:func:`walk_cdr`'s tuple, None where the field-by-field reader raises."""
    n = len(data)
    if n < 4 or data[0] != 0 or data[1] not in (0, 1):
        return None
    end = '<' if data[1] == 1 else '>'
    head, u32, two = _HEAD_AT[end], _U_AT[end], _UU_AT[end]
    heads, pos_at, ori_at, ts_at, rel_at = [], [], [], [], []
    usual = True
    try:
        sec, nsec, flen = head(data, 4)
        pos = 16 + flen                          # after the frame_id
        frame_id = data[16:pos - 1].decode('utf-8', 'replace') if flen else ''
        pos += (-pos) & 3   # (alignment counts from the 4-byte header: pos % 4 == (pos - 4) % 4)
        count, = u32(data, pos)
        pos += 4
        if count > n:
            return None
        for _ in range(count):
            pos += (-pos) & 3
            s, ns, slen = head(data, pos)
            s0 = pos + 12
            pos = s0 + slen                      # after the frame_id
            sk_frame = data[s0:pos - 1].decode('utf-8', 'replace') if slen else ''
            pos += (-pos) & 3
            uid, kp = two(data, pos)             # positions: float64 triples
            pos += 8
            if kp != _J:
                usual = False
            if kp:
                kp *= 3
                pos += (4 - pos) & 7
            pos_at.append(pos)
            pos += 8 * kp
            kq, = u32(data, pos)                 # orientations: float64 quadruples
            pos += 4
            if kq:
                if kq != _J:
                    usual = False
                kq *= 4
                pos += (4 - pos) & 7
                ori_at.append(pos)
                pos += 8 * kq
            else:                                # (none: unknown)
                ori_at.append(-1)
            kt, = u32(data, pos)                 # tracking states: uint8
            if kt != _J:
                usual = False
            pos += 4
            ts_at.append(pos)
            pos += kt
            pos += (-pos) & 3
            kr, = u32(data, pos)                 # reliabilities: float32 (none: unknown)
            pos += 4
            if kr:
                if kr != _J:
                    usual = False
                rel_at.append(pos)
                pos += 4 * kr
            else:
                rel_at.append(-1)
            heads.append((uid, s * 1_000_000_000 + ns, sk_frame, kp, kq, kt, kr))
    except struct.error:   # a read past the end
        return None
    if pos > n:            # the last sequence past the end
        return None
    return end, sec * 1_000_000_000 + nsec, frame_id, heads, pos_at, ori_at, ts_at, rel_at, usual


def _decode_blocks(data) -> Optional[tuple]:
    """(stamp, frame_id, per-skeleton arguments of ``frame_from_arrays``, the same checked as
    :func:`_checked_together` checks them or None) of the usual message; None: not the usual
    message (the caller reads it field by field)."""
    if not _BLOCKS_OK or type(data) is not bytes:
        return None
    n = len(data)
    if n < 20 or data[0] != 0 or data[1] != 1:
        return None
    walk = _walk(data)
    if walk is None or not walk[-1]:   # (the field-by-field reader says what is wrong)
        return None
    _, stamp, frame_id, heads, pos_at, ori_at, ts_at, rel_at, _ = walk
    count = len(heads)
    if not count:
        return stamp, frame_id, [], None
    has_q = [a >= 0 for a in ori_at]
    has_r = [a >= 0 for a in rel_at]
    if all(has_q) and all(has_r):
        # every skeleton complete: its fields a fixed layout of _BLOCK bytes from the positions
        # on, all of them gathered at once (rows padded to a multiple of 8: aligned views)
        B = np.frombuffer(data, np.uint8)[np.array(pos_at)[:, None] + _BLOCK_AT]
        P = B[:, :24 * _J].view(np.float64).reshape(count, _J, 3)
        Q = B[:, _ORI_AT:_ORI_AT + 32 * _J].view(np.float64).reshape(count, _J, 4)
        T = B[:, _TS_AT:_TS_AT + _J]
        R = B[:, _REL_AT:_REL_AT + 4 * _J].view(np.float32)
    else:
        f8 = np.frombuffer(data, np.float64, (n - 4) // 8, 4)
        P = f8[((np.array(pos_at) - 4) >> 3)[:, None] + _J3].reshape(count, _J, 3)
        T = np.frombuffer(data, np.uint8)[np.array(ts_at)[:, None] + _J1]
        q_at = [a for a in ori_at if a >= 0]
        r_at = [a for a in rel_at if a >= 0]
        Q = (f8[((np.array(q_at) - 4) >> 3)[:, None] + _J4].reshape(len(q_at), _J, 4)
             if q_at else None)
        R = (np.frombuffer(data, np.float32, (n - 4) // 4, 4)[
            ((np.array(r_at) - 4) >> 2)[:, None] + _J1] if r_at else None)
    Qn = _blocks_valid(P, T, R, Q)
    ri = iter(R) if R is not None else iter(())
    if Qn is None:   # one of them not valid: one by one, which says why
        qi = iter(Q) if Q is not None else iter(())
        parsed = [(P[k], T[k], next(ri) if has_r[k] else _EMPTY_F4,
                   next(qi) if has_q[k] else None, uid, sk_stamp, sk_frame)
                  for k, (uid, sk_stamp, sk_frame, _, _, _, _) in enumerate(heads)]
        return stamp, frame_id, parsed, None
    qi = iter(Qn)
    checked = [(P[k], T[k], next(ri) if has_r[k] else _NAN_RELIABILITY.copy(),
                next(qi) if has_q[k] else None, uid, sk_stamp, sk_frame)
               for k, (uid, sk_stamp, sk_frame, _, _, _, _) in enumerate(heads)]
    return stamp, frame_id, None, checked


def _blocks_valid(P, T, R, Q):
    """What :func:`validate_arrays` checks, for the stacked arrays of a message's skeletons:
    None when one of them is not valid, else the unit orientations (an empty block when there
    are none),
    as ``validate_arrays`` normalises them."""
    if not np.abs(P).max() <= MAX_ABS_COORDINATE:   # also False for NaN
        return None
    if T.max() > _MAX_STATE:
        return None
    if R is not None and not (R.min() >= 0.0 and R.max() <= 1.0) \
            and np.logical_or(R < 0.0, R > 1.0).any():
        return None   # (NaN: unknown, allowed)
    if Q is None:
        return _NO_Q
    q = Q.reshape(-1, 4)
    norm = np.sqrt(np.einsum('ij,ij->i', q, q))
    if not np.isfinite(norm).all():
        return None
    zero = norm < 1e-9   # a default-constructed message: identity
    if zero.any():
        q = q.copy()
        q[zero] = (0.0, 0.0, 0.0, 1.0)
        norm[zero] = 1.0
    return (q / norm[:, None]).reshape(Q.shape)


_MAX_STATE = max(TRACKING_STATES)
_EMPTY_F4 = np.zeros(0, np.float32)
_NO_Q = np.zeros((0, NUM_JOINTS, 4))


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
    frames = list(frames)
    out = _encode_blocks(frames, stamp_ns, frame_id, validated)
    return out if out is not None else _frames_to_cdr_general(frames, stamp_ns, frame_id,
                                                               validated)


def _frames_to_cdr_general(frames: List[SkeletonFrame], stamp_ns: int, frame_id: str,
                           validated: bool) -> bytes:
    """Field by field: what :func:`frames_to_cdr` falls back to when :func:`_encode_blocks`
    declines (arrays not of the usual shapes and types, an invalid skeleton: the error)."""
    w = _Writer()
    w.stamp(stamp_ns)
    w.string(frame_id)
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


# A complete skeleton's fields from its positions on (the layout _decode_blocks reads), rows
# of a multiple of 8 bytes: the counts preset, the arrays assigned for all skeletons at once.
_BLOCK_DT = np.dtype({'names': ['p', 'oc', 'q', 'tc', 't', 'rc', 'r'],
                      'formats': [('<f8', (3 * _J,)), '<u4', ('<f8', (4 * _J,)), '<u4',
                                  ('u1', (_J,)), '<u4', ('<f4', (_J,))],
                      'offsets': [0, 24 * _J, _ORI_AT, _TS_AT - 4, _TS_AT, _REL_AT - 4,
                                  _REL_AT],
                      'itemsize': len(_BLOCK_AT)})
_template = np.zeros(1, _BLOCK_DT)
for _name in ('oc', 'tc', 'rc'):
    _template[_name] = _J
_BLOCK_TEMPLATE = _template.tobytes()   # one skeleton's block: the counts, zero padding
_HEAD_W = struct.Struct('<iII')   # stamp, then a string's length
_UU_W = struct.Struct('<II')
_PADS = [b'\x00' * k for k in range(8)]


def _encode_blocks(frames: List[SkeletonFrame], stamp_ns: int, frame_id: str,
                   validated: bool) -> Optional[bytes]:
    """The bytes :func:`_frames_to_cdr_general` writes, for frames of the usual arrays (float64
    positions, uint8 states, float32 reliabilities of NUM_JOINTS, float64 or no orientations),
    valid (or ``validated``): every skeleton's arrays written in one block array, the rest
    packed in one pass. None for anything else (the general writer then says what is wrong)."""
    k = len(frames)
    if not _BLOCKS_OK or k < 2:   # (one skeleton: the general writer is as cheap)
        return None
    try:
        parts = [b'\x00\x01\x00\x00']
        fid = frame_id.encode('utf-8') + b'\x00'
        parts.append(_HEAD_W.pack(int(stamp_ns // 1_000_000_000), int(stamp_ns % 1_000_000_000),
                                  len(fid)))
        parts.append(fid)
        p = 16 + len(fid)
        pad = (-p) & 3
        parts.append(_PADS[pad] + _U_L.pack(k))
        p += pad + 4
        if not k:
            return b''.join(parts)
        heads = []
        for f in frames:
            ns = f.stamp_ns
            sk_fid = f.frame_id.encode('utf-8') + b'\x00'
            pad = (-p) & 3
            p += pad + 12 + len(sk_fid)
            pad2 = (-p) & 3
            p += pad2 + 8
            pad3 = (-(p - 4)) & 7
            p += pad3 + _BLOCK
            heads.append(b''.join((_PADS[pad], _HEAD_W.pack(int(ns // 1_000_000_000),
                                                           int(ns % 1_000_000_000),
                                                           len(sk_fid)),
                                   sk_fid, _PADS[pad2], _UU_W.pack(int(f.user_id), _J),
                                   _PADS[pad3])))
        P = np.array([f.positions for f in frames])
        T = np.array([f.tracking_state for f in frames])
        R = np.array([f.reliability for f in frames])
        oris = [f.orientations for f in frames]
        some = [q for q in oris if q is not None]
        Q = np.array(some) if some else None
    except (struct.error, ValueError, TypeError, AttributeError, UnicodeError, OverflowError):
        return None
    if (P.dtype != np.float64 or P.shape != (k, _J, 3) or T.dtype != np.uint8
            or T.shape != (k, _J) or R.dtype != np.float32 or R.shape != (k, _J)
            or (Q is not None and (Q.dtype != np.float64 or Q.shape != (len(some), _J, 4)))):
        return None
    if not validated:
        Qn = _blocks_valid(P, T, R, Q)
        if Qn is None:
            return None
        Q = Qn if Q is not None else None
    B = np.frombuffer(bytearray(_BLOCK_TEMPLATE * k), _BLOCK_DT)
    B['p'] = P.reshape(k, 3 * _J)
    B['t'] = T
    B['r'] = R
    if Q is None:
        B['q'] = _IDENTITY_ROW
    elif len(some) == k:
        B['q'] = Q.reshape(k, 4 * _J)
    else:
        has = np.array([q is not None for q in oris])
        B['q'] = _IDENTITY_ROW
        B['q'][has] = Q.reshape(-1, 4 * _J)
    rows = B.tobytes()
    step = _BLOCK_DT.itemsize
    for i, h in enumerate(heads):
        parts.append(h)
        parts.append(rows[i * step:i * step + _BLOCK])
    return b''.join(parts)


_IDENTITY_ROW = _IDENTITY.reshape(-1)


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


def header_stamp_ns(data: bytes) -> int:
    """The header stamp of a serialized SkeletonArray, the rest not read (:class:`CdrError`
    when the buffer is not CDR or too short for it)."""
    r = _Reader(data)
    return r.stamp_ns()


def restamp_cdr(data: bytes, offsets: Sequence[int], stamp_ns: int) -> bytes:
    """``data`` with every stamp at ``offsets`` (:func:`stamp_offsets`) set to ``stamp_ns``."""
    out = bytearray(data)
    sec, nsec = int(stamp_ns // 1_000_000_000), int(stamp_ns % 1_000_000_000)
    for off in offsets:
        _STAMP_W.pack_into(out, off, sec, nsec)
    return bytes(out)


__all__ = ['CdrError', 'SKELETON_ARRAY', 'frames_from_cdr', 'frames_to_cdr',
           'header_stamp_ns', 'restamp_cdr', 'stamp_offsets', 'walk_cdr']
