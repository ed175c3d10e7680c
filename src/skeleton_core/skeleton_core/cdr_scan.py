"""A light read of a serialized ``skeleton_msgs/SkeletonArray``: the header stamp and, per
skeleton, its user id, its stamp and whether :func:`skeleton_core.cdr.frames_from_cdr` would
return it as a frame (and if not, why) -- without building frames. For a consumer that only
needs stamps and ids (the benchmark's latency probe, which reads every message of every output).

The buffer's offsets are those :func:`skeleton_core.cdr.walk_cdr` finds, the walk the block
decoder of ``frames_from_cdr`` makes (a buffer ``frames_from_cdr`` rejects raises
:class:`CdrError` here too); the usual message
(every skeleton of the usual lengths, every value valid) is then checked with a few numpy
reductions over views of its blocks, the checks ``frames_from_cdr`` makes. Anything else (a NaN,
a wrong length, ...) -- rare in a graph's output -- is checked skeleton by skeleton with
:func:`frame_from_arrays`, as ``frames_from_cdr`` does, so the causes are its causes.
"""
from __future__ import annotations

from typing import List, NamedTuple, Optional, Tuple

import numpy as np

from .cdr import walk_cdr
from .conversions import MAX_ABS_COORDINATE, SkeletonFormatError, frame_from_arrays
from .model import NUM_JOINTS, TRACKING_STATES


class CdrScan(NamedTuple):
    """The header stamp and, per skeleton in message order, ``(user_id, stamp_ns, cause)``:
    ``cause`` None for a skeleton ``frames_from_cdr`` returns as a frame, else the ``cause`` of
    the error it reports for it (``'non-finite position'``, ``'duplicate user id'``, ...)."""
    stamp_ns: int
    skeletons: List[Tuple[int, int, Optional[str]]]


_F8 = {e: np.dtype('f8').newbyteorder(e) for e in '<>'}
_F4 = {e: np.dtype('f4').newbyteorder(e) for e in '<>'}
_NP, _NQ = 3 * NUM_JOINTS, 4 * NUM_JOINTS
_AR = {k: np.arange(k) for k in (_NP, _NQ, NUM_JOINTS)}
_MAX_STATE = max(TRACKING_STATES)


def scan_cdr(data: bytes) -> CdrScan:
    """:class:`CdrScan` of a serialized SkeletonArray (CdrError: not one, as for
    ``frames_from_cdr``)."""
    end, stamp, _, heads, pos_at, ori_at, ts_at, rel_at, usual = walk_cdr(data)
    if not heads:
        return CdrScan(stamp, [])
    if usual and _usual_values_valid(data, end, pos_at, ori_at, ts_at, rel_at):
        out = []
        seen = set()
        for uid, st, *_ in heads:
            out.append((uid, st, 'duplicate user id' if uid in seen else None))
            seen.add(uid)
        return CdrScan(stamp, out)
    return CdrScan(stamp, _causes(data, end, heads, pos_at, ori_at, ts_at, rel_at))


def _usual_values_valid(data: bytes, end: str, pos_at, ori_at, ts_at, rel_at) -> bool:
    """Every skeleton's values valid as ``frames_from_cdr`` checks them (its sequences all of the
    usual lengths): positions within MAX_ABS_COORDINATE (not NaN), known tracking states,
    reliabilities NaN or in [0, 1], quaternions of finite norm."""
    f8 = np.frombuffer(data, _F8[end], (len(data) - 4) // 8, 4)   # offsets 4 + 8 i: aligned
    P = f8[(np.array(pos_at) - 4)[:, None] // 8 + _AR[_NP]]
    if not np.abs(P).max() <= MAX_ABS_COORDINATE:   # also False for NaN
        return False
    T = np.frombuffer(data, np.uint8)[np.array(ts_at)[:, None] + _AR[NUM_JOINTS]]
    if T.max() > _MAX_STATE:
        return False
    r_at = [a for a in rel_at if a >= 0]
    if r_at:
        f4 = np.frombuffer(data, _F4[end], (len(data) - 4) // 4, 4)
        R = f4[(np.array(r_at) - 4)[:, None] // 4 + _AR[NUM_JOINTS]]
        if not (R.min() >= 0.0 and R.max() <= 1.0) and np.logical_or(R < 0.0, R > 1.0).any():
            return False   # (NaN: unknown, allowed)
    q_at = [a for a in ori_at if a >= 0]
    if q_at:
        Q = f8[(np.array(q_at) - 4)[:, None] // 8 + _AR[_NQ]].reshape(-1, 4)
        if not np.isfinite(np.einsum('ij,ij->i', Q, Q)).all():   # squared norms
            return False
    return True


def _causes(data: bytes, end: str, heads, pos_at, ori_at, ts_at, rel_at
            ) -> List[Tuple[int, int, Optional[str]]]:
    """Per skeleton ``(user id, stamp, cause)``: what ``frames_from_cdr`` makes of it one by one
    (``frame_from_arrays``, then the first of each user id kept): None (a frame) or the cause of
    its error."""
    out: List[Tuple[int, int, Optional[str]]] = []
    seen = set()
    for (uid, stamp, _, kp, kq, kt, kr), op, oq, ot, orl in zip(heads, pos_at, ori_at, ts_at,
                                                                  rel_at):
        pos = np.frombuffer(data, _F8[end], kp, op).astype('f8').reshape(-1, 3)
        ori = np.frombuffer(data, _F8[end], kq, oq).astype('f8').reshape(-1, 4) if kq else None
        ts = np.frombuffer(data, np.uint8, kt, ot).copy()
        rel = np.frombuffer(data, _F4[end], kr, orl).astype('f4') if kr else _NO_RELIABILITY
        try:
            frame_from_arrays(pos, ts, rel, ori, uid, stamp, '')
        except SkeletonFormatError as e:
            out.append((uid, stamp, e.cause))
            continue
        out.append((uid, stamp, 'duplicate user id' if uid in seen else None))
        seen.add(uid)
    return out


_NO_RELIABILITY = np.zeros(0, np.float32)


__all__ = ['CdrScan', 'scan_cdr']
