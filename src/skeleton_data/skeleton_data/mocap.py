"""Motion clips on the Kinect skeleton, and the CMU (cgspeed BVH) importer.

A :class:`MotionClip` holds world-space joint positions and segment orientations of the 20 Kinect
joints (``model.JOINT_NAMES``) in REP-103 metres: x forward, y left, z up, floor at z = 0.

Orientation convention (shared with :mod:`skeleton_data.motions` and the database)
---------------------------------------------------------------------------------
``orientations[t, j]`` (xyzw) is the global orientation of the segment that *ends* at joint j
(joint 0: the pelvis). Identity means "as in the standard body's T-pose facing +x", i.e.
``quat_rotate(orientations[t, j], unit(standard_body().rest_offsets[j]))`` is the direction of the
segment from ``PARENTS[j]`` to j (exactly, for built-in motions and mocap alike).

CMU -> Kinect mapping (the one table: ``config/joint_maps/cmu_bvh.yaml``)
-----------------------------------------------------------------------
The map is read through :mod:`skeleton_data.joint_map` (:data:`CMU_TO_KINECT` and
:data:`CMU_ORIENTATION_SOURCE` are views of it); other conventions (a generic BVH, Plug-in-Gait
markers) come in through their own maps with :func:`load_mapped_clip`.
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

from skeleton_core.model import MIRROR, NUM_JOINTS

from .bvh import BvhError, load_bvh
from .joint_map import (JointMap, JointMapError, builtin_map, bvh_frames, marker_joint_centres,
                        orientations_from_positions, read_markers, rest_directions)
from fnmatch import fnmatch

__all__ = [
    'MotionClip', 'MocapError', 'CMU_TO_KINECT', 'CMU_ORIENTATION_SOURCE', 'CMU_UNIT',
    'BVH_TO_REP103', 'FIVE_CLASSES', 'MOTION_CLASSES', 'load_cmu_clip', 'load_cmu_index',
    'load_cmu_clips', 'cmu_split', 'split_clips', 'mirror_clip', 'rest_directions', 'CMU_MAP',
    'load_mapped_clip', 'load_mapped_clips', 'mapped_files', 'JointMapError',
]

log = logging.getLogger(__name__)

# Shum et al. 2013, Table I
FIVE_CLASSES: Tuple[str, ...] = ('locomotion', 'object_handling', 'upper_body', 'boxing',
                                 'sword_fighting')
MOTION_CLASSES: Tuple[str, ...] = FIVE_CLASSES + ('other',)

# THE CMU mapping is config/joint_maps/cmu_bvh.yaml (skeleton_data.joint_map); these names are views
# of it for the code that reads them.
CMU_MAP: JointMap = builtin_map('cmu_bvh')
CMU_UNIT = CMU_MAP.scale  # metres per CMU ASF length unit (1/0.45 inch)
# rep = BVH_TO_REP103 @ bvh: x_rep = Z_bvh (forward), y_rep = X_bvh (left), z_rep = Y_bvh (up)
BVH_TO_REP103 = CMU_MAP.rotation
# Kinect joint -> weighted mocap points ('Joint' or 'Joint/End' for that joint's End Site)
CMU_TO_KINECT: Dict[str, Tuple[Tuple[str, float], ...]] = {
    name: alts[0] for name, alts in CMU_MAP.joints.items()}
# Kinect joint -> mocap bone whose global rotation orients the segment ending at that joint
CMU_ORIENTATION_SOURCE: Dict[str, str] = dict(CMU_MAP.orientation)
# Channels CMU says were not captured (set to zero)
CMU_IGNORED_JOINTS = CMU_MAP.zero_rotations


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
    jm = CMU_MAP if drop_first else replace(CMU_MAP, drop_first_frame=False)
    if bvh.num_frames - int(jm.drop_first_frame) < 2:
        raise MocapError(f'{path}: fewer than 2 frames of motion')
    kin, q = bvh_frames(bvh, jm)
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


# ------------------------------------------------------------------------------------------
# Clips in other conventions through a joint map
# ------------------------------------------------------------------------------------------
def load_mapped_clip(path, jmap: JointMap, motion_class: Optional[str] = None,
                     name: Optional[str] = None) -> MotionClip:
    """One BVH or marker file as a :class:`MotionClip` through ``jmap``
    (:mod:`skeleton_data.joint_map`). Marker frames where a joint centre is undefined (a marker
    gap) are dropped. Raises :class:`MocapError` (file unusable: names it and why) or
    :class:`JointMapError` (the map does not fit the file)."""
    path = Path(path)
    stem = name or path.name.split('.')[0]
    if jmap.format == 'bvh':
        try:
            bvh = load_bvh(path)
        except BvhError as e:
            raise MocapError(str(e)) from None
        pos, q = bvh_frames(bvh, jmap)
        fps = bvh.fps
    else:
        try:
            markers = read_markers(path, jmap)
        except ValueError as e:
            raise MocapError(str(e)) from None
        pos = marker_joint_centres(markers, jmap)
        ok = np.all(np.isfinite(pos), axis=(1, 2))
        pos = pos[ok]
        q = orientations_from_positions(pos) if len(pos) else np.zeros((0, NUM_JOINTS, 4))
        fps = jmap.frame_rate
    if len(pos) < 2:
        raise MocapError(f'{path}: fewer than 2 usable frames')
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(q))):
        raise MocapError(f'{path}: non-finite values after the joint map')
    return MotionClip(name=stem, motion_class=motion_class or jmap.motion_class, fps=fps,
                      positions=pos, orientations=q, source=f'{jmap.name}:{path.name}')


def mapped_files(folder, jmap: JointMap, include: Sequence[str] = (),
                 exclude: Sequence[str] = ()) -> List[Path]:
    """The files of ``folder`` a map reads (``*.bvh`` for BVH maps; ``*.txt``, ``*.txt.gz``,
    ``*.csv``, ``*.csv.gz`` for marker maps), sorted, filtered by shell patterns on the file name:
    kept when it matches one of ``include`` (if any) and none of ``exclude``."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f'mocap folder {folder} does not exist')
    pats = ('*.bvh',) if jmap.format == 'bvh' else ('*.txt', '*.txt.gz', '*.csv', '*.csv.gz')
    files = sorted({f for p in pats for f in folder.glob(p)})
    return [f for f in files
            if (not include or any(fnmatch(f.name, p) for p in include))
            and not any(fnmatch(f.name, p) for p in exclude)]


def load_mapped_clips(folder, jmap: JointMap, include: Sequence[str] = (),
                      exclude: Sequence[str] = (), skipped: Optional[list] = None,
                      progress=None) -> List[MotionClip]:
    """Every file of :func:`mapped_files` as a clip; unusable files are skipped (``(name,
    reason)`` appended to ``skipped`` and logged). A map that does not fit a file
    (:class:`JointMapError`) is raised: it would not fit the others either."""
    clips = []
    for f in mapped_files(folder, jmap, include, exclude):
        try:
            clips.append(load_mapped_clip(f, jmap))
        except (MocapError, OSError) as e:
            log.warning('skipping %s: %s', f.name, e)
            if skipped is not None:
                skipped.append((f.name, str(e)))
        if progress is not None:
            progress(f.name)
    return clips
