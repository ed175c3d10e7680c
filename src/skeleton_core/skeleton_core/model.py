"""The skeleton model: the one source of truth for joints, the tree and the standard body.

Joint order and names are those of the Kinect SDK v1 (``NUI_SKELETON_POSITION_INDEX``): 20 joints,
rooted at HipCenter, 19 segments (one per non-root joint, from its parent to it).

Coordinates follow REP-103: x forward, y left, z up, metres. In the rest posture the body stands
on the floor (z = 0) at the origin, facing +x.

Standard body
-------------
Segment lengths and masses come from the anthropometric table of D. A. Winter, *Biomechanics and
Motor Control of Human Movement*, 4th ed., Wiley 2009, Table 4.1 and Fig. 4.1 (segment lengths as
fractions of body height H, segment masses as fractions of body mass M), for the standard body
``H = 1.75 m``, ``M = 75 kg``. Winter gives whole-trunk figures; the Kinect skeleton splits the
trunk at the "Spine" joint, so we place that joint at 35 % of the hip-to-shoulder height and give
the abdomen and thorax their Winter masses (0.139 M and 0.216 M, the thorax minus 2 x 0.020 M for the
shoulder-girdle segments); the pelvis (0.142 M) is shared by the two hip segments. Hip joint centres
are 0.5 x Winter's hip width apart laterally (0.191 H), as Kinect reports them at the greater
trochanter. The hand joint is at the centre of the hand (half of Winter's hand length 0.108 H); the
foot joint sits half a foot length (0.152 H) ahead of the ankle on the floor.

The function :func:`standard_body` returns these numbers scaled to any height, so the reliability
term can use "the standard body scaled to the user's height" before a reference is captured.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Tuple

import numpy as np

# --------------------------------------------------------------------------------------------
# Joints
# --------------------------------------------------------------------------------------------
JOINT_NAMES: Tuple[str, ...] = (
    'HipCenter', 'Spine', 'ShoulderCenter', 'Head',
    'ShoulderLeft', 'ElbowLeft', 'WristLeft', 'HandLeft',
    'ShoulderRight', 'ElbowRight', 'WristRight', 'HandRight',
    'HipLeft', 'KneeLeft', 'AnkleLeft', 'FootLeft',
    'HipRight', 'KneeRight', 'AnkleRight', 'FootRight',
)
NUM_JOINTS = len(JOINT_NAMES)
JOINT_INDEX: Dict[str, int] = {name: i for i, name in enumerate(JOINT_NAMES)}

HIP_CENTER, SPINE, SHOULDER_CENTER, HEAD = 0, 1, 2, 3
SHOULDER_LEFT, ELBOW_LEFT, WRIST_LEFT, HAND_LEFT = 4, 5, 6, 7
SHOULDER_RIGHT, ELBOW_RIGHT, WRIST_RIGHT, HAND_RIGHT = 8, 9, 10, 11
HIP_LEFT, KNEE_LEFT, ANKLE_LEFT, FOOT_LEFT = 12, 13, 14, 15
HIP_RIGHT, KNEE_RIGHT, ANKLE_RIGHT, FOOT_RIGHT = 16, 17, 18, 19
ROOT = HIP_CENTER

# Parent of every joint (-1 for the root). Parents always come before children.
PARENTS: Tuple[int, ...] = (
    -1, HIP_CENTER, SPINE, SHOULDER_CENTER,
    SHOULDER_CENTER, SHOULDER_LEFT, ELBOW_LEFT, WRIST_LEFT,
    SHOULDER_CENTER, SHOULDER_RIGHT, ELBOW_RIGHT, WRIST_RIGHT,
    HIP_CENTER, HIP_LEFT, KNEE_LEFT, ANKLE_LEFT,
    HIP_CENTER, HIP_RIGHT, KNEE_RIGHT, ANKLE_RIGHT,
)

# Tracking states (Kinect SDK convention; identical to the constants in skeleton_msgs/Skeleton)
NOT_TRACKED, INFERRED, TRACKED = 0, 1, 2
TRACKING_STATES = (NOT_TRACKED, INFERRED, TRACKED)

# Segments: one per non-root joint, named by the joint it ends at. SEGMENTS[k] = (parent, child).
SEGMENTS: Tuple[Tuple[int, int], ...] = tuple(
    (PARENTS[j], j) for j in range(NUM_JOINTS) if PARENTS[j] >= 0)
NUM_SEGMENTS = len(SEGMENTS)
SEGMENT_CHILDREN: Tuple[int, ...] = tuple(c for _, c in SEGMENTS)
SEGMENT_PARENTS: Tuple[int, ...] = tuple(p for p, _ in SEGMENTS)
SEGMENT_NAMES: Tuple[str, ...] = tuple(
    f'{JOINT_NAMES[p]}-{JOINT_NAMES[c]}' for p, c in SEGMENTS)
# The same two as read-only index arrays for numpy: the (..., 19, 3) segment vectors of joint
# positions x (..., 20, 3) are ``x[..., SEGMENT_CHILD_INDEX, :] - x[..., SEGMENT_PARENT_INDEX, :]``
SEGMENT_PARENT_INDEX = np.array(SEGMENT_PARENTS)
SEGMENT_CHILD_INDEX = np.array(SEGMENT_CHILDREN)
SEGMENT_PARENT_INDEX.flags.writeable = False
SEGMENT_CHILD_INDEX.flags.writeable = False
# Index of the segment that ends at joint j (-1 for the root)
SEGMENT_OF_JOINT: Tuple[int, ...] = tuple(
    SEGMENT_CHILDREN.index(j) if j in SEGMENT_CHILDREN else -1 for j in range(NUM_JOINTS))

CHILDREN: Tuple[Tuple[int, ...], ...] = tuple(
    tuple(c for c in range(NUM_JOINTS) if PARENTS[c] == j) for j in range(NUM_JOINTS))

# Mirror image of every joint (left <-> right), for symmetry checks and data augmentation
MIRROR: Tuple[int, ...] = tuple(
    JOINT_INDEX[n.replace('Left', '#').replace('Right', 'Left').replace('#', 'Right')]
    for n in JOINT_NAMES)

# Body parts used by studies of joint subsets (Shum 2013, Table III)
LIMB_JOINTS: Dict[str, Tuple[int, ...]] = {
    'torso': (HIP_CENTER, SPINE, SHOULDER_CENTER, HEAD),
    'left_arm': (SHOULDER_LEFT, ELBOW_LEFT, WRIST_LEFT, HAND_LEFT),
    'right_arm': (SHOULDER_RIGHT, ELBOW_RIGHT, WRIST_RIGHT, HAND_RIGHT),
    'left_leg': (HIP_LEFT, KNEE_LEFT, ANKLE_LEFT, FOOT_LEFT),
    'right_leg': (HIP_RIGHT, KNEE_RIGHT, ANKLE_RIGHT, FOOT_RIGHT),
}
END_EFFECTORS: Tuple[int, ...] = (HEAD, HAND_LEFT, HAND_RIGHT, FOOT_LEFT, FOOT_RIGHT)
# the hip and shoulder lines a body's heading is measured from (geometry.facing_yaw)
HEADING_JOINTS: Tuple[int, ...] = (HIP_LEFT, HIP_RIGHT, SHOULDER_LEFT, SHOULDER_RIGHT)

# --------------------------------------------------------------------------------------------
# NiTE2 (OpenNI2 user tracker): 15 joints, nite::JointType order
# --------------------------------------------------------------------------------------------
NITE_JOINT_NAMES: Tuple[str, ...] = (
    'JOINT_HEAD', 'JOINT_NECK',
    'JOINT_LEFT_SHOULDER', 'JOINT_RIGHT_SHOULDER',
    'JOINT_LEFT_ELBOW', 'JOINT_RIGHT_ELBOW',
    'JOINT_LEFT_HAND', 'JOINT_RIGHT_HAND',
    'JOINT_TORSO',
    'JOINT_LEFT_HIP', 'JOINT_RIGHT_HIP',
    'JOINT_LEFT_KNEE', 'JOINT_RIGHT_KNEE',
    'JOINT_LEFT_FOOT', 'JOINT_RIGHT_FOOT',
)
# NiTE joint index -> Kinect joint index. NiTE's "hand" is at the wrist end of the forearm and its
# "foot" at the ankle, so they map to Wrist and Ankle; NiTE's torso is the Kinect Spine joint and its
# neck the ShoulderCenter. HipCenter is not reported by NiTE (it can be derived from the two hips by
# consumers that want it) and HandLeft/HandRight/FootLeft/FootRight do not exist in NiTE.
NITE_TO_KINECT: Tuple[int, ...] = (
    HEAD, SHOULDER_CENTER,
    SHOULDER_LEFT, SHOULDER_RIGHT,
    ELBOW_LEFT, ELBOW_RIGHT,
    WRIST_LEFT, WRIST_RIGHT,
    SPINE,
    HIP_LEFT, HIP_RIGHT,
    KNEE_LEFT, KNEE_RIGHT,
    ANKLE_LEFT, ANKLE_RIGHT,
)
NITE_MISSING: Tuple[int, ...] = tuple(
    j for j in range(NUM_JOINTS) if j not in NITE_TO_KINECT)  # marked NOT_TRACKED

# ROS 1 openni2_tracker TF frame names for the NiTE joints (suffix _<user_id> appended)
NITE_TF_NAMES: Tuple[str, ...] = (
    'head', 'neck', 'left_shoulder', 'right_shoulder', 'left_elbow', 'right_elbow',
    'left_hand', 'right_hand', 'torso', 'left_hip', 'right_hip', 'left_knee', 'right_knee',
    'left_foot', 'right_foot',
)

# --------------------------------------------------------------------------------------------
# Standard body (Winter 2009, Table 4.1; see module docstring)
# --------------------------------------------------------------------------------------------
STANDARD_HEIGHT = 1.75  # m
STANDARD_MASS = 75.0    # kg

# Winter's fractions of body height used below
_H_HIP = 0.530         # greater trochanter height
_H_SHOULDER = 0.818    # shoulder height
_H_HEAD = 0.936        # eye level, taken as the Kinect head joint
_W_SHOULDER = 0.259    # shoulder (biacromial) width
_W_HIP = 0.191         # hip width
_L_UPPER_ARM = 0.186
_L_FOREARM = 0.146
_L_HAND = 0.108
_L_THIGH = 0.245
_L_SHANK = 0.246
_H_ANKLE = 0.039
_L_FOOT = 0.152
_SPINE_SPLIT = 0.35    # Spine joint between hip and shoulder height (our choice, see docstring)

# Segment mass fractions of body mass, keyed by the segment's child joint (sum = 1)
SEGMENT_MASS_FRACTION: Dict[str, float] = {
    'Spine': 0.139,           # abdomen
    'ShoulderCenter': 0.176,  # thorax less the shoulder girdles
    'Head': 0.081,            # head and neck
    'ShoulderLeft': 0.020, 'ShoulderRight': 0.020,
    'ElbowLeft': 0.028, 'ElbowRight': 0.028,  # upper arm
    'WristLeft': 0.016, 'WristRight': 0.016,  # forearm
    'HandLeft': 0.006, 'HandRight': 0.006,    # hand
    'HipLeft': 0.071, 'HipRight': 0.071,      # half of the pelvis each
    'KneeLeft': 0.100, 'KneeRight': 0.100,    # thigh
    'AnkleLeft': 0.0465, 'AnkleRight': 0.0465,  # shank
    'FootLeft': 0.0145, 'FootRight': 0.0145,  # foot
}

# Capsule radius of each segment as a fraction of body height (for the physics character and viz;
# from Winter's segment circumferences / 2 pi, rounded).
SEGMENT_RADIUS_FRACTION: Dict[str, float] = {
    'Spine': 0.080, 'ShoulderCenter': 0.085, 'Head': 0.055,
    'ShoulderLeft': 0.030, 'ShoulderRight': 0.030,
    'ElbowLeft': 0.027, 'ElbowRight': 0.027,
    'WristLeft': 0.022, 'WristRight': 0.022,
    'HandLeft': 0.020, 'HandRight': 0.020,
    'HipLeft': 0.050, 'HipRight': 0.050,
    'KneeLeft': 0.040, 'KneeRight': 0.040,
    'AnkleLeft': 0.030, 'AnkleRight': 0.030,
    'FootLeft': 0.022, 'FootRight': 0.022,
}


def _tpose_offsets(height: float) -> np.ndarray:
    """Offset of every joint from its parent in the T-pose (REP-103, facing +x), shape (20, 3)."""
    h = height
    trunk = (_H_SHOULDER - _H_HIP) * h
    o = np.zeros((NUM_JOINTS, 3))
    o[SPINE] = (0.0, 0.0, _SPINE_SPLIT * trunk)
    o[SHOULDER_CENTER] = (0.0, 0.0, (1.0 - _SPINE_SPLIT) * trunk)
    o[HEAD] = (0.0, 0.0, (_H_HEAD - _H_SHOULDER) * h)
    for side, sign in (('Left', 1.0), ('Right', -1.0)):
        s, e, w, hd = (JOINT_INDEX[n + side] for n in ('Shoulder', 'Elbow', 'Wrist', 'Hand'))
        o[s] = (0.0, sign * 0.5 * _W_SHOULDER * h, 0.0)
        o[e] = (0.0, sign * _L_UPPER_ARM * h, 0.0)
        o[w] = (0.0, sign * _L_FOREARM * h, 0.0)
        o[hd] = (0.0, sign * 0.5 * _L_HAND * h, 0.0)
        hp, kn, an, ft = (JOINT_INDEX[n + side] for n in ('Hip', 'Knee', 'Ankle', 'Foot'))
        o[hp] = (0.0, sign * 0.5 * _W_HIP * h, 0.0)
        o[kn] = (0.0, 0.0, -_L_THIGH * h)
        o[an] = (0.0, 0.0, -_L_SHANK * h)
        o[ft] = (0.5 * _L_FOOT * h, 0.0, -_H_ANKLE * h)
    return o


@dataclass(frozen=True)
class Body:
    """Body dimensions: segment lengths (m), masses (kg) and capsule radii (m), per segment."""

    height: float
    mass: float
    rest_offsets: np.ndarray = field(repr=False)  # (20, 3) T-pose offsets from the parent
    segment_lengths: np.ndarray = field(repr=False)  # (19,) in SEGMENTS order
    segment_masses: np.ndarray = field(repr=False)   # (19,)
    segment_radii: np.ndarray = field(repr=False)    # (19,)
    root_height: float = 0.0  # HipCenter height above the floor in the rest pose

    def rest_positions(self) -> np.ndarray:
        """T-pose joint positions (20, 3), feet on the floor, facing +x."""
        p = forward_kinematics(self.rest_offsets, np.array([0.0, 0.0, self.root_height]))
        return p

    def bone_lengths_by_joint(self) -> np.ndarray:
        """(20,) length of the segment ending at each joint (0 for the root)."""
        out = np.zeros(NUM_JOINTS)
        out[SEGMENT_CHILD_INDEX] = self.segment_lengths
        return out

    def scaled(self, height: float) -> 'Body':
        return standard_body(height, self.mass * (height / self.height) ** 3)


def standard_body(height: float = STANDARD_HEIGHT, mass: float = STANDARD_MASS) -> Body:
    """The Winter (2009) standard body scaled to ``height`` (m) and ``mass`` (kg)."""
    if not np.isfinite(height) or height <= 0.5 or height > 2.6:
        raise ValueError(f'body height must be in (0.5, 2.6] m, got {height!r}')
    if not np.isfinite(mass) or mass <= 0:
        raise ValueError(f'body mass must be positive, got {mass!r}')
    offsets = _tpose_offsets(height)
    lengths = np.linalg.norm(offsets[SEGMENT_CHILD_INDEX], axis=1)
    names = [JOINT_NAMES[c] for c in SEGMENT_CHILDREN]
    masses = np.array([SEGMENT_MASS_FRACTION[n] * mass for n in names])
    radii = np.array([SEGMENT_RADIUS_FRACTION[n] * height for n in names])
    return Body(height=height, mass=mass, rest_offsets=offsets, segment_lengths=lengths,
                segment_masses=masses, segment_radii=radii, root_height=_H_HIP * height)


# --------------------------------------------------------------------------------------------
# Tree helpers
# --------------------------------------------------------------------------------------------
def _ancestor_matrix() -> np.ndarray:
    a = np.zeros((NUM_JOINTS, NUM_JOINTS))
    for j in range(NUM_JOINTS):
        k = j
        while k >= 0 and k != ROOT:
            a[j, k] = 1.0
            k = PARENTS[k]
    return a


# PATH_TO_ROOT[j, k] = 1 when k is j or one of its ancestors, the root excluded: positions relative
# to the root are PATH_TO_ROOT @ parent-relative offsets (one matrix product instead of a loop).
PATH_TO_ROOT = _ancestor_matrix()


def forward_kinematics(offsets: np.ndarray, root: np.ndarray) -> np.ndarray:
    """Positions from parent-relative offsets. ``offsets``: (..., 20, 3) (the root row is ignored),
    ``root``: (..., 3)."""
    offsets = np.asarray(offsets, dtype=float)
    return np.asarray(root, float)[..., None, :] + PATH_TO_ROOT @ offsets


def parent_relative(positions: np.ndarray) -> np.ndarray:
    """Offsets of every joint from its parent, (..., 20, 3); the root row holds the root position."""
    positions = np.asarray(positions, dtype=float)
    rel = positions.copy()
    rel[..., 1:, :] = positions[..., 1:, :] - positions[..., SEGMENT_PARENT_INDEX, :]
    return rel


def segment_lengths(positions: np.ndarray) -> np.ndarray:
    """Segment lengths (..., 19) of joint positions (..., 20, 3), SEGMENTS order."""
    positions = np.asarray(positions, dtype=float)
    d = positions[..., SEGMENT_CHILD_INDEX, :] - positions[..., SEGMENT_PARENT_INDEX, :]
    return np.linalg.norm(d, axis=-1)


def subtree(joint: int) -> List[int]:
    """The joint and all its descendants."""
    out = [joint]
    for c in CHILDREN[joint]:
        out.extend(subtree(c))
    return out


def estimate_height(positions: np.ndarray) -> float:
    """Standing height implied by a skeleton's segment lengths (ignores posture)."""
    lengths = segment_lengths(positions)
    ref = standard_body().segment_lengths
    # Ratio of summed leg+trunk+head chain lengths against the standard body
    chain = [SEGMENT_OF_JOINT[j] for j in (SPINE, SHOULDER_CENTER, HEAD, KNEE_LEFT, ANKLE_LEFT,
                                          KNEE_RIGHT, ANKLE_RIGHT)]
    ok = np.isfinite(lengths[chain])
    if not ok.any():
        return STANDARD_HEIGHT
    return float(STANDARD_HEIGHT * lengths[chain][ok].sum() / ref[chain][ok].sum())
