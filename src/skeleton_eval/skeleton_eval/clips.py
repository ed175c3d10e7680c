"""The motion clips of the evaluation: the CMU database/dev split in ``../shared`` (or the
built-in motions), and a small synthetic clip for tests and smoke runs."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from skeleton_core.model import (ELBOW_LEFT as EL, ELBOW_RIGHT as ER, HAND_LEFT, HAND_RIGHT,
                                 NUM_JOINTS, SHOULDER_LEFT as SL, SHOULDER_RIGHT as SR,
                                 WRIST_LEFT as WL, WRIST_RIGHT as WR, standard_body)
from skeleton_data.mocap import MotionClip, cmu_split
from skeleton_data.motions import builtin_split


def shared_dir() -> Path:
    env = os.environ.get('KP_SHARED')
    if env:
        return Path(env)
    here = Path(__file__).resolve()
    for parent in here.parents:
        if (parent / 'src').is_dir() and (parent.parent / 'shared').is_dir():
            return parent.parent / 'shared'
    return Path('/nonexistent-shared')


def load_clips(source: str = 'auto', seed: int = 0):
    """(database_clips, dev_clips, source_used) from CMU (``../shared/mocap/cmu``) or built-ins."""
    if source not in ('auto', 'cmu', 'builtin'):
        raise ValueError(f"source must be auto, cmu or builtin, got {source!r}")
    cmu = shared_dir() / 'mocap' / 'cmu'
    if source in ('auto', 'cmu') and cmu.is_dir():
        db, dev = cmu_split(cmu)
        return db, dev, f'cmu:{cmu}'
    if source == 'cmu':
        raise FileNotFoundError(f'no CMU mocap at {cmu}')
    db, dev = builtin_split(seed)
    return db, dev, f'builtin:seed={seed}'


def toy_clip(seconds: float = 10.0, fps: float = 30.0, name: str = 'toy_arm_swing'):
    """The standard body standing with both arms swinging up and down (for tests and smoke runs)."""
    body = standard_body()
    rest = body.rest_positions()
    n = int(round(seconds * fps))
    t = np.arange(n) / fps
    pos = np.repeat(rest[None], n, axis=0)
    for sh, chain, sign in ((SL, (EL, WL, HAND_LEFT), 1.0), (SR, (ER, WR, HAND_RIGHT), -1.0)):
        elev = -1.1 + 0.7 * np.sin(2 * np.pi * 0.4 * t + (0.0 if sign > 0 else np.pi))
        fwd = 0.3 * (1 + np.sin(2 * np.pi * 0.25 * t))
        d = np.stack([np.sin(fwd) * np.cos(elev), sign * np.cos(fwd) * np.cos(elev),
                      np.sin(elev)], axis=1)
        for j in chain:
            r = np.linalg.norm(rest[j] - rest[sh])
            pos[:, j] = rest[sh] + r * d
    quats = np.zeros((n, NUM_JOINTS, 4))
    quats[..., 3] = 1.0
    return MotionClip(name=name, motion_class='test', fps=fps, positions=pos, orientations=quats,
                      source='evaluation.toy_clip')
