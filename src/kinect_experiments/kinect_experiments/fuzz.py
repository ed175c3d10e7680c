"""Malformed and adversarial skeleton messages for robustness tests and the soak (no rclpy here:
functions return ``SkeletonArray`` messages built from a valid one)."""
from __future__ import annotations

import copy
from typing import Callable, Dict

import numpy as np

from skeleton_core.conversions import SkeletonFrame, frames_to_array_msg
from skeleton_core.model import standard_body


def valid_array(stamp_ns: int, user_ids=(1,), offset=(2.5, 0.0, -0.8), rng=None):
    rng = rng or np.random.default_rng(0)
    frames = []
    for uid in user_ids:
        p = standard_body().rest_positions() + np.asarray(offset) + [0.0, 0.6 * (uid % 5), 0.0]
        p = p + rng.normal(0, 0.005, p.shape)
        frames.append(SkeletonFrame(positions=p, tracking_state=np.full(20, 2, np.uint8),
                                    user_id=int(uid), stamp_ns=stamp_ns, frame_id='kinect_link'))
    return frames_to_array_msg(frames, stamp_ns, 'kinect_link')


def _wrong_positions(m):
    m.skeletons[0].positions.pop()


def _wrong_tracking(m):
    m.skeletons[0].tracking_state = [2] * 7


def _nan(m):
    m.skeletons[0].positions[5].x = float('nan')


def _inf(m):
    m.skeletons[0].positions[2].z = float('inf')


def _huge(m):
    m.skeletons[0].positions[9].y = 1e12


def _unknown_state(m):
    m.skeletons[0].tracking_state = [9] * 20


def _empty_skeleton(m):
    sk = m.skeletons[0]
    sk.positions, sk.orientations, sk.tracking_state, sk.reliability = [], [], [], []


def _empty_array(m):
    m.skeletons = []


def _duplicate_ids(m):
    m.skeletons.append(copy.deepcopy(m.skeletons[0]))


def _bad_reliability(m):
    m.skeletons[0].reliability = [2.0] * 20


def _bad_quaternion(m):
    m.skeletons[0].orientations[0].w = float('nan')


MUTATIONS: Dict[str, Callable] = {
    'wrong positions length': _wrong_positions,
    'wrong tracking_state length': _wrong_tracking,
    'NaN position': _nan,
    'inf position': _inf,
    'huge coordinate': _huge,
    'unknown tracking state': _unknown_state,
    'empty skeleton arrays': _empty_skeleton,
    'empty SkeletonArray': _empty_array,
    'duplicate user ids': _duplicate_ids,
    'reliability out of range': _bad_reliability,
    'NaN quaternion': _bad_quaternion,
}


def malformed(kind: str, stamp_ns: int, user_id: int = 1):
    """A SkeletonArray broken in the named way (see MUTATIONS)."""
    m = valid_array(stamp_ns, (user_id,))
    MUTATIONS[kind](m)
    return m
