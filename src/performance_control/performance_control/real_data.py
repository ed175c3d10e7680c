"""Real recordings for the recognition benchmark (``bench_control --real``): what people do in front
of a sensor without imitating anything, and real hanging from bars. Needs ``../shared`` (nothing
here is shipped or cached in the repository).

* :func:`uiprmd_streams` -- the UI-PRMD Kinect v2 clips (real sensor, subjects s01-s05, ten
  rehabilitation exercises, ten repetitions each) with their tracking states (the hands are
  extrapolated from the forearm and reported NOT_TRACKED, as the importer does).
* :func:`cmu_streams` -- CMU clips of every class through the Kinect sensor model (the performance
  placement of :mod:`.performances`), split into tuning and held-out clips per class with
  :func:`skeleton_data.mocap.split_clips` (the held-out ones are the project's "dev" clips, never in
  the motion database). Subject 01 (the playground: climbing, hanging) is left out: it is the
  true-positive set.
* :func:`hanging_segments` -- CMU subject 01's playground clips (01_10, 01_11, 01_12 by default)
  with the frames where the subject hangs, labelled automatically: both hands above the head and
  both feet at least ``min_foot`` m above the floor (the clip's lowest foot).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, List, Optional, Sequence, Tuple

import numpy as np
from skeleton_core.model import JOINT_INDEX
from skeleton_data.mocap import load_cmu_clip, load_cmu_clips, split_clips
from skeleton_data.uiprmd import find_clips, load_kinect_clip

from .performances import to_sensor

HANG_CLIPS = ('01_10', '01_11', '01_12')
UIPRMD_SUBJECTS = ('s01', 's02', 's03', 's04', 's05')


def shared_dir() -> Path:
    """``../shared`` of the source tree (KINECT_POSTURE_ROOT/../shared, else next to this file)."""
    root = os.environ.get('KINECT_POSTURE_ROOT')
    cands = [Path(root).parent / 'shared'] if root else []
    here = Path(__file__).resolve()
    cands += [p / 'shared' for p in here.parents]
    cands += [p.parent / 'shared' for p in here.parents]
    for c in cands:
        if (c / 'mocap').is_dir() or (c / 'kinect').is_dir():
            return c
    return Path('../shared')


@dataclass
class Stream:
    name: str             # e.g. m01_s02_e03 or 08_01
    group: str            # the exercise (m01..m10) or the CMU class
    subject: str          # s01..s05, or the CMU subject
    split: str            # uiprmd: the subject; cmu: 'tune' | 'held-out'
    positions: np.ndarray     # (T, 20, 3) z up (any origin: the recognizer is relative)
    states: np.ndarray        # (T, 20) uint8
    label: Optional[np.ndarray] = None   # (T,) bool: true-positive frames (hanging)


def uiprmd_streams(src: Optional[Path] = None, subjects: Sequence[str] = UIPRMD_SUBJECTS
                   ) -> Iterator[Stream]:
    src = Path(src) if src else shared_dir() / 'kinect' / 'ui-prmd'
    for f in find_clips(src):
        k = load_kinect_clip(f)
        c = k.clip
        subj = f's{int(c.subject):02d}'
        if subj not in subjects:
            continue
        st = np.repeat(np.asarray(k.tracking_state, np.uint8)[None], k.num_frames, 0)
        yield Stream(c.name, f'm{int(c.movement):02d}', subj, subj, k.positions, st)


def cmu_streams(cmu_dir: Optional[Path] = None, seed: int = 0, noise: bool = True
                ) -> Iterator[Stream]:
    cmu_dir = Path(cmu_dir) if cmu_dir else shared_dir() / 'mocap' / 'cmu'
    clips = [c for c in load_cmu_clips(cmu_dir, classes=None) if not c.name.startswith('01_')]
    tune, held = split_clips(clips, 0.3)
    for split, group in (('tune', tune), ('held-out', held)):
        for i, c in enumerate(group):
            pos, st = to_sensor(np.asarray(c.positions, float), c.name, seed + i, noise,
                                states=True)
            yield Stream(c.name, c.motion_class, c.name.split('_')[0], split, pos, st)


def hang_label(p: np.ndarray, min_foot: float = 0.3) -> np.ndarray:
    """(T,) bool: both hands above the head and both feet >= ``min_foot`` above the floor (the
    clip's lowest foot, 1st percentile) -- a clip in world coordinates, z up."""
    p = np.asarray(p, float)
    feet = p[:, [JOINT_INDEX['FootLeft'], JOINT_INDEX['FootRight']], 2]
    floor = float(np.percentile(feet.min(axis=1), 1))
    head = p[:, JOINT_INDEX['Head'], 2]
    hands = p[:, [JOINT_INDEX['HandLeft'], JOINT_INDEX['HandRight']], 2]
    return (hands.min(axis=1) > head) & (feet.min(axis=1) - floor >= min_foot)


def segments(label: np.ndarray, min_len: int = 1) -> List[Tuple[int, int]]:
    """[(start, stop)] of the runs of true frames (stop exclusive) at least ``min_len`` long."""
    lab = np.concatenate([[False], np.asarray(label, bool), [False]])
    d = np.diff(lab.astype(int))
    return [(a, b) for a, b in zip(np.nonzero(d == 1)[0], np.nonzero(d == -1)[0])
            if b - a >= min_len]


def hanging_segments(cmu_dir: Optional[Path] = None, clips: Sequence[str] = HANG_CLIPS,
                     seed: int = 0, noise: bool = True, min_foot: float = 0.3
                     ) -> Iterator[Stream]:
    """Subject 01's playground clips through the sensor model, labelled (the label from the clean
    mocap)."""
    cmu_dir = Path(cmu_dir) if cmu_dir else shared_dir() / 'mocap' / 'cmu'
    for i, name in enumerate(clips):
        f = cmu_dir / f'{name}.bvh'
        if not f.is_file():
            continue
        c = load_cmu_clip(f)
        p = np.asarray(c.positions, float)
        pos, st = to_sensor(p, c.name, seed + i, noise, states=True)
        yield Stream(c.name, 'hanging', '01', 'tp', pos, st, hang_label(p, min_foot))


__all__ = ['Stream', 'uiprmd_streams', 'cmu_streams', 'hanging_segments', 'hang_label',
           'segments', 'shared_dir', 'HANG_CLIPS', 'UIPRMD_SUBJECTS']
