"""A small BVH (Biovision Hierarchy) reader with vectorised forward kinematics.

Why our own: the PyPI BVH readers (``bvh`` 0.3, 2017, pure-Python per-frame access; ``bvhio`` /
``bvhsdk``, per-joint object graphs) either lack forward kinematics, are slow on 25k frames, or do
not report *where* a file is broken. This one parses a whole file into numpy arrays and names the
file and line of every error.

Format handled
--------------
``HIERARCHY`` with one ``ROOT``, nested ``JOINT`` and ``End Site`` blocks (``OFFSET x y z``,
``CHANNELS n <name>...``), then ``MOTION``, ``Frames: N``, ``Frame Time: dt`` and N lines of
numbers. Channel names: ``X/Y/Z position`` and ``X/Y/Z rotation`` (degrees) in any order.

Conventions (the usual BVH ones)
--------------------------------
* Rotation channels are intrinsic rotations in the listed order: ``Zrotation Yrotation Xrotation``
  gives ``R = Rz @ Ry @ Rx`` (column vectors, child-to-parent).
* A joint's position is ``p_parent + R_parent_global @ (offset + translation_channels)``; its
  global rotation is ``R_parent_global @ R_local``.
* Positions are in file units; scale them yourself (see :mod:`skeleton_data.mocap`).

Errors raise :class:`BvhError`; its message starts with ``<file>:<line>:``.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

__all__ = ['BvhError', 'Bvh', 'parse_bvh', 'load_bvh', 'CHANNEL_NAMES']

CHANNEL_NAMES = ('Xposition', 'Yposition', 'Zposition', 'Xrotation', 'Yrotation', 'Zrotation')


class BvhError(ValueError):
    """A malformed BVH file. ``path`` and ``line`` (1-based, or None) name where."""

    def __init__(self, path: str, line: Optional[int], message: str):
        self.path = path
        self.line = line
        self.reason = message
        where = f'{path}:{line}' if line is not None else f'{path}'
        super().__init__(f'{where}: {message}')


@dataclass
class Bvh:
    """A parsed BVH file.

    ``names``/``parents``/``offsets`` describe the joints in file order (parents before children);
    ``end_sites`` are ``(parent_joint_index, offset)``. ``motion`` is (frames, total_channels) as
    in the file; ``channels[j]`` lists joint j's channel names and ``channel_start[j]`` its first
    column in ``motion``.
    """

    path: str
    names: List[str]
    parents: List[int]
    offsets: np.ndarray                  # (J, 3)
    channels: List[Tuple[str, ...]]
    channel_start: List[int]
    end_sites: List[Tuple[int, np.ndarray]]
    frame_time: float
    motion: np.ndarray = field(repr=False)  # (F, C)

    @property
    def num_frames(self) -> int:
        return int(self.motion.shape[0])

    @property
    def num_joints(self) -> int:
        return len(self.names)

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f'{self.path}: no joint named {name!r}') from None

    def end_site_of(self, joint: str) -> int:
        """Index into ``end_sites`` of the End Site below ``joint``."""
        j = self.index(joint)
        for k, (p, _) in enumerate(self.end_sites):
            if p == j:
                return k
        raise KeyError(f'{self.path}: joint {joint!r} has no End Site')

    def local_transforms(self, motion: Optional[np.ndarray] = None):
        """Local rotations (F, J, 3, 3) and translations (F, J, 3) (offset + position channels)."""
        m = self.motion if motion is None else np.asarray(motion, float)
        f, nj = m.shape[0], self.num_joints
        rot = np.broadcast_to(np.eye(3), (f, nj, 3, 3)).copy()
        trans = np.broadcast_to(self.offsets, (f, nj, 3)).copy()
        for j, chans in enumerate(self.channels):
            start = self.channel_start[j]
            rot_axes, rot_cols = [], []
            for k, c in enumerate(chans):
                if c.endswith('position'):
                    trans[:, j, 'XYZ'.index(c[0])] += m[:, start + k]
                else:
                    rot_axes.append(c[0])
                    rot_cols.append(start + k)
            if rot_axes:
                from scipy.spatial.transform import Rotation   # (scipy.spatial: 0.3 s to import)
                angles = m[:, rot_cols]
                if np.any(angles != 0.0):
                    rot[:, j] = Rotation.from_euler(''.join(rot_axes), angles,
                                                    degrees=True).as_matrix()
        return rot, trans

    def forward_kinematics(self, motion: Optional[np.ndarray] = None, scale: float = 1.0):
        """Global joint positions (F, J, 3) (times ``scale``), global rotations (F, J, 3, 3) and
        End Site positions (F, E, 3)."""
        rot, trans = self.local_transforms(motion)
        f, nj = rot.shape[:2]
        g_rot = np.empty_like(rot)
        g_pos = np.empty((f, nj, 3))
        for j in range(nj):
            p = self.parents[j]
            if p < 0:
                g_rot[:, j] = rot[:, j]
                g_pos[:, j] = trans[:, j]
            else:
                g_rot[:, j] = g_rot[:, p] @ rot[:, j]
                g_pos[:, j] = g_pos[:, p] + np.einsum('fij,fj->fi', g_rot[:, p], trans[:, j])
        ends = np.empty((f, len(self.end_sites), 3))
        for k, (p, off) in enumerate(self.end_sites):
            ends[:, k] = g_pos[:, p] + g_rot[:, p] @ off
        return g_pos * scale, g_rot, ends * scale


def _floats(tokens: Sequence[str], path: str, line: int, what: str) -> np.ndarray:
    try:
        vals = np.array([float(t) for t in tokens])
    except ValueError:
        raise BvhError(path, line, f'bad number in {what}: {" ".join(tokens)!r}') from None
    if not np.all(np.isfinite(vals)):
        raise BvhError(path, line, f'non-finite number in {what}')
    return vals


def parse_bvh(text: str, path: str = '<string>') -> Bvh:
    """Parse BVH text. ``path`` is only used in error messages."""
    lines = text.splitlines()
    n = len(lines)
    i = 0

    def next_content(i):
        while i < n and not lines[i].strip():
            i += 1
        return i

    i = next_content(i)
    if i >= n or lines[i].split()[0] != 'HIERARCHY':
        raise BvhError(path, i + 1 if i < n else None, 'expected HIERARCHY at the start')
    i += 1

    names: List[str] = []
    parents: List[int] = []
    offsets: List[np.ndarray] = []
    channels: List[Tuple[str, ...]] = []
    end_sites: List[Tuple[int, np.ndarray]] = []
    # stack of open blocks: (kind 'joint'|'end', joint index or parent index, line of '{')
    stack: List[Tuple[str, int, int]] = []
    pending: Optional[Tuple[str, int, int]] = None  # block header waiting for its '{'
    seen_root = False
    motion_line = None
    while i < n:
        raw = lines[i]
        toks = raw.split()
        ln = i + 1
        i += 1
        if not toks:
            continue
        key = toks[0]
        if key == 'MOTION':
            motion_line = ln
            break
        if pending is not None and key != '{':
            raise BvhError(path, ln, f"expected '{{' after {pending[0]} declared on line "
                                     f"{pending[2]}")
        if key in ('ROOT', 'JOINT'):
            if key == 'ROOT':
                if seen_root:
                    raise BvhError(path, ln, 'more than one ROOT')
                if stack:
                    raise BvhError(path, ln, 'ROOT inside another block')
                seen_root = True
                parent = -1
            else:
                if not stack or stack[-1][0] != 'joint':
                    raise BvhError(path, ln, 'JOINT outside a joint block')
                parent = stack[-1][1]
            if len(toks) < 2:
                raise BvhError(path, ln, f'{key} without a name')
            name = ' '.join(toks[1:])
            if name in names:
                raise BvhError(path, ln, f'duplicate joint name {name!r}')
            names.append(name)
            parents.append(parent)
            offsets.append(None)
            channels.append(())
            pending = ('joint', len(names) - 1, ln)
        elif key == 'End' and len(toks) >= 2 and toks[1] == 'Site':
            if not stack or stack[-1][0] != 'joint':
                raise BvhError(path, ln, 'End Site outside a joint block')
            end_sites.append((stack[-1][1], None))
            pending = ('end', len(end_sites) - 1, ln)
        elif key == '{':
            if pending is None:
                raise BvhError(path, ln, "unexpected '{'")
            stack.append((pending[0], pending[1], ln))
            pending = None
        elif key == '}':
            if not stack:
                raise BvhError(path, ln, "unbalanced braces: '}' without an open block")
            kind, idx, open_ln = stack.pop()
            if kind == 'joint' and offsets[idx] is None:
                raise BvhError(path, ln, f'joint {names[idx]!r} has no OFFSET')
            if kind == 'end' and end_sites[idx][1] is None:
                raise BvhError(path, ln, 'End Site has no OFFSET')
        elif key == 'OFFSET':
            if not stack:
                raise BvhError(path, ln, 'OFFSET outside a block')
            if len(toks) != 4:
                raise BvhError(path, ln, f'OFFSET needs 3 numbers, got {len(toks) - 1}')
            off = _floats(toks[1:], path, ln, 'OFFSET')
            kind, idx, _ = stack[-1]
            if kind == 'joint':
                offsets[idx] = off
            else:
                end_sites[idx] = (end_sites[idx][0], off)
        elif key == 'CHANNELS':
            if not stack or stack[-1][0] != 'joint':
                raise BvhError(path, ln, 'CHANNELS outside a joint block')
            try:
                count = int(toks[1])
            except (IndexError, ValueError):
                raise BvhError(path, ln, 'CHANNELS needs a count') from None
            chans = tuple(toks[2:])
            if len(chans) != count:
                raise BvhError(path, ln, f'CHANNELS declares {count} channels but lists '
                                         f'{len(chans)}')
            for c in chans:
                if c not in CHANNEL_NAMES:
                    raise BvhError(path, ln, f'unknown channel {c!r} (expected one of '
                                             f'{", ".join(CHANNEL_NAMES)})')
            if len(set(chans)) != len(chans):
                raise BvhError(path, ln, 'repeated channel')
            channels[stack[-1][1]] = chans
        else:
            raise BvhError(path, ln, f'unexpected keyword {key!r} in HIERARCHY')
    if pending is not None:
        raise BvhError(path, pending[2], f"{pending[0]} block never opened with '{{'")
    if stack:
        raise BvhError(path, stack[-1][2], "unbalanced braces: block opened here is never closed")
    if not names:
        raise BvhError(path, None, 'no ROOT joint')
    if motion_line is None:
        raise BvhError(path, n, 'no MOTION section')

    # --- MOTION header
    def header(i, label):
        i = next_content(i)
        if i >= n:
            raise BvhError(path, n, f'truncated MOTION: missing "{label}"')
        s = lines[i].strip()
        if not s.startswith(label):
            raise BvhError(path, i + 1, f'expected "{label}", got {s[:40]!r}')
        return i, s[len(label):].strip()

    i, val = header(i, 'Frames:')
    try:
        num_frames = int(val)
        if num_frames < 0:
            raise ValueError
    except ValueError:
        raise BvhError(path, i + 1, f'bad frame count {val!r}') from None
    i, val = header(i + 1, 'Frame Time:')
    try:
        frame_time = float(val)
        if not (np.isfinite(frame_time) and frame_time > 0):
            raise ValueError
    except ValueError:
        raise BvhError(path, i + 1, f'bad frame time {val!r}') from None
    i += 1

    channel_start, total = [], 0
    for c in channels:
        channel_start.append(total)
        total += len(c)

    # --- MOTION data: fast path over all lines, then locate the first bad line if needed
    data_lines = [(k + 1, lines[k]) for k in range(i, n) if lines[k].strip()]
    if len(data_lines) < num_frames:
        raise BvhError(path, n + 1, f'truncated MOTION: Frames: {num_frames} but only '
                                    f'{len(data_lines)} motion lines')
    if len(data_lines) > num_frames:
        raise BvhError(path, data_lines[num_frames][0],
                       f'{len(data_lines) - num_frames} motion lines more than '
                       f'Frames: {num_frames}')
    motion = None
    if num_frames:
        try:
            flat = np.array(' '.join(l for _, l in data_lines).split(), dtype=float)
        except ValueError:
            flat = None
        if flat is not None and flat.size == num_frames * total and np.all(np.isfinite(flat)):
            motion = flat.reshape(num_frames, total)
        else:
            for ln, l in data_lines:
                toks = l.split()
                if len(toks) != total:
                    raise BvhError(path, ln, f'motion line has {len(toks)} numbers, '
                                             f'expected {total} (one per channel)')
                _floats(toks, path, ln, 'MOTION')
            raise BvhError(path, None, 'malformed MOTION data')  # pragma: no cover
    else:
        motion = np.zeros((0, total))
    return Bvh(path=path, names=names, parents=parents, offsets=np.array(offsets, float),
               channels=channels, channel_start=channel_start,
               end_sites=[(p, np.asarray(o, float)) for p, o in end_sites],
               frame_time=frame_time, motion=motion)


def load_bvh(path) -> Bvh:
    """Read and parse a BVH file (``BvhError`` on I/O or format problems)."""
    path = os.fspath(path)
    try:
        with open(path, 'r', encoding='utf-8', errors='strict') as f:
            text = f.read()
    except UnicodeDecodeError as e:
        raise BvhError(path, None, f'not a text file ({e.reason})') from None
    except OSError as e:
        raise BvhError(path, None, f'cannot read: {e.strerror or e}') from None
    return parse_bvh(text, path)


def joint_table(bvh: Bvh) -> Dict[str, int]:
    return {nm: k for k, nm in enumerate(bvh.names)}
