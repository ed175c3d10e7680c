"""User profiles: what belongs to the person, not to the clip, measured once and kept in a file.

A profile holds the user's 19 segment lengths (m, :data:`skeleton_core.model.SEGMENT_CHILDREN`
order), measured by the sensor (after the sensor correction, when one is used) in a calibration
capture (a T-pose or standing, a few seconds) or accumulated over a session: the median over
frames of each segment's length, left and right limbs sharing the mean of their two medians (the
reconstruction's ``symmetric_lengths``). The reconstruction (``profile`` parameter) then uses
these lengths from the first frame instead of freezing the mean of the first ``length_frames``
observations of every clip.

The reconstruction's own estimate of a user's lengths (the constant lengths every output posture
of methods B and C has, :mod:`.bone_lengths`) is saved the same way (:func:`from_estimate`,
``process_bag --save-profile NAME``), with ``"estimated_by": "reconstruction"`` added.

File: JSON ``{"format": "kinect_posture.user_profile", "version": 1, "name": ..., "tracker": ...,
"segment_lengths_m": [19 numbers], "frames": n, "source": ...}`` (other keys are kept when
written and ignored when read). :func:`load` refuses a malformed
file with one line (:class:`ProfileError`). Profiles are found by name in a directory
(:func:`profile_path`: ``<dir>/<name>.json``, default ``cache/profiles``).
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Iterable, Optional

import numpy as np

from skeleton_core.model import (JOINT_NAMES, MIRROR, NUM_JOINTS, NUM_SEGMENTS, SEGMENT_CHILDREN,
                                 SEGMENT_PARENTS)
from skeleton_core.bagio import read_messages
from skeleton_core.cdr import frames_from_cdr
from skeleton_core.model import TRACKED
import argparse
import sys

FORMAT = 'kinect_posture.user_profile'
FORMAT_VERSION = 1
# plausible adult / child segment lengths: anything outside is a broken measurement
MIN_LENGTH_M, MAX_LENGTH_M = 0.01, 1.0
_NAME_RE = re.compile(r'^[A-Za-z0-9_.-]{1,64}$')
_SC = np.array(SEGMENT_CHILDREN)
_SP = np.array(SEGMENT_PARENTS)
_MIRROR_SEG = np.array([SEGMENT_CHILDREN.index(MIRROR[c]) for c in SEGMENT_CHILDREN])
SEGMENT_NAMES = [f'{JOINT_NAMES[p]}-{JOINT_NAMES[c]}' for p, c in zip(SEGMENT_PARENTS,
                                                                       SEGMENT_CHILDREN)]


class ProfileError(ValueError):
    """A profile file or name that cannot be used (one line)."""


@dataclass
class UserProfile:
    name: str
    segment_lengths: np.ndarray          # (19,) m
    tracker: str = ''
    frames: int = 0
    source: str = ''
    extra: Dict = field(default_factory=dict)

    def __post_init__(self):
        if not isinstance(self.name, str) or not _NAME_RE.match(self.name):
            raise ValueError(f'profile name {self.name!r} must be 1-64 letters, digits, _ . -')
        L = np.asarray(self.segment_lengths, float)
        if L.shape != (NUM_SEGMENTS,):
            raise ValueError(f'segment_lengths_m must hold {NUM_SEGMENTS} numbers, got '
                             f'{L.size}')
        bad = ~np.isfinite(L) | (L < MIN_LENGTH_M) | (L > MAX_LENGTH_M)
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f'segment {SEGMENT_NAMES[i]} length {L[i]!r} m is outside '
                             f'[{MIN_LENGTH_M}, {MAX_LENGTH_M}]')
        self.segment_lengths = L

    def to_dict(self) -> Dict:
        return {'format': FORMAT, 'version': FORMAT_VERSION, 'name': self.name,
                'tracker': self.tracker, 'segment_lengths_m': [round(float(v), 5)
                                                               for v in self.segment_lengths],
                'segments': SEGMENT_NAMES, 'frames': int(self.frames), 'source': self.source,
                **self.extra}

    def save(self, path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + '.tmp')
        tmp.write_text(json.dumps(self.to_dict(), indent=1) + '\n')
        tmp.replace(path)
        return path


def measure(sequences: Iterable[np.ndarray], name: str, tracker: str = '',
            symmetric: bool = True, source: str = '', correction=None) -> UserProfile:
    """A profile from skeleton sequences (each (T, 20, 3), every joint tracked): the median
    length of each segment over all frames; ``symmetric``: left/right share their mean.
    ``correction`` (:class:`~.correction.SensorCorrection`): applied to the frames first, so the
    lengths are those the corrected reconstruction will see."""
    seqs = [np.asarray(s, float) for s in sequences]
    if not seqs or sum(len(s) for s in seqs) == 0:
        raise ValueError('no frames to measure a profile from')
    if correction is not None:
        seqs = [correction.apply(s) for s in seqs]
    P = np.concatenate(seqs)
    if P.ndim != 3 or P.shape[1:] != (NUM_JOINTS, 3):
        raise ValueError(f'expected (T, {NUM_JOINTS}, 3) sequences, got {P.shape}')
    L = np.linalg.norm(P[:, _SC] - P[:, _SP], axis=-1)
    med = np.nanmedian(L, axis=0)
    if symmetric:
        med = 0.5 * (med + med[_MIRROR_SEG])
    return UserProfile(name=name, segment_lengths=med, tracker=tracker, frames=len(P),
                       source=source)


def from_estimate(lengths, name: str, tracker: str = '', frames: int = 0,
                  source: str = '') -> UserProfile:
    """A profile from the reconstruction's estimate of the user's lengths (19,; a
    :class:`~.reconstructor.Reconstructor`'s ``bone_lengths`` once frozen)."""
    if lengths is None:
        raise ValueError('the reconstruction has not estimated the user\'s lengths yet')
    return UserProfile(name=name, segment_lengths=np.asarray(lengths, float), tracker=tracker,
                       frames=frames, source=source, extra={'estimated_by': 'reconstruction'})


def load(path) -> UserProfile:
    """Read and validate a profile file; :class:`ProfileError` with one line if it is unusable."""
    p = Path(path).expanduser()
    if not p.is_file():
        raise ProfileError(f'user profile {str(p)!r} does not exist')
    try:
        d = json.loads(p.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise ProfileError(f'user profile {str(p)!r} is not valid JSON: {e}') from e
    if not isinstance(d, dict):
        raise ProfileError(f'user profile {str(p)!r}: expected a JSON object')
    if d.get('format') != FORMAT or d.get('version') != FORMAT_VERSION:
        raise ProfileError(f'user profile {str(p)!r}: not a version {FORMAT_VERSION} {FORMAT} file')
    L = d.get('segment_lengths_m')
    if not isinstance(L, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                          for v in L):
        raise ProfileError(f'user profile {str(p)!r}: segment_lengths_m must be a list of '
                           f'{NUM_SEGMENTS} numbers')
    try:
        return UserProfile(name=d.get('name'), segment_lengths=np.array(L, float),
                           tracker=str(d.get('tracker', '')), frames=int(d.get('frames', 0)),
                           source=str(d.get('source', '')))
    except (ValueError, TypeError) as e:
        raise ProfileError(f'user profile {str(p)!r}: {e}') from e


def profile_path(name: str, directory=None) -> Path:
    """``<directory>/<name>.json`` (directory default: ``cache/profiles`` of the workspace)."""
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise ProfileError(f'user profile name {name!r} must be 1-64 letters, digits, _ . -')
    if directory is None or directory == '':
        from skeleton_data.database import default_cache_dir
        directory = default_cache_dir() / 'profiles'
    return Path(directory).expanduser() / f'{name}.json'


def load_by_name(name: str, directory=None) -> UserProfile:
    return load(profile_path(name, directory))


def from_optional(profile) -> Optional[np.ndarray]:
    """The (19,) lengths of a profile-like argument (UserProfile, array or None)."""
    if profile is None:
        return None
    L = profile.segment_lengths if isinstance(profile, UserProfile) else profile
    return UserProfile('inline', L).segment_lengths


def frames_from_bag(path, topic: str = '/kinect/skeletons', user_id: Optional[int] = None):
    """(T, 20, 3) positions of the frames of one user in a bag whose joints are all TRACKED."""
    out = []
    for m in read_messages(str(path), topics=[topic], decode=False):
        for f in frames_from_cdr(m.data)[2]:
            if user_id is not None and f.user_id != user_id:
                continue
            if np.all(f.tracking_state == TRACKED) and np.isfinite(f.positions).all():
                out.append(np.asarray(f.positions, float))
    return np.array(out).reshape(-1, NUM_JOINTS, 3)


def main(argv=None) -> int:
    """``build_profile``: measure a user's profile from a calibration capture (a bag) and save it
    by name (``<dir>/<name>.json``), for the reconstruction's ``user_profile`` parameter."""
    ap = argparse.ArgumentParser(prog='build_profile', description=main.__doc__)
    ap.add_argument('--name', required=True, help='profile name (letters, digits, _ . -)')
    ap.add_argument('--bag', action='append', default=[], required=True,
                    help='MCAP bag(s) of the user (a T-pose / standing capture or a session); '
                         'only frames with every joint tracked count')
    ap.add_argument('--topic', default='/kinect/skeletons')
    ap.add_argument('--user-id', type=int, default=None, help='only this user id of the bag')
    ap.add_argument('--dir', default='', help='profile directory (default cache/profiles)')
    ap.add_argument('--correction', default='',
                    help="sensor correction file to apply first ('auto' = the one learned for "
                         "the bag's tracker; the reconstruction must then run with the same "
                         'correction)')
    ap.add_argument('--input-tracker', default='', help="the skeleton tracker of the bag "
                    "(default: the one the bag declares on /kinect/tracker)")
    ap.add_argument('--min-frames', type=int, default=30)
    args = ap.parse_args(argv)
    try:
        path = profile_path(args.name, args.dir or None)
        corr = None
        if not args.input_tracker:   # the tracker the bags declare (skeleton_core.tracker)
            from skeleton_core.tracker import from_bag
            found = sorted({from_bag(b) for b in args.bag} - {''})
            args.input_tracker = found[0] if len(found) == 1 else ''
        if args.correction:
            from . import correction as C

            def refuse(text):   # a correction that cannot be used: one line, exit 1
                raise C.TrackerMismatch(text)
            corr = C.select(args.correction, args.input_tracker, warn=refuse)
        seqs = [frames_from_bag(b, args.topic, args.user_id) for b in args.bag]
        n = sum(len(s) for s in seqs)
        if n < args.min_frames:
            raise ValueError(f'only {n} frames with every joint tracked in {", ".join(args.bag)} '
                             f'(need {args.min_frames})')
        prof = measure(seqs, args.name, args.input_tracker, source=', '.join(args.bag),
                       correction=corr)
        prof.save(path)
    except Exception as e:  # noqa: BLE001 - one clear line, no traceback
        print(f'build_profile: {e}', file=sys.stderr)
        return 1
    print(f'{path}: {prof.frames} frames; segment lengths (m): '
          + ', '.join(f'{n} {v:.3f}' for n, v in zip(SEGMENT_NAMES, prof.segment_lengths)))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
