"""Paired real data: UI-PRMD Kinect clips with their Vicon marker reference registered into the sensor frame.

:func:`load_dataset` reads the Kinect clips (:mod:`skeleton_data.uiprmd`), the marker-derived joint
centres (:mod:`skeleton_data.vicon`), and fits one rigid registration and lag per session
(:mod:`skeleton_eval.registration`) so that every clip has a reference resampled to its frames.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np

from skeleton_data import vicon
from skeleton_data.uiprmd import (ClipId, KinectClip, UIPRMDFormatError, find_clips,
                                  load_kinect_clip, parse_name)

from . import registration as reg

@dataclass
class RealClip:
    """A Kinect clip with its marker reference resampled to the Kinect frames (sensor frame)."""

    kinect: KinectClip
    reference: Optional[np.ndarray] = None  # (N, 20, 3) m, NaN where the reference has no data
    lag: Optional[float] = None             # s, reference time = Kinect time + lag
    setup: Optional[str] = None             # the registration (session or 'sNN/k' setup) used

    @property
    def clip(self) -> ClipId:
        return self.kinect.clip


def _select(paths, subjects, movements, repetitions):
    out = []
    for p in paths:
        try:
            c = parse_name(p)
        except UIPRMDFormatError:
            out.append(p)  # reported by the loader
            continue
        if subjects and c.subject not in subjects:
            continue
        if movements and c.movement not in movements:
            continue
        if repetitions and c.repetition not in repetitions:
            continue
        out.append(p)
    return out


def load_dataset(src, subjects=None, movements=None, repetitions=None, with_reference=True,
                 progress=None, sensor_height: float = 0.0):
    """Load Kinect clips (and, where Vicon files exist, the registered marker reference).

    Returns ``(clips, skipped, registrations)``: ``clips`` a list of :class:`RealClip`,
    ``skipped`` a list of ``(path, reason)`` for files that could not be used (the rest continue),
    ``registrations`` ``{setup: registration.SessionRegistration}``: one rigid transform per
    subject session, or per setup where a session's movements were not one rigid setup
    (:func:`registration.split_setups`; the extra setups are named ``sNN/2``, ...). ``progress`` wraps an
    iterable (e.g. ``tqdm``). ``sensor_height`` (m) moves the origin up from the floor to a
    nominal sensor height (z of the floor = -sensor_height); 0 keeps the floor at z = 0.
    """
    src = Path(src)
    if not (src / 'Kinect' / 'Positions').is_dir() and not src.is_dir():
        raise FileNotFoundError(f'{src}: no UI-PRMD folder (expected Kinect/Positions inside)')
    paths = _select(find_clips(src), subjects, movements, repetitions)
    it = progress(paths) if progress else paths
    skipped = []
    clips: List[RealClip] = []
    refs: Dict[str, List[Tuple[RealClip, np.ndarray]]] = {}
    shift = np.array([0.0, 0.0, -float(sensor_height)])
    for p in it:
        try:
            kc = load_kinect_clip(p)
        except UIPRMDFormatError as e:
            skipped.append((str(e.path), e.reason))
            continue
        if sensor_height:
            kc.positions = kc.positions + shift
            kc.positions22 = kc.positions22 + shift
        rc = RealClip(kinect=kc)
        clips.append(rc)
        if not with_reference:
            continue
        vp = vicon.vicon_path_for(src, kc.clip.name)
        if not vp.exists():
            continue  # no reference recorded for this subject: not an error
        try:
            refs.setdefault(kc.clip.session, []).append((rc, vicon.load_reference(vp)))
        except UIPRMDFormatError as e:
            skipped.append((str(e.path), e.reason + ' (reference only; Kinect clip kept)'))
    registrations = {}
    for session, items in sorted(refs.items()):
        # the tracking-failure clips take no part in any fit; they join the largest setup
        fit = [(rc, r) for rc, r in items if not rc.clip.is_tracking_failure] or items
        by_movement: Dict[int, List[int]] = {}
        for i, (rc, _) in enumerate(fit):
            by_movement.setdefault(rc.clip.movement, []).append(i)
        setups = (reg.split_setups(list(by_movement.values()),
                                   [rc.kinect.positions for rc, _ in fit], [r for _, r in fit])
                  if len(by_movement) > 1 else [list(range(len(fit)))])
        rest = [(rc, r) for rc, r in items if not any(rc is f for f, _ in fit)]
        for n, idx in enumerate(setups):
            members = [fit[i] for i in idx]
            name = session if n == 0 else f'{session}/{n + 1}'
            try:
                sr = reg.register_session([rc.kinect.positions for rc, _ in members],
                                          [r for _, r in members])
            except (ValueError, np.linalg.LinAlgError) as e:
                for rc, _ in members + (rest if n == 0 else []):
                    skipped.append((rc.clip.name,
                                    f'reference not registered ({e}); Kinect clip kept'))
                continue
            for (rc, r), lag in zip(members, sr.lags):
                rc.lag = lag
                rc.reference = sr.to_kinect(reg.paired_reference(r, len(rc.kinect.positions),
                                                                 lag))
                rc.setup = name
            if n == 0:
                for rc, r in rest:
                    k = rc.kinect.positions
                    rc.lag = reg.estimate_lag(k, reg.apply_transform(sr.rotation, sr.translation,
                                                                     r))
                    rc.reference = sr.to_kinect(reg.paired_reference(r, len(k), rc.lag))
                    rc.setup = name
            registrations[name] = sr
    return clips, skipped, registrations


__all__ = ['RealClip', 'load_dataset']
