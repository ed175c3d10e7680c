"""A light read of a serialized ``skeleton_msgs/SkeletonArray``: the header stamp and, per
skeleton, its user id, its stamp and whether :func:`skeleton_core.cdr.frames_from_cdr` would
return it as a frame (and if not, why) -- without building frames. For a consumer that only
needs stamps and ids (the benchmark's latency probe, which reads every message of every output).

The buffer's offsets are walked once with the bounds :class:`skeleton_core.cdr._Reader` checks
(a buffer ``frames_from_cdr`` rejects raises :class:`CdrError` here too); the usual message
(every skeleton of the usual lengths, every value valid) is then checked with a few numpy
reductions over views of its blocks, the checks ``frames_from_cdr`` makes. Anything else (a NaN,
a wrong length, ...) -- rare in a graph's output -- is checked skeleton by skeleton with
:func:`frame_from_arrays`, as ``frames_from_cdr`` does, so the causes are its causes.
"""
from __future__ import annotations

import struct
from typing import List, NamedTuple, Optional, Tuple

import numpy as np

from .cdr import CdrError
from .conversions import MAX_ABS_COORDINATE, SkeletonFormatError, frame_from_arrays
from .model import NUM_JOINTS, TRACKING_STATES


class CdrScan(NamedTuple):
    """The header stamp and, per skeleton in message order, ``(user_id, stamp_ns, cause)``:
    ``cause`` None for a skeleton ``frames_from_cdr`` returns as a frame, else the ``cause`` of
    the error it reports for it (``'non-finite position'``, ``'duplicate user id'``, ...)."""
    stamp_ns: int
    skeletons: List[Tuple[int, int, Optional[str]]]


_U32 = {e: struct.Struct(e + 'I').unpack_from for e in '<>'}
_U32X2 = {e: struct.Struct(e + 'II').unpack_from for e in '<>'}
_STAMP = {e: struct.Struct(e + 'iI').unpack_from for e in '<>'}
_F8 = {e: np.dtype('f8').newbyteorder(e) for e in '<>'}
_F4 = {e: np.dtype('f4').newbyteorder(e) for e in '<>'}
_NP, _NQ = 3 * NUM_JOINTS, 4 * NUM_JOINTS
_AR = {k: np.arange(k) for k in (_NP, _NQ, NUM_JOINTS)}
_MAX_STATE = max(TRACKING_STATES)


def _truncated(n: int) -> CdrError:
    return CdrError(f'truncated CDR buffer ({n} bytes)')


def _too_long(k: int) -> CdrError:
    return CdrError(f'sequence of {k} does not fit the buffer')


def scan_cdr(data: bytes) -> CdrScan:
    """:class:`CdrScan` of a serialized SkeletonArray (CdrError: not one, as for
    ``frames_from_cdr``)."""
    n = len(data)
    if n < 4 or data[0] != 0 or data[1] not in (0, 1):
        raise CdrError('not a CDR buffer (bad encapsulation header)')
    end = '<' if data[1] == 1 else '>'
    u32, two, stamp_of = _U32[end], _U32X2[end], _STAMP[end]
    if n < 16:                                   # header stamp, frame_id length
        raise _truncated(n)
    sec, nsec = stamp_of(data, 4)
    pos = 16 + u32(data, 12)[0]                  # after the frame_id
    pos += -(pos - 4) % 4
    if pos + 4 > n:
        raise _truncated(n)
    count = u32(data, pos)[0]
    pos += 4
    if count > n:
        raise CdrError(f'{count} skeletons cannot fit {n} bytes')
    ids = []                                     # (user id, stamp) per skeleton
    blocks = []                                  # (offset, count) of its 4 sequences
    usual = True                                 # every sequence of the usual length so far
    for _ in range(count):
        pos += -(pos - 4) % 4
        if pos + 12 > n:                         # stamp, frame_id length
            raise _truncated(n)
        s, ns = stamp_of(data, pos)
        pos += 12 + u32(data, pos + 8)[0]        # after the frame_id
        if pos > n:
            raise _truncated(n)
        pos += -(pos - 4) % 4
        if pos + 8 > n:                          # user id, positions count
            raise _truncated(n)
        uid, kp = two(data, pos)
        ids.append((uid, s * 1_000_000_000 + ns))
        pos += 8
        kp *= 3                                  # positions: float64 triples
        if kp:
            pos += -(pos - 4) % 8
            if kp > (n - pos) // 8:
                raise _too_long(kp)
        op = pos
        pos += 8 * kp
        pos += -(pos - 4) % 4
        if pos + 4 > n:
            raise _truncated(n)
        kq = 4 * u32(data, pos)[0]               # orientations: float64 quadruples (none: unknown)
        pos += 4
        if kq:
            pos += -(pos - 4) % 8
            if kq > (n - pos) // 8:
                raise _too_long(kq)
        oq = pos
        pos += 8 * kq
        pos += -(pos - 4) % 4
        if pos + 4 > n:
            raise _truncated(n)
        kt = u32(data, pos)[0]                   # tracking states: uint8
        pos += 4
        if kt > n - pos:
            raise _too_long(kt)
        ot = pos
        pos += kt
        pos += -(pos - 4) % 4
        if pos + 4 > n:
            raise _truncated(n)
        kr = u32(data, pos)[0]                   # reliabilities: float32 (none: unknown)
        pos += 4
        if kr and kr > (n - pos) // 4:           # (already aligned to 4)
            raise _too_long(kr)
        blocks.append((op, kp, oq, kq, ot, kt, pos, kr))
        pos += 4 * kr
        usual = (usual and kp == _NP and kt == NUM_JOINTS and kq in (0, _NQ)
                 and kr in (0, NUM_JOINTS))
    stamp = sec * 1_000_000_000 + nsec
    if not ids:
        return CdrScan(stamp, [])
    if usual and _usual_values_valid(data, end, blocks):
        causes = []
        seen = set()
        for uid, _ in ids:
            causes.append('duplicate user id' if uid in seen else None)
            seen.add(uid)
    else:
        causes = _causes(data, end, ids, blocks)
    return CdrScan(stamp, [(uid, st, c) for (uid, st), c in zip(ids, causes)])


def _usual_values_valid(data: bytes, end: str, blocks) -> bool:
    """Every skeleton's values valid as ``frames_from_cdr`` checks them (its sequences all of the
    usual lengths): positions within MAX_ABS_COORDINATE (not NaN), known tracking states,
    reliabilities NaN or in [0, 1], quaternions of finite norm."""
    f8 = np.frombuffer(data, _F8[end], (len(data) - 4) // 8, 4)   # offsets 4 + 8 i: aligned
    P = f8[(np.array([b[0] for b in blocks]) - 4)[:, None] // 8 + _AR[_NP]]
    if not np.abs(P).max() <= MAX_ABS_COORDINATE:   # also False for NaN
        return False
    T = np.frombuffer(data, np.uint8)[np.array([b[4] for b in blocks])[:, None] + _AR[NUM_JOINTS]]
    if T.max() > _MAX_STATE:
        return False
    r_at = [b[6] for b in blocks if b[7]]
    if r_at:
        f4 = np.frombuffer(data, _F4[end], (len(data) - 4) // 4, 4)
        R = f4[(np.array(r_at) - 4)[:, None] // 4 + _AR[NUM_JOINTS]]
        if not (R.min() >= 0.0 and R.max() <= 1.0) and np.logical_or(R < 0.0, R > 1.0).any():
            return False   # (NaN: unknown, allowed)
    q_at = [b[2] for b in blocks if b[3]]
    if q_at:
        Q = f8[(np.array(q_at) - 4)[:, None] // 8 + _AR[_NQ]].reshape(-1, 4)
        if not np.isfinite(np.einsum('ij,ij->i', Q, Q)).all():   # squared norms
            return False
    return True


def _causes(data: bytes, end: str, ids, blocks) -> List[Optional[str]]:
    """Per skeleton what ``frames_from_cdr`` makes of it one by one (``frame_from_arrays``, then
    the first of each user id kept): None (a frame) or the cause of its error."""
    out: List[Optional[str]] = []
    seen = set()
    for (uid, stamp), (op, kp, oq, kq, ot, kt, orl, kr) in zip(ids, blocks):
        pos = np.frombuffer(data, _F8[end], kp, op).astype('f8').reshape(-1, 3)
        ori = np.frombuffer(data, _F8[end], kq, oq).astype('f8').reshape(-1, 4) if kq else None
        ts = np.frombuffer(data, np.uint8, kt, ot).copy()
        rel = np.frombuffer(data, _F4[end], kr, orl).astype('f4')
        try:
            frame_from_arrays(pos, ts, rel, ori, uid, stamp, '')
        except SkeletonFormatError as e:
            out.append(e.cause)
            continue
        out.append('duplicate user id' if uid in seen else None)
        seen.add(uid)
    return out


__all__ = ['CdrScan', 'scan_cdr']
