"""UI-PRMD Kinect recordings: reader, forward kinematics, 22 -> 20 joint mapping, sensor frame.

Data set: Vakanski, Jun, Paul, Baker, "A Data Set of Human Body Movements for Physical
Rehabilitation Exercises", *Data* 3(1):2, 2018 (PDDL 1.0). Format (see the data set README):

* ``Kinect/Positions/mMM_sSS_eEE_positions.txt.gz``: one frame per line, 66 comma-separated numbers,
  22 joints x (x, y, z) in cm. Row 0 is the absolute Waist position; every other row is the joint's
  offset from its parent *in the parent's local frame*.
* ``Kinect/Angles/mMM_sSS_eEE_angles.txt.gz``: the same layout, each joint's rotation relative to
  its parent, degrees, columns (rx, ry, rz), composing as ``R = Rz(rz) Rx(rx) Ry(ry)``.
* Forward kinematics: ``R_g[j] = R_g[parent] R_l[j]``, ``p[j] = p[parent] + R_g[parent] offset[j]``.

File frame -> sensor frame
--------------------------
The files' frame is y up (floor at y ~ 0), x towards the subject's left, z towards the sensor:
Kinect camera space turned 180 deg about the vertical and moved down to the floor. We undo the turn,
which gives REP-103 axes of the sensor (x forward out of the sensor, y to the sensor's left, z up)::

    X = -z / 100,   Y = -x / 100,   Z = y / 100      (metres)

The vertical shift cannot be undone (the sensor height is not in the files), so the resulting frame
is the sensor's REP-103 frame **with its origin dropped to the floor**: the origin is on the floor
directly below the sensor, z = 0 is the floor, and the subject stands ~2.2-2.8 m in front
(x > 0). The camera tilt, if any, was already removed by the data set's export (the floor is level
in the files). :func:`load_dataset` (and the importer, ``--sensor-height``, default 0.8 m) can
put the origin at a nominal sensor height instead (floor at z = -height), the synthetic
driver's convention; the frame_id is ``'kinect_link'``.

Joint mapping (one table: :data:`KINECT_FROM_UIPRMD`)
----------------------------------------------------
UI-PRMD's 22-joint skeleton is Kinect v2's 25 minus the hand tips and thumbs, renamed BVH-style.
Bone lengths in the files show where each joint sits: Chest -> Neck is < 1 cm and Neck -> Head is
~7 cm, HeadTip is ~15 cm above Head, so the Kinect v2 "Head" (head centre) is HeadTip, the collar
joints sit on the Chest, and LShoulder/LElbow/LWrist are the v2 ShoulderLeft/ElbowLeft/WristLeft.
Kinect v1 (our model) joints take them as follows; hands are not in the recordings, so HandLeft /
HandRight are extrapolated from the forearm (wrist + ``HAND_FOREARM_RATIO`` x (wrist - elbow), the
standard body's wrist-to-hand-centre / forearm ratio) and marked NOT_TRACKED. Every mapped joint
is TRACKED (the files carry no tracking state).
"""
from __future__ import annotations

import gzip
import re
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np

from skeleton_core.model import (JOINT_NAMES, NOT_TRACKED, NUM_JOINTS, TRACKED,
                    ELBOW_LEFT, ELBOW_RIGHT, HAND_LEFT, HAND_RIGHT, WRIST_LEFT, WRIST_RIGHT,
                    standard_body)
from skeleton_core.conversions import SkeletonFrame

FRAME_RATE = 30.0  # Hz, Kinect streams
FRAME_ID = 'kinect_link'

UIPRMD_JOINTS: Tuple[str, ...] = (
    'Waist', 'Spine', 'Chest', 'Neck', 'Head', 'HeadTip',
    'LCollar', 'LShoulder', 'LElbow', 'LWrist',
    'RCollar', 'RShoulder', 'RElbow', 'RWrist',
    'LHip', 'LKnee', 'LAnkle', 'LToes',
    'RHip', 'RKnee', 'RAnkle', 'RToes',
)
UIPRMD_INDEX: Dict[str, int] = {n: i for i, n in enumerate(UIPRMD_JOINTS)}
UIPRMD_PARENTS: Tuple[int, ...] = (
    -1, 0, 1, 2, 3, 4,
    2, 6, 7, 8,
    2, 10, 11, 12,
    0, 14, 15, 16,
    0, 18, 19, 20,
)
NUM_UIPRMD = len(UIPRMD_JOINTS)
NUM_COLUMNS = 3 * NUM_UIPRMD  # 66

# THE mapping table: Kinect v1 joint -> UI-PRMD joint (None = not in the recordings, extrapolated
# and NOT_TRACKED). See the module docstring for why each joint maps where it does.
KINECT_FROM_UIPRMD: Dict[str, Optional[str]] = {
    'HipCenter': 'Waist',         # v2 SpineBase
    'Spine': 'Spine',             # v2 SpineMid
    'ShoulderCenter': 'Chest',    # v2 SpineShoulder (the collars start here)
    'Head': 'HeadTip',            # v2 Head (head centre), ~15 cm above the BVH "Head" joint
    'ShoulderLeft': 'LShoulder', 'ElbowLeft': 'LElbow', 'WristLeft': 'LWrist', 'HandLeft': None,
    'ShoulderRight': 'RShoulder', 'ElbowRight': 'RElbow', 'WristRight': 'RWrist',
    'HandRight': None,
    'HipLeft': 'LHip', 'KneeLeft': 'LKnee', 'AnkleLeft': 'LAnkle', 'FootLeft': 'LToes',
    'HipRight': 'RHip', 'KneeRight': 'RKnee', 'AnkleRight': 'RAnkle', 'FootRight': 'RToes',
}
SOURCE_INDEX: Tuple[int, ...] = tuple(
    -1 if KINECT_FROM_UIPRMD[n] is None else UIPRMD_INDEX[KINECT_FROM_UIPRMD[n]]
    for n in JOINT_NAMES)
MISSING_JOINTS: Tuple[int, ...] = tuple(j for j in range(NUM_JOINTS) if SOURCE_INDEX[j] < 0)

_SB = standard_body()
HAND_FOREARM_RATIO = float(_SB.bone_lengths_by_joint()[HAND_LEFT]
                           / _SB.bone_lengths_by_joint()[WRIST_LEFT])

MOVEMENTS: Dict[int, str] = {
    1: 'deep squat', 2: 'hurdle step', 3: 'inline lunge', 4: 'side lunge', 5: 'sit to stand',
    6: 'standing active straight-leg raise', 7: 'standing shoulder abduction',
    8: 'standing shoulder extension', 9: 'standing shoulder internal-external rotation',
    10: 'standing shoulder scaption',
}
# Known real tracking failure (data set README): inline lunge, subject 1
TRACKING_FAILURE_CASES = (('m03', 's01'),)

_NAME_RE = re.compile(r'^m(\d\d)_s(\d\d)_e(\d\d)_(positions|angles)\.txt(\.gz)?$')


# UI-PRMD's skeletons come from the Kinect v2 SDK body tracker (skeleton_core.tracker)
TRACKER = 'kinect_v2_sdk'

class UIPRMDFormatError(ValueError):
    """A UI-PRMD file that cannot be used; the message names the file and the reason."""

    def __init__(self, path, reason: str):
        super().__init__(f'{path}: {reason}')
        self.path = str(path)
        self.reason = reason


@dataclass(frozen=True)
class ClipId:
    movement: int
    subject: int
    repetition: int

    @property
    def name(self) -> str:
        return f'm{self.movement:02d}_s{self.subject:02d}_e{self.repetition:02d}'

    @property
    def session(self) -> str:
        return f's{self.subject:02d}'

    @property
    def is_tracking_failure(self) -> bool:
        return (f'm{self.movement:02d}', f's{self.subject:02d}') in TRACKING_FAILURE_CASES


def parse_name(path) -> ClipId:
    m = _NAME_RE.match(Path(path).name)
    if not m:
        raise UIPRMDFormatError(path, 'name is not mMM_sSS_eEE_{positions,angles}.txt[.gz]')
    return ClipId(int(m.group(1)), int(m.group(2)), int(m.group(3)))


def read_table(path, ncols: int) -> np.ndarray:
    """Read a (gzipped) comma-separated numeric table with exactly ``ncols`` columns.

    Raises :class:`UIPRMDFormatError` naming the file for: unreadable/truncated gzip, empty file,
    a line with the wrong number of columns, a non-numeric, NaN or infinite value.
    """
    path = Path(path)
    opener = gzip.open if path.suffix == '.gz' else open
    try:
        with opener(path, 'rt') as f:
            text = f.read()
    except (OSError, EOFError, zlib.error, UnicodeDecodeError) as exc:
        # gzip.BadGzipFile is an OSError; a truncated stream raises EOFError
        raise UIPRMDFormatError(path, f'cannot read ({type(exc).__name__}: {exc or "truncated"})') \
            from None
    rows: List[List[float]] = []
    for lineno, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line:
            continue
        parts = line.rstrip(',').split(',')
        if len(parts) != ncols:
            raise UIPRMDFormatError(path, f'line {lineno}: {len(parts)} columns, expected {ncols}')
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            raise UIPRMDFormatError(path, f'line {lineno}: non-numeric value') from None
        if not all(np.isfinite(vals)):
            raise UIPRMDFormatError(path, f'line {lineno}: NaN or infinite value')
        rows.append(vals)
    if not rows:
        raise UIPRMDFormatError(path, 'empty (no frames)')
    return np.array(rows, dtype=float)


# ------------------------------------------------------------------------------------------
# Forward kinematics
# ------------------------------------------------------------------------------------------
def euler_zxy(angles_deg: np.ndarray) -> np.ndarray:
    """Rotation matrices ``Rz(rz) Rx(rx) Ry(ry)`` from (..., 3) angles (rx, ry, rz) in degrees."""
    a = np.radians(np.asarray(angles_deg, dtype=float))
    cx, sx = np.cos(a[..., 0]), np.sin(a[..., 0])
    cy, sy = np.cos(a[..., 1]), np.sin(a[..., 1])
    cz, sz = np.cos(a[..., 2]), np.sin(a[..., 2])
    o, z = np.ones_like(cx), np.zeros_like(cx)
    rx = np.stack([o, z, z, z, cx, -sx, z, sx, cx], -1).reshape(a.shape[:-1] + (3, 3))
    ry = np.stack([cy, z, sy, z, o, z, -sy, z, cy], -1).reshape(a.shape[:-1] + (3, 3))
    rz = np.stack([cz, -sz, z, sz, cz, z, z, z, o], -1).reshape(a.shape[:-1] + (3, 3))
    return rz @ rx @ ry


def forward_kinematics(offsets: np.ndarray, angles_deg: np.ndarray) -> np.ndarray:
    """UI-PRMD positions (N, 22, 3) in the file frame (cm) from offsets and local angles.

    ``offsets``: (N, 22, 3), row 0 the absolute Waist position; ``angles_deg``: (N, 22, 3).
    """
    offsets = np.asarray(offsets, dtype=float)
    rl = euler_zxy(angles_deg)
    rg = np.empty_like(rl)
    pos = np.empty_like(offsets)
    pos[:, 0] = offsets[:, 0]
    rg[:, 0] = rl[:, 0]
    for j in range(1, NUM_UIPRMD):
        p = UIPRMD_PARENTS[j]
        rg[:, j] = rg[:, p] @ rl[:, j]
        pos[:, j] = pos[:, p] + np.einsum('nab,nb->na', rg[:, p], offsets[:, j])
    return pos


# File frame (cm, y up, x subject's left, z towards the sensor) -> REP-103 sensor frame on the floor
FILE_TO_SENSOR = np.array([[0.0, 0.0, -1.0],
                           [-1.0, 0.0, 0.0],
                           [0.0, 1.0, 0.0]]) / 100.0


def file_to_sensor(p_cm: np.ndarray) -> np.ndarray:
    return np.asarray(p_cm, dtype=float) @ FILE_TO_SENSOR.T


def to_kinect20(pos22: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Map (..., 22, 3) UI-PRMD positions to (..., 20, 3) Kinect v1 joints and tracking states."""
    pos22 = np.asarray(pos22, dtype=float)
    out = np.zeros(pos22.shape[:-2] + (NUM_JOINTS, 3))
    state = np.full(NUM_JOINTS, TRACKED, np.uint8)
    for j in range(NUM_JOINTS):
        if SOURCE_INDEX[j] >= 0:
            out[..., j, :] = pos22[..., SOURCE_INDEX[j], :]
    for hand, wrist, elbow in ((HAND_LEFT, WRIST_LEFT, ELBOW_LEFT),
                               (HAND_RIGHT, WRIST_RIGHT, ELBOW_RIGHT)):
        out[..., hand, :] = out[..., wrist, :] + HAND_FOREARM_RATIO * (
            out[..., wrist, :] - out[..., elbow, :])
        state[hand] = NOT_TRACKED
    assert all(state[j] == NOT_TRACKED for j in MISSING_JOINTS)
    return out, state


@dataclass
class KinectClip:
    clip: ClipId
    positions: np.ndarray       # (N, 20, 3) m, REP-103 sensor frame on the floor
    tracking_state: np.ndarray  # (20,) uint8
    positions22: np.ndarray     # (N, 22, 3) m, same frame, all UI-PRMD joints

    @property
    def num_frames(self) -> int:
        return len(self.positions)

    def times(self) -> np.ndarray:
        return np.arange(self.num_frames) / FRAME_RATE


def angles_path_for(positions_path) -> Path:
    p = Path(positions_path)
    return p.parent.parent / 'Angles' / p.name.replace('_positions', '_angles')


def load_kinect_clip(positions_path, angles_path=None) -> KinectClip:
    """Read one repetition (positions + angles), run FK, map to the 20-joint sensor frame."""
    positions_path = Path(positions_path)
    clip = parse_name(positions_path)
    angles_path = Path(angles_path) if angles_path is not None else angles_path_for(positions_path)
    if not angles_path.exists():
        raise UIPRMDFormatError(angles_path, 'missing (needed for the forward kinematics)')
    off = read_table(positions_path, NUM_COLUMNS).reshape(-1, NUM_UIPRMD, 3)
    ang = read_table(angles_path, NUM_COLUMNS).reshape(-1, NUM_UIPRMD, 3)
    if len(off) != len(ang):
        raise UIPRMDFormatError(positions_path,
                                f'{len(off)} frames but {angles_path.name} has {len(ang)}')
    p22 = file_to_sensor(forward_kinematics(off, ang))
    if np.any(np.abs(p22) > 20.0):
        raise UIPRMDFormatError(positions_path, 'positions farther than 20 m from the sensor')
    p20, state = to_kinect20(p22)
    return KinectClip(clip=clip, positions=p20, tracking_state=state, positions22=p22)


def find_clips(src) -> List[Path]:
    """All Kinect position files under ``src`` (the ui-prmd folder), sorted."""
    src = Path(src)
    d = src / 'Kinect' / 'Positions'
    if not d.is_dir():
        d = src
    return sorted(p for p in d.iterdir() if p.name.endswith(('_positions.txt.gz',
                                                              '_positions.txt')))


def clip_frames(kclip: KinectClip, start_ns: int = 0, user_id: int = 1,
                frame_id: str = FRAME_ID, positions: Optional[np.ndarray] = None,
                tracking_state: Optional[np.ndarray] = None):
    """SkeletonFrames at 30 Hz with monotonic stamps starting at ``start_ns``."""
    pos = kclip.positions if positions is None else positions
    st = kclip.tracking_state if tracking_state is None else tracking_state
    period = int(round(1e9 / FRAME_RATE))
    return [SkeletonFrame(positions=pos[i].copy(), tracking_state=st.copy(), user_id=user_id,
                          stamp_ns=start_ns + i * period, frame_id=frame_id)
            for i in range(len(pos))]


__all__ = ['UIPRMD_JOINTS', 'UIPRMD_PARENTS', 'KINECT_FROM_UIPRMD', 'SOURCE_INDEX',
           'MISSING_JOINTS', 'HAND_FOREARM_RATIO', 'MOVEMENTS', 'ClipId', 'KinectClip',
           'UIPRMDFormatError', 'parse_name', 'read_table', 'euler_zxy', 'forward_kinematics',
           'file_to_sensor', 'to_kinect20', 'load_kinect_clip', 'find_clips', 'clip_frames',
           'FRAME_RATE', 'FRAME_ID']
