"""Motion clips on the Kinect skeleton, and the CMU (cgspeed BVH) importer.

A :class:`MotionClip` holds world-space joint positions and segment orientations of the 20 Kinect
joints (``model.JOINT_NAMES``) in REP-103 metres: x forward, y left, z up, floor at z = 0.

Orientation convention (shared with :mod:`skeleton_data.motions` and the database)
---------------------------------------------------------------------------------
``orientations[t, j]`` (xyzw) is the global orientation of the segment that *ends* at joint j
(joint 0: the pelvis). Identity means "as in the standard body's T-pose facing +x", i.e.
``quat_rotate(orientations[t, j], unit(standard_body().rest_offsets[j]))`` is the direction of the
segment from ``PARENTS[j]`` to j (exactly, for built-in motions and mocap alike).

CMU -> Kinect mapping (the one table: :data:`CMU_TO_KINECT`)
-----------------------------------------------------------
Kinect joints are points on the mocap skeleton; segment orientations are the global rotation of one
mocap bone (:data:`CMU_ORIENTATION_SOURCE`), composed with a constant per-subject correction that
turns the standard body's rest direction into the mocap bone's rest direction; for segments that
span several bones (Spine-ShoulderCenter, ShoulderCenter-Head: up to ~25 deg off) a final minimal
swing aligns the orientation with the actual segment, so the twist comes from the source bone and
the direction from the positions. Choices:

* HipCenter = ``Hips`` (pelvis centre); HipLeft/Right = ``LeftUpLeg``/``RightUpLeg`` (hip joint
  centres), Knee = ``Leg``, Ankle = ``Foot``, Foot = ``ToeBase`` (ball of the foot; the toe end
  sites are ignored).
* Spine = ``Spine`` (top of CMU's lower back, 38 % of the hip-to-shoulder height; the standard body
  puts it at 35 %).
* ShoulderCenter = midpoint of ``LeftArm`` and ``RightArm``. In the cgspeed skeleton ``Neck``
  has a zero offset from ``Spine1`` and lies 7 cm *below* the shoulder line, so ``Neck`` would tilt
  both clavicles upwards; Kinect reports ShoulderCenter on the shoulder line.
* Head = midpoint of ``Head`` (top of the neck) and the head's End Site (top of the skull): Kinect's
  head joint is near the centre of the head, not at the neck.
* Shoulder = ``Arm``, Elbow = ``ForeArm``, Wrist = ``Hand``, Hand = ``LeftHandIndex1`` /
  ``RightHandIndex1`` with the finger channels zeroed (a point 3.3 cm along the hand, rigid with the
  wrist bone). CMU says finger/thumb data is not captured, so ``*FingerBase``, ``*HandIndex1`` and
  ``*Thumb`` channels are set to 0 before forward kinematics.

Axes: the cgspeed BVH is Y-up with the T-pose facing +Z, so the body's left is +X. REP-103 is
``x = Z_bvh, y = X_bvh, z = Y_bvh`` (a proper rotation, :data:`BVH_TO_REP103`). Units: 1 CMU unit =
1/0.45 inch = 0.056444 m. The CMU floor is at Y = 0 (toe joints reach -0.4 cm in 08_01), so no floor
offset is applied. Frame 0 of every cgspeed file is a synthetic T-pose and is dropped.
"""
from __future__ import annotations

import csv
import logging
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
from scipy.spatial.transform import Rotation

from .bvh import Bvh, BvhError, load_bvh
from skeleton_core.geometry import quat_multiply, quat_rotate
from skeleton_core.model import (JOINT_NAMES, MIRROR, NUM_JOINTS, PARENTS, SEGMENT_PARENT_INDEX,
                                 standard_body)

__all__ = [
    'MotionClip', 'MocapError', 'CMU_TO_KINECT', 'CMU_ORIENTATION_SOURCE', 'CMU_UNIT',
    'BVH_TO_REP103', 'FIVE_CLASSES', 'MOTION_CLASSES', 'load_cmu_clip', 'load_cmu_index',
    'load_cmu_clips', 'cmu_split', 'split_clips', 'mirror_clip', 'rest_directions',
]

log = logging.getLogger(__name__)

# Shum et al. 2013, Table I
FIVE_CLASSES: Tuple[str, ...] = ('locomotion', 'object_handling', 'upper_body', 'boxing',
                                 'sword_fighting')
MOTION_CLASSES: Tuple[str, ...] = FIVE_CLASSES + ('other',)

CMU_UNIT = 0.056444  # metres per CMU ASF length unit (1/0.45 inch)
# rep = BVH_TO_REP103 @ bvh: x_rep = Z_bvh (forward), y_rep = X_bvh (left), z_rep = Y_bvh (up)
BVH_TO_REP103 = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])

# Kinect joint -> weighted mocap points ('Joint' or 'Joint/End' for that joint's End Site)
CMU_TO_KINECT: Dict[str, Tuple[Tuple[str, float], ...]] = {
    'HipCenter': (('Hips', 1.0),),
    'Spine': (('Spine', 1.0),),
    'ShoulderCenter': (('LeftArm', 0.5), ('RightArm', 0.5)),
    'Head': (('Head', 0.5), ('Head/End', 0.5)),
    'ShoulderLeft': (('LeftArm', 1.0),),
    'ElbowLeft': (('LeftForeArm', 1.0),),
    'WristLeft': (('LeftHand', 1.0),),
    'HandLeft': (('LeftHandIndex1', 1.0),),
    'ShoulderRight': (('RightArm', 1.0),),
    'ElbowRight': (('RightForeArm', 1.0),),
    'WristRight': (('RightHand', 1.0),),
    'HandRight': (('RightHandIndex1', 1.0),),
    'HipLeft': (('LeftUpLeg', 1.0),),
    'KneeLeft': (('LeftLeg', 1.0),),
    'AnkleLeft': (('LeftFoot', 1.0),),
    'FootLeft': (('LeftToeBase', 1.0),),
    'HipRight': (('RightUpLeg', 1.0),),
    'KneeRight': (('RightLeg', 1.0),),
    'AnkleRight': (('RightFoot', 1.0),),
    'FootRight': (('RightToeBase', 1.0),),
}
# Kinect joint -> mocap bone whose global rotation orients the segment ending at that joint
CMU_ORIENTATION_SOURCE: Dict[str, str] = {
    'HipCenter': 'Hips', 'Spine': 'LowerBack', 'ShoulderCenter': 'Spine1', 'Head': 'Head',
    'ShoulderLeft': 'LeftShoulder', 'ElbowLeft': 'LeftArm', 'WristLeft': 'LeftForeArm',
    'HandLeft': 'LeftHand',
    'ShoulderRight': 'RightShoulder', 'ElbowRight': 'RightArm', 'WristRight': 'RightForeArm',
    'HandRight': 'RightHand',
    'HipLeft': 'Hips', 'KneeLeft': 'LeftUpLeg', 'AnkleLeft': 'LeftLeg', 'FootLeft': 'LeftFoot',
    'HipRight': 'Hips', 'KneeRight': 'RightUpLeg', 'AnkleRight': 'RightLeg',
    'FootRight': 'RightFoot',
}
# Channels CMU says were not captured (set to zero)
CMU_IGNORED_JOINTS = ('LeftFingerBase', 'LeftHandIndex1', 'LThumb',
                      'RightFingerBase', 'RightHandIndex1', 'RThumb')


class MocapError(ValueError):
    """A mocap file that cannot be turned into a clip (message names the file)."""


@dataclass
class MotionClip:
    """A motion on the 20-joint Kinect skeleton, world frame, REP-103 metres."""

    name: str
    motion_class: str
    fps: float
    positions: np.ndarray      # (T, 20, 3)
    orientations: np.ndarray   # (T, 20, 4) xyzw, see module docstring
    source: str = ''
    description: str = ''

    def __post_init__(self):
        self.positions = np.asarray(self.positions, dtype=float)
        self.orientations = np.asarray(self.orientations, dtype=float)
        t = self.positions.shape[0]
        if self.positions.shape != (t, NUM_JOINTS, 3):
            raise ValueError(f'{self.name}: positions must be (T, 20, 3), '
                             f'got {self.positions.shape}')
        if self.orientations.shape != (t, NUM_JOINTS, 4):
            raise ValueError(f'{self.name}: orientations must be (T, 20, 4), '
                             f'got {self.orientations.shape}')

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    @property
    def duration(self) -> float:
        return len(self) / self.fps

    def slice(self, start: int, stop: Optional[int] = None, suffix: str = '') -> 'MotionClip':
        return replace(self, name=self.name + suffix, positions=self.positions[start:stop].copy(),
                       orientations=self.orientations[start:stop].copy())


def rest_directions(body=None) -> np.ndarray:
    """(20, 3) unit direction of every segment in the standard T-pose (row 0: zeros)."""
    body = standard_body() if body is None else body
    off = body.rest_offsets.copy()
    n = np.linalg.norm(off, axis=1, keepdims=True)
    return np.where(n > 0, off / np.maximum(n, 1e-12), 0.0)


def _min_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Quaternion (xyzw) of the smallest rotation taking unit vector a to unit vector b."""
    c = np.cross(a, b)
    d = float(np.dot(a, b))
    if d < -1.0 + 1e-9:  # opposite: any perpendicular axis
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return np.array([*axis, 0.0])
    q = np.array([c[0], c[1], c[2], 1.0 + d])
    return q / np.linalg.norm(q)


def _min_rotation_batch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched smallest rotations taking unit vectors a to b (..., 3) -> (..., 4); for (near)
    opposite vectors, which cannot occur for the small residuals this is used on, identity."""
    c = np.cross(a, b)
    w = 1.0 + np.sum(a * b, -1, keepdims=True)
    q = np.concatenate([c, w], -1)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    ident = np.zeros_like(q)
    ident[..., 3] = 1.0
    return np.where(n > 1e-9, q / np.maximum(n, 1e-12), ident)


def _kinect_points(bvh: Bvh, pos: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Kinect joint positions (F, 20, 3) in BVH axes from mocap joint / End Site positions."""
    out = np.zeros(pos.shape[:1] + (NUM_JOINTS, 3))
    for j, name in enumerate(JOINT_NAMES):
        for src, w in CMU_TO_KINECT[name]:
            if src.endswith('/End'):
                out[:, j] += w * ends[:, bvh.end_site_of(src[:-4])]
            else:
                out[:, j] += w * pos[:, bvh.index(src)]
    return out


_INDEX_CACHE: Dict[str, Dict[str, dict]] = {}


def load_cmu_index(cmu_dir) -> Dict[str, dict]:
    """``index.csv`` of the CMU folder as ``{file: {subject, trial, class, description, frames}}``
    ({} if there is no index)."""
    cmu_dir = Path(cmu_dir)
    key = str(cmu_dir.resolve())
    if key in _INDEX_CACHE:
        return _INDEX_CACHE[key]
    out: Dict[str, dict] = {}
    p = cmu_dir / 'index.csv'
    if p.is_file():
        with open(p, newline='', encoding='utf-8') as f:
            for row in csv.DictReader(f):
                try:
                    out[row['file']] = {
                        'file': row['file'], 'subject': int(row['cmu_subject']),
                        'trial': int(row['cmu_trial']), 'class': row['class'].strip(),
                        'description': row.get('description', '').strip(),
                        'frames': int(row['frames_30fps'])}
                except (KeyError, ValueError):
                    log.warning('%s: skipping malformed index row %r', p, row)
    _INDEX_CACHE[key] = out
    return out


def load_cmu_clip(path, motion_class: Optional[str] = None, drop_first: bool = True) -> MotionClip:
    """Load one cgspeed CMU BVH file as a :class:`MotionClip` (see module docstring).

    ``motion_class`` defaults to the class in the folder's ``index.csv`` (or ``'other'``).
    Raises :class:`BvhError` (malformed file) or :class:`MocapError` (wrong skeleton, too short).
    """
    path = Path(path)
    bvh = load_bvh(path)
    needed = {s.split('/')[0] for v in CMU_TO_KINECT.values() for s, _ in v}
    needed |= set(CMU_ORIENTATION_SOURCE.values())
    missing = sorted(needed - set(bvh.names))
    if missing:
        raise MocapError(f'{path}: not a CMU cgspeed skeleton '
                         f'(missing joints {", ".join(missing)})')
    motion = bvh.motion[1:] if drop_first else bvh.motion
    if motion.shape[0] < 2:
        raise MocapError(f'{path}: fewer than 2 frames of motion')
    motion = motion.copy()
    for nm in CMU_IGNORED_JOINTS:
        if nm in bvh.names:
            j = bvh.index(nm)
            s = bvh.channel_start[j]
            for k, c in enumerate(bvh.channels[j]):
                if c.endswith('rotation'):
                    motion[:, s + k] = 0.0

    c = BVH_TO_REP103
    pos, rot, ends = bvh.forward_kinematics(motion, scale=CMU_UNIT)
    kin = _kinect_points(bvh, pos, ends) @ c.T
    # rest (all-zero rotations) pose of this subject, for the orientation corrections
    zero = np.zeros((1, bvh.motion.shape[1]))
    pos0, _, ends0 = bvh.forward_kinematics(zero, scale=CMU_UNIT)
    kin0 = (_kinect_points(bvh, pos0, ends0) @ c.T)[0]
    a_std = rest_directions()
    src = [bvh.index(CMU_ORIENTATION_SOURCE[n]) for n in JOINT_NAMES]
    r_rep = np.einsum('ij,fkjl,ml->fkim', c, rot[:, src], c)
    q = Rotation.from_matrix(r_rep.reshape(-1, 3, 3)).as_quat().reshape(-1, NUM_JOINTS, 4)
    corr = np.zeros((NUM_JOINTS, 4))
    corr[:, 3] = 1.0
    for j in range(1, NUM_JOINTS):
        d = kin0[j] - kin0[PARENTS[j]]
        corr[j] = _min_rotation(a_std[j], d / np.linalg.norm(d))
    q = quat_multiply(q, corr)
    # Segments spanning several mocap bones (trunk, neck) are not rigid with their source bone:
    # swing the orientation by the small residual so it points exactly along the segment (the
    # twist still comes from the source bone).
    seg = kin[:, 1:] - kin[:, SEGMENT_PARENT_INDEX]
    seg /= np.maximum(np.linalg.norm(seg, axis=-1, keepdims=True), 1e-12)
    pred = quat_rotate(q[:, 1:], np.broadcast_to(a_std[1:], seg.shape))
    q[:, 1:] = quat_multiply(_min_rotation_batch(pred, seg), q[:, 1:])
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q *= np.where(q[..., 3:4] < 0, -1.0, 1.0)
    if not (np.all(np.isfinite(kin)) and np.all(np.isfinite(q))):
        raise MocapError(f'{path}: non-finite values after forward kinematics')

    if motion_class is None:
        info = load_cmu_index(path.parent).get(path.name)
        motion_class = info['class'] if info else 'other'
        desc = info['description'] if info else ''
    else:
        info = load_cmu_index(path.parent).get(path.name)
        desc = info['description'] if info else ''
    return MotionClip(name=path.stem, motion_class=motion_class, fps=bvh.fps, positions=kin,
                      orientations=q, source=f'cmu:{path.name}', description=desc)


def _list_cmu(cmu_dir, classes: Optional[Sequence[str]]) -> List[Tuple[Path, str]]:
    cmu_dir = Path(cmu_dir)
    if not cmu_dir.is_dir():
        raise FileNotFoundError(f'CMU mocap folder {cmu_dir} does not exist')
    index = load_cmu_index(cmu_dir)
    files = sorted(cmu_dir.glob('*.bvh'))
    out = []
    for f in files:
        cls = index.get(f.name, {}).get('class', 'other')
        if classes is None or cls in classes:
            out.append((f, cls))
    return out


def load_cmu_clips(cmu_dir, classes: Optional[Sequence[str]] = FIVE_CLASSES,
                   skipped: Optional[list] = None, progress=None) -> List[MotionClip]:
    """Load every ``*.bvh`` of ``cmu_dir`` whose index class is in ``classes`` (None: all),
    sorted by file name. Bad files are skipped: ``(file name, reason)`` is appended to ``skipped``
    and logged as a warning. ``progress`` is an optional callable(frames_loaded) per file."""
    clips = []
    for f, cls in _list_cmu(cmu_dir, classes):
        try:
            clips.append(load_cmu_clip(f, cls))
        except (BvhError, MocapError, OSError) as e:
            reason = str(e)
            log.warning('skipping %s: %s', f.name, reason)
            if skipped is not None:
                skipped.append((f.name, reason))
        if progress is not None:
            progress(f.name)
    return clips


def split_clips(clips: Sequence[MotionClip], dev_fraction: float = 0.3
                ) -> Tuple[List[MotionClip], List[MotionClip]]:
    """Deterministic database/dev split (input order matters; pass clips sorted by name).

    Per class: with n >= 2 clips, ``k = max(1, round(dev_fraction * n))`` whole clips evenly spread
    over the list (positions ``floor((i + 0.5) n / k)``) go to dev; with a single clip, its last
    ``dev_fraction`` of frames goes to dev (clip name suffixed ``:dev``) and the rest to the
    database (suffix ``:db``).
    """
    db, dev = [], []
    classes = []
    for c in clips:
        if c.motion_class not in classes:
            classes.append(c.motion_class)
    for cls in classes:
        members = [c for c in clips if c.motion_class == cls]
        n = len(members)
        if n == 1:
            c = members[0]
            cut = int(round(len(c) * (1.0 - dev_fraction)))
            cut = min(max(cut, 1), len(c) - 1)
            db.append(c.slice(0, cut, ':db'))
            dev.append(c.slice(cut, None, ':dev'))
            continue
        k = max(1, int(round(dev_fraction * n)))
        held = {int((i + 0.5) * n / k) for i in range(k)}
        for i, c in enumerate(members):
            (dev if i in held else db).append(c)
    return db, dev


def cmu_split(cmu_dir, classes: Sequence[str] = FIVE_CLASSES, dev_fraction: float = 0.3,
              skipped: Optional[list] = None, progress=None
              ) -> Tuple[List[MotionClip], List[MotionClip]]:
    """(database_clips, dev_clips) of the five-class CMU clips; see :func:`split_clips`.

    With the shared set (31 locomotion, 3 sword, 2 object-handling, 1 boxing, 1 upper-body clips)
    this holds out 9 locomotion clips, 1 sword clip (02_08), 1 object-handling clip (14_04) and the
    last 30 % of 02_05 (boxing) and 02_10 (upper body).
    """
    clips = load_cmu_clips(cmu_dir, classes, skipped=skipped, progress=progress)
    return split_clips(clips, dev_fraction)


def mirror_clip(clip: MotionClip, suffix: str = ':mirror') -> MotionClip:
    """Left-right mirror image (y -> -y, left and right joints swapped) for data augmentation."""
    mirror = list(MIRROR)
    p = clip.positions[:, mirror].copy()
    p[..., 1] *= -1.0
    q = clip.orientations[:, mirror].copy()
    # M R M with M = diag(1, -1, 1): axis (x, y, z) -> (-x, y, -z), same angle
    q[..., 0] *= -1.0
    q[..., 2] *= -1.0
    return replace(clip, name=clip.name + suffix, positions=p, orientations=q,
                   source=clip.source + suffix)
