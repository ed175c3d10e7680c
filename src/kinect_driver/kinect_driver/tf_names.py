"""TF frame names like the ROS 1 ``openni2_tracker`` (``head_1``, ``neck_1``, ``torso_1``, ...):
one frame per NiTE joint and user, child of the sensor frame (names from ``model.NITE_TF_NAMES``)."""
from __future__ import annotations

from typing import List, Tuple

from skeleton_core.model import NITE_TF_NAMES, NITE_TO_KINECT, NOT_TRACKED


def tf_frame_name(nite_joint: int, user_id: int, prefix: str = '') -> str:
    return f'{prefix}{NITE_TF_NAMES[nite_joint]}_{user_id}'


def tf_frames(frame, prefix: str = '') -> List[Tuple[str, int]]:
    """(child frame name, Kinect joint index) of every NiTE joint of a SkeletonFrame that is not
    NOT_TRACKED."""
    out = []
    for k, j in enumerate(NITE_TO_KINECT):
        if frame.tracking_state[j] != NOT_TRACKED:
            out.append((tf_frame_name(k, frame.user_id, prefix), j))
    return out
