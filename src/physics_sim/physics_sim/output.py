"""The characters' states as the skeletons the physics node publishes: every joint tracked and
fully reliable, in TF's world (the simulated floor's lift taken off).

:func:`output_frames` checks all characters' arrays at once, with the same arithmetic as
``validate_arrays`` per frame (positions within range and finite, quaternions finite and scaled
to unit length), so that ``frames_to_cdr(..., validated=True)`` writes the same bytes as the
frame-by-frame check would, at one numpy call per check instead of a few per character.
"""
from __future__ import annotations

from typing import Dict, List, Tuple

import numpy as np
from skeleton_core.conversions import MAX_ABS_COORDINATE, SkeletonFrame
from skeleton_core.model import NUM_JOINTS, TRACKED

from .config import CharacterState


def _constant(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False   # shared by every published frame
    return a


TRACKED_ALL = _constant(np.full(NUM_JOINTS, TRACKED, np.uint8))
RELIABLE_ALL = _constant(np.ones(NUM_JOINTS, np.float32))


def output_frames(states: Dict[int, CharacterState], lift: np.ndarray,
                  frame_id: str) -> Tuple[List[SkeletonFrame], int, bool]:
    """(frames, newest target stamp, validated) of ``states`` (``lift``: (3,) taken off every
    position). ``validated``: every array is what ``validate_arrays`` returns for it; False when a
    check failed (a non-finite state): then the frames are as they came, and the caller's
    frame-by-frame validation says which and why."""
    if not states:
        return [], 0, True
    sts = list(states.values())
    pos = np.concatenate([st.positions for st in sts]) - lift
    quat = np.concatenate([st.orientations for st in sts])
    ok = bool(np.abs(pos).max() <= MAX_ABS_COORDINATE)   # also False for NaN
    if ok:
        n = np.sqrt(np.einsum('ij,ij->i', quat, quat))
        ok = bool(np.isfinite(n).all() and n.min() >= 1e-9)
        if ok:
            quat = quat / n[:, None]
    if not ok:
        quat = np.concatenate([st.orientations for st in sts])
    frames = []
    latest = 0
    for i, st in enumerate(sts):
        r = slice(i * NUM_JOINTS, (i + 1) * NUM_JOINTS)
        frames.append(SkeletonFrame(
            positions=pos[r], tracking_state=TRACKED_ALL, reliability=RELIABLE_ALL,
            orientations=quat[r], user_id=st.user_id, stamp_ns=st.stamp_ns, frame_id=frame_id))
        latest = max(latest, st.stamp_ns)
    return frames, latest, ok


__all__ = ['output_frames', 'TRACKED_ALL', 'RELIABLE_ALL']
