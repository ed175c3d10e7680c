"""The motion database (Shum et al. 2013 Sec. V-A; Shum & Ho 2012 Sec. 5.1).

Every posture of the input clips is

1. **normalised** (:func:`geometry.normalize`): root moved to the origin, rotation about the
   vertical axis removed so the body faces +x;
2. **retargeted** to the standard body (:func:`geometry.retarget`, Shum & Ho 2012 Eq. 3-4), so
   segment lengths are exactly the standard body's;
3. given its **twists** (:func:`segment_twists`): for each of the 19 segments, the angle of the
   twist component of the segment's orientation (normalised frame) about the segment's rest axis,
   from the swing-twist decomposition ``q = swing * twist(rest_axis)``
   (:func:`geometry.swing_twist`).
   Zero in the T-pose. These are the "rotations along the joint axes" Theta_d of Shum & Ho 2012
   Sec. 6.2 / Shum 2013 Eq. 17, the target the physics character's axial PD torque tracks; apply the
   same function to the simulated body's segment orientations to get the current value;
4. **filtered**: a posture is dropped when the sum over joints of squared position differences
   (m^2) to an already kept posture is below ``threshold`` (greedy, in clip order).

Default threshold: :data:`DEFAULT_THRESHOLD` = 0.02 m^2 (an RMS joint distance of 3.2 cm over the
20 joints). Counts (``build_db``):

* CMU five-class database clips (27 clips after the dev split): 5,150 -> 2,199 postures
  (0.01 m^2: 3,304; 0.05 m^2: 1,192);
* all 73 CMU clips incl. 'other' (``--all-clips``): 26,537 -> 12,438;
  with mirrored copies (``--all-clips --mirror``): 53,074 -> 24,840;
* built-in motions (45 clips): 8,100 -> 783.

Shum 2013 went 21,590 -> 2,574 and found ~2,000 postures enough (Sec. VIII-D, Fig. 8a).

File format (:meth:`MotionDatabase.save`): an uncompressed ``.npz`` of the arrays plus a JSON
``meta`` string (no pickles); :data:`FORMAT_VERSION` is checked on load.
"""
from __future__ import annotations

import hashlib
import json
import logging
import os
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from skeleton_core.geometry import normalize, quat_from_yaw, quat_multiply, retarget, swing_twist
from .mocap import FIVE_CLASSES, MotionClip, rest_directions
from skeleton_core.model import (JOINT_NAMES, NUM_JOINTS, SEGMENT_CHILD_INDEX, SEGMENT_NAMES,
                                 SEGMENT_PARENT_INDEX, Body, estimate_height, standard_body)
from skeleton_core import geometry, model
from .joint_map import maps_dir
from .joint_map import load_joint_map
from .mocap import mapped_files
from .mocap import load_mapped_clips

__all__ = ['MotionDatabase', 'DatabaseError', 'build_database', 'load_or_build_default', 'default_path',
           'build_default',
           'segment_twists', 'filter_postures', 'DEFAULT_THRESHOLD', 'FORMAT_VERSION',
           'default_cache_dir', 'default_shared_dir', 'repo_root', 'class_statistics',
           'MappedSource', 'uiprmd_vicon_source']

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
DEFAULT_THRESHOLD = 0.02  # m^2, sum over the 20 joints of squared position differences
_ALGO_VERSION = 1  # bump when the build changes the output for the same inputs (cache key)


class DatabaseError(RuntimeError):
    """Missing, corrupt or incompatible database file."""


@dataclass
class MotionDatabase:
    """Normalised, retargeted postures. Arrays are float32 / int32; see module docstring."""

    positions: np.ndarray      # (N, 20, 3)
    orientations: np.ndarray   # (N, 20, 4) xyzw, normalised frame
    twists: np.ndarray         # (N, 19) rad, SEGMENTS order
    clip_index: np.ndarray     # (N,) index into meta['clips']
    frame_index: np.ndarray    # (N,) frame of the posture in its clip
    class_names: List[str] = field(default_factory=list)  # per clip
    meta: Dict = field(default_factory=dict)

    def __post_init__(self):
        self.positions = np.ascontiguousarray(self.positions, dtype=np.float32)
        self.orientations = np.ascontiguousarray(self.orientations, dtype=np.float32)
        self.twists = np.ascontiguousarray(self.twists, dtype=np.float32)
        self.clip_index = np.ascontiguousarray(self.clip_index, dtype=np.int32)
        self.frame_index = np.ascontiguousarray(self.frame_index, dtype=np.int32)
        n = self.positions.shape[0]
        shapes = {'positions': (self.positions.shape, (n, NUM_JOINTS, 3)),
                  'orientations': (self.orientations.shape, (n, NUM_JOINTS, 4)),
                  'twists': (self.twists.shape, (n, NUM_JOINTS - 1)),
                  'clip_index': (self.clip_index.shape, (n,)),
                  'frame_index': (self.frame_index.shape, (n,))}
        for k, (got, want) in shapes.items():
            if got != want:
                raise DatabaseError(f'motion database: {k} has shape {got}, expected {want}')

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    @property
    def flat(self) -> np.ndarray:
        """(N, 60) float32 view of the positions."""
        return self.positions.reshape(len(self), NUM_JOINTS * 3)

    @property
    def body(self) -> Body:
        """The body the postures were retargeted to (from ``meta``; default standard body)."""
        h = self.meta.get('body_height')
        m = self.meta.get('body_mass')
        if h is None:
            return standard_body()
        return standard_body(float(h), float(m) if m is not None else 75.0)

    @property
    def posture_classes(self) -> np.ndarray:
        """(N,) class name of every posture."""
        names = np.array(self.class_names + [''], dtype=object)
        return names[self.clip_index]

    def save(self, path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = dict(self.meta)
        meta['format_version'] = FORMAT_VERSION
        meta['class_names'] = list(self.class_names)
        tmp = path.with_name(path.name + f'.tmp{os.getpid()}')
        with open(tmp, 'wb') as f:
            np.savez(f, positions=self.positions, orientations=self.orientations,
                     twists=self.twists, clip_index=self.clip_index,
                     frame_index=self.frame_index, meta=np.array(json.dumps(meta)))
        os.replace(tmp, path)  # atomic: readers never see a half-written file
        return path

    @classmethod
    def load(cls, path) -> 'MotionDatabase':
        path = Path(path)
        if not path.is_file():
            raise DatabaseError(f'motion database {path} does not exist '
                                f'(build it with `ros2 run skeleton_data build_db`)')
        try:
            with np.load(path, allow_pickle=False) as z:
                missing = {'positions', 'orientations', 'twists', 'clip_index', 'frame_index',
                           'meta'} - set(z.files)
                if missing:
                    raise DatabaseError(f'motion database {path} is missing arrays '
                                        f'{sorted(missing)}')
                meta = json.loads(str(z['meta']))
                version = meta.get('format_version')
                if version != FORMAT_VERSION:
                    raise DatabaseError(f'motion database {path} has format version {version}, '
                                        f'expected {FORMAT_VERSION}: rebuild it')
                arrays = {k: z[k] for k in ('positions', 'orientations', 'twists', 'clip_index',
                                            'frame_index')}
        except DatabaseError:
            raise
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile,
                json.JSONDecodeError) as e:
            raise DatabaseError(f'motion database {path} is corrupt or not a database '
                                f'({type(e).__name__}: {e})') from None
        db = cls(class_names=list(meta.pop('class_names', [])), meta=meta, **arrays)
        if not (np.all(np.isfinite(db.positions)) and np.all(np.isfinite(db.orientations))):
            raise DatabaseError(f'motion database {path} holds non-finite values')
        return db


# ------------------------------------------------------------------------------------------
# Building
# ------------------------------------------------------------------------------------------
def segment_twists(orientations: np.ndarray, body: Optional[Body] = None) -> np.ndarray:
    """Twist angle (rad, (-pi, pi]) of every segment about its own rest axis, (..., 19).

    ``orientations`` (..., 20, 4) are segment orientations with the :mod:`mocap` convention
    (identity = standard T-pose). ``q_seg = swing * twist`` with the twist about the unit rest
    direction of the segment (``rest_offsets`` of its child joint); the swing then carries the rest
    axis to the current segment direction. Use the same function on the simulated body.
    """
    q = np.asarray(orientations, float)[..., SEGMENT_CHILD_INDEX, :]
    axes = rest_directions(body)[SEGMENT_CHILD_INDEX]
    _, angle = swing_twist(q, axes)
    return angle


def filter_postures(flat: np.ndarray, threshold: float, chunk: int = 256,
                    dims: int = 12) -> np.ndarray:
    """Greedy near-duplicate removal: indices (ascending) of the kept rows of ``flat`` (N, D).

    Row i is kept unless ``sum((flat[i] - flat[k])**2) < threshold`` for an earlier kept row k
    (exactly the result of the sequential loop). Speed-up: rows are projected on their first
    ``dims`` principal axes (an orthonormal projection never increases distances), a KD-tree over
    the projected kept rows yields candidates within ``sqrt(threshold)``, and only those are checked
    in full dimension. Rows kept since the last tree build (< 256) are checked by brute force.
    """
    from scipy.spatial import cKDTree   # (building only: the nodes load the database without it)
    x = np.ascontiguousarray(flat, dtype=np.float64)
    n = x.shape[0]
    if threshold <= 0 or n == 0:
        return np.arange(n)
    r = float(np.sqrt(threshold))
    d = min(dims, x.shape[1])
    mean = x.mean(0)
    # principal axes from a subsample (any orthonormal basis is valid; PCA makes it tight)
    sub = x[:: max(1, n // 20000)] - mean
    _, vecs = np.linalg.eigh(sub.T @ sub)
    y = (x - mean) @ vecs[:, ::-1][:, :d]
    kept: List[int] = []
    tree = None
    tree_n = 0
    for s in range(0, n, chunk):
        c = x[s:s + chunk]
        covered = np.zeros(len(c), bool)
        if tree is not None:
            lists = tree.query_ball_point(y[s:s + chunk], r, return_sorted=False)
            lens = np.fromiter((len(l) for l in lists), int, len(lists))
            if lens.sum():
                rows = np.repeat(np.arange(len(c)), lens)
                cols = np.asarray(kept[:tree_n])[np.concatenate(
                    [np.asarray(l, dtype=np.int64) for l in lists if len(l)])]
                d2 = np.sum((c[rows] - x[cols]) ** 2, 1)
                hit = rows[d2 < threshold]
                covered[hit] = True
        recent = kept[tree_n:]
        if recent:
            buf = x[recent]
            d2 = (np.sum(c * c, 1)[:, None] - 2 * c @ buf.T + np.sum(buf * buf, 1)[None])
            covered |= (d2 < threshold).any(1)
        cand = np.flatnonzero(~covered)
        if len(cand):
            cc = c[cand]
            sq = np.sum(cc * cc, 1)
            close = (sq[:, None] + sq[None, :] - 2.0 * (cc @ cc.T)) < threshold
            alive = np.ones(len(cand), bool)
            for a in range(len(cand)):
                if alive[a]:
                    kept.append(s + int(cand[a]))
                    alive[a + 1:] &= ~close[a, a + 1:]
        if len(kept) - tree_n >= 256:
            tree = cKDTree(y[kept])
            tree_n = len(kept)
    return np.asarray(kept, dtype=np.int64)


UPPER_BODY = tuple(range(2, 12))   # ShoulderCenter, Head, shoulders, arms, hands
LOWER_BODY = tuple(range(12, 20))  # hips, knees, ankles, feet


def class_statistics(db: 'MotionDatabase') -> Dict[str, Dict[str, float]]:
    """Per class: postures and the standard deviation (cm) of the normalised joint positions of the
    upper and lower body (mean over joints of the RMS of the per-axis SDs), as in Shum 2013
    Table I (which reports them for the unfiltered database)."""
    out = {}
    classes = db.posture_classes
    for cls in sorted(set(classes)):
        p = db.positions[classes == cls].astype(float)
        sd = np.sqrt(np.sum(p.var(0), -1))  # (20,)
        out[cls] = {'postures': int(len(p)),
                    'upper_sd_cm': float(100 * sd[list(UPPER_BODY)].mean()),
                    'lower_sd_cm': float(100 * sd[list(LOWER_BODY)].mean())}
    return out


def _maybe_tqdm(total, desc, enabled):
    if not enabled:
        return None
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover
        return None
    return tqdm(total=total, desc=desc, unit='frame', leave=False)


def length_ratios(clips: Sequence[MotionClip], frames: int = 30) -> Tuple[np.ndarray, np.ndarray]:
    """The bodies of ``clips`` before retargeting: per segment the mean and the standard deviation
    over the clips of (the clip's median segment length / its median standing height,
    :func:`~skeleton_core.model.estimate_height` every ``frames`` frames), (19,) each. The
    reconstruction's length prior (``pose_reconstruction.length_prior``)."""
    ratios = []
    for c in clips:
        p = np.asarray(c.positions, float)
        ln = np.median(np.linalg.norm(p[:, SEGMENT_CHILD_INDEX] - p[:, SEGMENT_PARENT_INDEX],
                                      axis=-1), axis=0)
        h = float(np.median([estimate_height(x) for x in p[::max(1, int(frames))]]))
        if np.isfinite(h) and h > 0 and np.all(np.isfinite(ln)):
            ratios.append(ln / h)
    if not ratios:
        return np.full(len(SEGMENT_NAMES), np.nan), np.full(len(SEGMENT_NAMES), np.nan)
    r = np.asarray(ratios)
    return r.mean(axis=0), r.std(axis=0)


def build_database(clips: Sequence[MotionClip], body: Optional[Body] = None,
                   threshold: Optional[float] = DEFAULT_THRESHOLD, progress: bool = True,
                   meta: Optional[dict] = None):
    """Normalise, retarget, compute twists and filter the postures of ``clips``.

    Returns ``(db, stats)``; ``stats`` holds ``frames_before``, ``frames_after``, ``clips``,
    ``threshold``, ``seconds``. ``threshold`` None or <= 0 keeps every posture.
    """
    t0 = time.perf_counter()
    body = standard_body() if body is None else body
    thr = 0.0 if threshold is None else float(threshold)
    if not clips:
        raise ValueError('build_database: no clips given')
    total = sum(len(c) for c in clips)
    bar = _maybe_tqdm(total, 'normalising', progress)
    pos_l, ori_l, ci_l, fi_l = [], [], [], []
    for k, c in enumerate(clips):
        norm, tf = normalize(c.positions)
        pos = retarget(norm, body)
        q = quat_multiply(quat_from_yaw(-tf.yaw)[:, None, :], c.orientations)
        q /= np.linalg.norm(q, axis=-1, keepdims=True)
        q *= np.where(q[..., 3:4] < 0, -1.0, 1.0)
        pos_l.append(pos)
        ori_l.append(q)
        ci_l.append(np.full(len(c), k))
        fi_l.append(np.arange(len(c)))
        if bar is not None:
            bar.update(len(c))
    if bar is not None:
        bar.close()
    pos = np.concatenate(pos_l)
    ori = np.concatenate(ori_l)
    ci = np.concatenate(ci_l)
    fi = np.concatenate(fi_l)
    t_norm = time.perf_counter() - t0
    keep = filter_postures(pos.reshape(len(pos), -1), thr)
    twists = segment_twists(ori[keep], body)
    ratio_mean, ratio_std = length_ratios(clips)
    m = {
        'joint_names': list(JOINT_NAMES),
        'segment_names': list(SEGMENT_NAMES),
        'threshold': thr,
        'threshold_unit': 'm^2, sum over joints of squared position differences',
        'body_height': float(body.height),
        'body_mass': float(body.mass),
        'segment_lengths': [float(x) for x in body.segment_lengths],
        # the clips' own bodies (before retargeting): segment length / standing height
        'length_ratio_mean': [float(x) for x in ratio_mean],
        'length_ratio_std': [float(x) for x in ratio_std],
        'frames_before': int(total),
        'frames_after': int(len(keep)),
        'clips': [c.name for c in clips],
        'sources': [c.source for c in clips],
        'clip_frames': [len(c) for c in clips],
        'clip_fps': [float(c.fps) for c in clips],
        'twist_definition': 'swing-twist of the segment orientation about its rest axis',
        'orientation_convention': 'xyzw, identity = standard T-pose facing +x',
        'built_unix': time.time(),
    }
    if meta:
        m.update(meta)
    db = MotionDatabase(positions=pos[keep], orientations=ori[keep], twists=twists,
                        clip_index=ci[keep], frame_index=fi[keep],
                        class_names=[c.motion_class for c in clips], meta=m)
    secs = time.perf_counter() - t0
    stats = {'frames_before': int(total), 'frames_after': int(len(keep)), 'clips': len(clips),
             'threshold': thr, 'seconds': secs, 'seconds_normalise': t_norm}
    return db, stats


# ------------------------------------------------------------------------------------------
# Default database with a cache
# ------------------------------------------------------------------------------------------
def repo_root() -> Path:
    """The workspace root (the directory holding ``src/skeleton_core``), else the cwd."""
    here = Path(__file__).resolve()
    for p in here.parents:
        if (p / 'src' / 'skeleton_core').is_dir():
            return p
    return Path.cwd()


def default_cache_dir() -> Path:
    env = os.environ.get('KINECT_POSTURE_CACHE')
    return Path(env) if env else repo_root() / 'cache'


DEFAULT_FILE = 'motion_db.npz'


def default_path() -> Path:
    """The default motion database file: what ``make build-db`` writes and what every node's
    ``database`` parameter ('' ) loads. Nodes never build it (a missing file is a one-line
    configure error naming ``make build-db``)."""
    return default_cache_dir() / DEFAULT_FILE


def default_shared_dir() -> Optional[Path]:
    env = os.environ.get('KP_SHARED')
    p = Path(env) if env else repo_root().parent / 'shared'
    return p if p.is_dir() else None


def _code_digest() -> str:
    """Hash of the modules whose code decides the database content (so edits invalidate it)."""
    h = hashlib.sha256()
    here = Path(__file__).resolve().parent
    for path in [here / n for n in ('database.py', 'mocap.py', 'motions.py', 'bvh.py',
                                     'joint_map.py', 'vicon.py')] \
            + [Path(geometry.__file__), Path(model.__file__), maps_dir() / 'cmu_bvh.yaml']:
        try:
            h.update(path.read_bytes())
        except OSError:  # pragma: no cover
            h.update(path.name.encode())
    return h.hexdigest()[:16]


def _files_digest(files: Sequence[Path]) -> str:
    h = hashlib.sha256()
    for f in files:
        st = f.stat()
        h.update(f'{f.name}:{st.st_size}:{st.st_mtime_ns};'.encode())
    return h.hexdigest()


@dataclass(frozen=True)
class MappedSource:
    """A folder of mocap clips in another convention, read through a joint map
    (:mod:`skeleton_data.joint_map`): files whose name matches one of ``include`` (if any) and
    none of ``exclude`` (shell patterns)."""

    folder: Path
    joint_map: Path
    include: Tuple[str, ...] = ()
    exclude: Tuple[str, ...] = ()

    def files(self) -> List[Path]:
        return mapped_files(self.folder, load_joint_map(self.joint_map), self.include,
                            self.exclude)

    def key(self) -> dict:
        """Cache-key part: the map's content, the selection and the selected files."""
        return {'map': hashlib.sha256(Path(self.joint_map).read_bytes()).hexdigest()[:16],
                'include': list(self.include), 'exclude': list(self.exclude),
                'files': _files_digest(self.files())}


def uiprmd_vicon_source(src, subjects: Optional[Sequence[int]] = None,
                        exclude_subjects: Sequence[int] = (), joint_map=None) -> MappedSource:
    """The Vicon marker files of a UI-PRMD folder (``<src>/Vicon/Positions``) through the
    Plug-in-Gait map: the repetitions of ``subjects`` (None: all) except ``exclude_subjects``
    (e.g. the subject a leave-one-subject-out fold scores)."""
    inc = tuple(f'm*_s{int(s):02d}_*' for s in subjects) if subjects else ()
    exc = tuple(f'm*_s{int(s):02d}_*' for s in exclude_subjects)
    return MappedSource(Path(src) / 'Vicon' / 'Positions',
                        Path(joint_map) if joint_map else maps_dir() / 'plug_in_gait.yaml',
                        inc, exc)


def load_mapped_sources(sources: Sequence[MappedSource], skipped: Optional[list] = None) -> list:
    """The clips of every mapped source (see :func:`skeleton_data.mocap.load_mapped_clips`)."""
    clips = []
    for ms in sources:
        clips += load_mapped_clips(ms.folder, load_joint_map(ms.joint_map), ms.include, ms.exclude,
                                   skipped=skipped)
    return clips


def load_or_build_default(source: str = 'auto', cache_dir=None, shared_dir=None,
                          threshold: Optional[float] = None, classes: Sequence[str] = FIVE_CLASSES,
                          split: str = 'database', mirror: bool = False,
                          progress: bool = False, rebuild: bool = False,
                          stats: Optional[dict] = None,
                          mapped: Sequence[MappedSource] = ()) -> MotionDatabase:
    """The default motion database, from the cache when its inputs have not changed.

    ``source``: ``'cmu'`` (``<shared>/mocap/cmu``), ``'builtin'`` (:mod:`motions`) or ``'auto'``
    (CMU when the shared folder exists: ``shared_dir``, else ``$KP_SHARED``, else ``../shared``
    of the repository). ``split``: ``'database'`` (the database part of the split, default) or
    ``'all'`` (database and dev clips). ``classes`` None: all CMU clips including 'other'.
    ``mirror`` adds left-right mirrored copies. ``mapped``: clips in other conventions added
    beside (all their frames: a lab's own mocap is not split); with ``source='none'`` only
    those. The cache file name is a hash of the inputs
    (file names, sizes, mtimes), every parameter and the code of the modules that build it.
    ``stats`` (dict) receives build statistics
    plus ``cache_hit`` and ``path``.
    """
    from . import mocap, motions  # local: keeps import of this module light
    thr = DEFAULT_THRESHOLD if threshold is None else float(threshold)
    if source not in ('auto', 'cmu', 'builtin', 'none'):
        raise ValueError(f"source must be 'auto', 'cmu', 'builtin' or 'none', got {source!r}")
    if source == 'none' and not mapped:
        raise ValueError("source 'none' needs mapped mocap sources")
    if split not in ('database', 'all'):
        raise ValueError(f"split must be 'database' or 'all', got {split!r}")
    if shared_dir is None:
        shared_dir = default_shared_dir()
    cmu_dir = Path(shared_dir) / 'mocap' / 'cmu' if shared_dir is not None else None
    if source == 'auto':
        source = 'cmu' if cmu_dir is not None and cmu_dir.is_dir() else 'builtin'
    if source == 'cmu' and (cmu_dir is None or not cmu_dir.is_dir()):
        raise DatabaseError(f'CMU mocap folder not found ({cmu_dir or "no shared folder"}); '
                            f'use source="builtin" or set KP_SHARED')
    key = {'algo': _ALGO_VERSION, 'code': _code_digest(), 'format': FORMAT_VERSION,
           'source': source, 'threshold': thr,
           'split': split, 'mirror': bool(mirror), 'height': standard_body().height}
    if source == 'cmu':
        key['classes'] = sorted(classes) if classes is not None else None
        key['files'] = _files_digest(sorted(cmu_dir.glob('*.bvh')) +
                                     [p for p in [cmu_dir / 'index.csv'] if p.is_file()])
    elif source == 'builtin':
        key['seed'] = 0
    if mapped:
        key['mapped'] = [m.key() for m in mapped]
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]
    cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    label = '+'.join([source] * (source != 'none') + [Path(m.joint_map).stem for m in mapped])
    path = cache_dir / f'motion_db_{label}_{digest}.npz'
    out_stats = stats if stats is not None else {}
    if path.is_file() and not rebuild:
        try:
            t0 = time.perf_counter()
            db = MotionDatabase.load(path)
            log.info('motion database cache hit: %s (%d postures, loaded in %.3f s)', path,
                     len(db), time.perf_counter() - t0)
            out_stats.update(cache_hit=True, path=str(path), frames_after=len(db),
                             frames_before=db.meta.get('frames_before'), skipped=[])
            return db
        except DatabaseError as e:
            log.warning('ignoring unusable cached database: %s', e)
    skipped: list = []
    if source == 'cmu':
        db_clips, dev_clips = mocap.cmu_split(cmu_dir, classes, skipped=skipped) if classes \
            is not None else mocap.split_clips(mocap.load_cmu_clips(cmu_dir, None, skipped=skipped))
    elif source == 'builtin':
        db_clips, dev_clips = motions.builtin_split()
    else:
        db_clips, dev_clips = [], []
    clips = list(db_clips) + (list(dev_clips) if split == 'all' else [])
    clips += load_mapped_sources(mapped, skipped)
    if not clips:
        raise DatabaseError('no usable clips in the mapped mocap sources')
    if mirror:
        clips = clips + [mocap.mirror_clip(c) for c in clips]
    db, st = build_database(clips, threshold=thr, progress=progress,
                            meta={'source': label, 'cache_key': key, 'skipped': skipped})
    db.save(path)
    log.info('motion database built: %d -> %d postures from %d clips in %.1f s, saved %s',
             st['frames_before'], st['frames_after'], st['clips'], st['seconds'], path)
    out_stats.update(st, cache_hit=False, path=str(path), skipped=skipped)
    return db


def build_default(**kwargs) -> MotionDatabase:
    """The producer of the nodes' default database (``make build-db``, and the tools that start
    the graph: ``demo``, ``bench``, ``soak``): :func:`load_or_build_default` (``kwargs``), written
    to :func:`default_path`, the file every node's default ``database`` loads."""
    db = load_or_build_default(**kwargs)
    db.save(default_path())
    return db
