"""Learned sensor correction: the skeleton tracker's posture-dependent error, learned from paired
recordings (tracker skeleton + marker-derived joint centres) and removed from each frame.

The tracker's joint centres sit away from the anatomical ones (real Kinect v2 against Vicon
joint-centre estimates: ~13 deg per bone, 5-10 cm per joint), by an amount that depends on the
posture (a bent knee moves the tracker's knee joint differently from a straight one). Liu, Zhou,
Leung & Shum 2016 learn this from Kinect/mocap pairs (local mixture of Gaussian processes);
this module learns it with a linear model in the body frame, which measured as well as a local
(K-nearest-neighbour) one on held-out subjects (docs/real_recordings.md):

* **Body (heading) frame.** Every frame is expressed relative to the tracker's root joint and
  turned about the vertical so that the body faces +x (heading from the hip and shoulder lines,
  :func:`skeleton_core.geometry.facing_yaw`). The correction does not depend on where the user
  stands or which way they face.
* **Posture-independent part.** ``offset`` (20, 3): the mean (reference - tracker) per joint in
  that frame, e.g. the Kinect v2 SpineBase sits ~3 cm behind the pelvis centre.
* **Posture-dependent part.** ``weights`` (57, 60): ridge regression of the remaining
  (reference - tracker) vectors of all 20 joints on the posture features: the 19 bone unit
  directions of the tracker skeleton in the body frame (length-free, so the user's size does
  not enter). The ridge strength is chosen by leave-one-group-out (one group per subject) on the
  training data only (:func:`fit`).

Correction of a frame: ``p + R(yaw) (offset + weights^T (f(p) - mean))``. Hands take the wrist's
correction (the paired data set has no tracked hands). With ``weights`` (20,) (reliabilities),
only joints at or above the threshold are moved and only bones with both ends at or above it
enter the features (the others are held at the training mean, i.e. contribute nothing).

A correction is specific to the skeleton tracker it was learned from (:data:`TRACKERS`): the file
records it, and :func:`check_tracker` refuses a stream whose tracker is another or unknown.

File: ``.npz`` with the arrays and a JSON ``meta`` (format, tracker, training subjects/clips,
ridge strength, source digest); :func:`load` validates it and raises :class:`CorrectionFileError`
with one line when it is malformed.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Optional, Sequence

import numpy as np

from skeleton_core.geometry import facing_yaw
from skeleton_core.params import param
from skeleton_core.tracker import TRACKERS
from skeleton_core.model import (HAND_LEFT, HAND_RIGHT, NUM_JOINTS, NUM_SEGMENTS,
                                 SEGMENT_CHILDREN, SEGMENT_PARENTS, WRIST_LEFT, WRIST_RIGHT)
from skeleton_data.database import default_shared_dir
from skeleton_data.database import default_cache_dir
from skeleton_eval.paired import load_dataset

FORMAT = 'kinect_posture.sensor_correction'
FORMAT_VERSION = 1
NUM_FEATURES = 3 * NUM_SEGMENTS
RIDGE_GRID = (1e-3, 3e-3, 1e-2, 3e-2, 1e-1, 3e-1, 1.0)  # ridge strength / training frames
_SC = np.array(SEGMENT_CHILDREN)
_SP = np.array(SEGMENT_PARENTS)
_COPY = ((HAND_LEFT, WRIST_LEFT), (HAND_RIGHT, WRIST_RIGHT))


STAGES = ('input', 'reliable')


@dataclass
class CorrectionConfig:
    """The node parameters of the learned correction and the user profile (files and names are
    resolved by the node: :func:`pose_reconstruction.node_common.load_user_terms`)."""

    sensor_correction: str = param(
        'auto', "learned sensor correction file; 'auto' = the one for the input's tracker, "
        'cache/sensor_correction_<tracker>.npz (written by `make build-correction` or '
        "build_correction --bag ... --reference ...), else off; '' = off")
    input_tracker: str = param(
        '', 'skeleton tracker of the input stream (kinect_v2_sdk, kinect_v1_sdk, nite2, '
        "azure_kinect_bt, sensor_model; '' = the one the stream declares on /kinect/tracker): a correction is "
        'applied only to the tracker it was learned from', choices=('',) + TRACKERS)
    correction_stage: str = param(
        'input', 'where the correction runs: input (every joint, before the reliability) or '
        'reliable (the reliable joints, after it)', choices=STAGES, public=False)
    user_profile: str = param(
        '', "user profile name (<profiles_dir>/<name>.json, from build_profile): the user's "
        "segment lengths from the first frame; '' = measured per user")
    profiles_dir: str = param('', "directory of user profiles ('' = cache/profiles)")


class CorrectionFileError(ValueError):
    """A correction file that cannot be used (one line: the file and why)."""


class TrackerMismatch(ValueError):
    """A correction offered to a stream of another (or an undeclared) skeleton tracker."""


def _rot(yaw: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations about +z (body frame -> sensor frame)."""
    c, s = np.cos(yaw), np.sin(yaw)
    r = np.zeros(np.shape(yaw) + (3, 3))
    r[..., 0, 0] = c
    r[..., 0, 1] = -s
    r[..., 1, 0] = s
    r[..., 1, 1] = c
    r[..., 2, 2] = 1.0
    return r


def body_frame(positions: np.ndarray, reliability: Optional[np.ndarray] = None) -> np.ndarray:
    """(..., 3, 3) rotation body frame -> sensor frame of skeletons (..., 20, 3)."""
    w = None if reliability is None else np.maximum(np.asarray(reliability, float), 1e-3)
    return _rot(facing_yaw(positions, w))


def features(positions: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """(..., 57) bone unit directions in the body frame (``rot`` from :func:`body_frame`)."""
    v = positions[..., _SC, :] - positions[..., _SP, :]
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    u = v / np.maximum(n, 1e-9)
    u = np.einsum('...sk,...kj->...sj', u, rot)  # sensor -> body: u @ R
    return u.reshape(u.shape[:-2] + (NUM_FEATURES,))


def targets(positions: np.ndarray, reference: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """(..., 20, 3) reference - tracker in the body frame; hands take the wrists' rows."""
    d = np.asarray(reference, float) - np.asarray(positions, float)
    for h, w in _COPY:
        d[..., h, :] = d[..., w, :]
    return np.einsum('...jk,...kl->...jl', d, rot)


@dataclass
class SensorCorrection:
    """A learned correction (module docstring)."""

    tracker: str
    offset: np.ndarray                  # (20, 3) body frame, m
    weights: np.ndarray                 # (57, 60) ridge weights (zeros: offset only)
    feature_mean: np.ndarray            # (57,)
    meta: Dict = field(default_factory=dict)

    def __post_init__(self):
        if self.tracker not in TRACKERS:
            raise ValueError(f'unknown tracker {self.tracker!r}; known: {", ".join(TRACKERS)}')
        self.offset = np.ascontiguousarray(self.offset, float)
        self.weights = np.ascontiguousarray(self.weights, float)
        self.feature_mean = np.ascontiguousarray(self.feature_mean, float)
        for name, arr, shape in (('offset', self.offset, (NUM_JOINTS, 3)),
                                 ('weights', self.weights, (NUM_FEATURES, 3 * NUM_JOINTS)),
                                 ('feature_mean', self.feature_mean, (NUM_FEATURES,))):
            if arr.shape != shape:
                raise ValueError(f'{name} must have shape {shape}, got {arr.shape}')
            if not np.isfinite(arr).all():
                raise ValueError(f'{name} holds non-finite values')

    # -- applying --------------------------------------------------------------------------------
    def delta(self, positions: np.ndarray, reliability: Optional[np.ndarray] = None,
              threshold: float = 0.5) -> np.ndarray:
        """(..., 20, 3) the correction to add to ``positions`` (..., 20, 3), sensor frame."""
        p = np.asarray(positions, float)
        rot = body_frame(p, reliability)
        f = features(p, rot) - self.feature_mean
        if reliability is not None:
            ok = np.asarray(reliability, float) >= threshold
            bone_ok = ok[..., _SP] & ok[..., _SC]
            f = f * np.repeat(bone_ok, 3, axis=-1)
        c = self.offset + (f @ self.weights).reshape(f.shape[:-1] + (NUM_JOINTS, 3))
        d = np.einsum('...jk,...lk->...jl', c, rot)  # body -> sensor: c @ R.T
        if reliability is not None:
            d = np.where(ok[..., None], d, 0.0)
        return d

    def apply(self, positions: np.ndarray, reliability: Optional[np.ndarray] = None,
              threshold: float = 0.5) -> np.ndarray:
        """Corrected positions (same shape). With ``reliability``: only reliable joints move."""
        return np.asarray(positions, float) + self.delta(positions, reliability, threshold)

    # -- file ------------------------------------------------------------------------------------
    def save(self, path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {'format': FORMAT, 'version': FORMAT_VERSION, 'tracker': self.tracker,
                **{k: v for k, v in self.meta.items() if k not in ('format', 'version',
                                                                   'tracker')}}
        tmp = path.with_name(path.name + '.tmp.npz')
        np.savez(tmp, offset=self.offset, weights=self.weights, feature_mean=self.feature_mean,
                 meta=np.array(json.dumps(meta)))
        tmp.replace(path)
        return path

    def describe(self) -> str:
        subj = self.meta.get('subjects')
        return (f'sensor correction for {self.tracker} skeletons'
                + (f' (learned on {", ".join(subj)}, {self.meta.get("frames", "?")} frames)'
                   if subj else ''))


def load(path) -> SensorCorrection:
    """Read and validate a correction file; :class:`CorrectionFileError` (one line) if unusable."""
    p = Path(path).expanduser()
    if not p.is_file():
        raise CorrectionFileError(f'sensor correction {str(p)!r} does not exist')
    try:
        with np.load(p, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except Exception as e:  # noqa: BLE001 - any unreadable file: one clear line
        raise CorrectionFileError(f'sensor correction {str(p)!r} cannot be read: '
                                  f'{type(e).__name__}: {e}') from e
    missing = [k for k in ('offset', 'weights', 'feature_mean', 'meta') if k not in arrays]
    if missing:
        raise CorrectionFileError(f'sensor correction {str(p)!r} lacks {", ".join(missing)}')
    try:
        meta = json.loads(str(arrays['meta']))
        if not isinstance(meta, dict):
            raise ValueError('meta is not an object')
    except ValueError as e:
        raise CorrectionFileError(f'sensor correction {str(p)!r}: bad meta ({e})') from e
    if meta.get('format') != FORMAT or meta.get('version') != FORMAT_VERSION:
        raise CorrectionFileError(f'sensor correction {str(p)!r}: not a version {FORMAT_VERSION} '
                                  f'{FORMAT} file (format {meta.get("format")!r}, version '
                                  f'{meta.get("version")!r})')
    try:
        return SensorCorrection(tracker=meta.get('tracker'), offset=arrays['offset'],
                                weights=arrays['weights'], feature_mean=arrays['feature_mean'],
                                meta=meta)
    except (ValueError, TypeError) as e:
        raise CorrectionFileError(f'sensor correction {str(p)!r}: {e}') from e


def describe_file(correction: SensorCorrection) -> str:
    return (correction.describe() + (f' from {correction.meta["source"]}'
                                     if correction.meta.get('source') else ''))


def check_tracker(correction: SensorCorrection, input_tracker: str) -> None:
    """Raise :class:`TrackerMismatch` unless the stream's declared tracker is the correction's."""
    if not input_tracker:
        raise TrackerMismatch(f'{correction.describe()} not applied: the input stream\'s skeleton '
                              f'tracker is not declared (the stream carries none on '
                              f'/kinect/tracker; set input_tracker to {correction.tracker!r} if '
                              f'the input comes from it)')
    if input_tracker != correction.tracker:
        raise TrackerMismatch(f'{correction.describe()} not applied: the input comes from '
                              f'{input_tracker!r}, another tracker')


# ------------------------------------------------------------------------------------------
# Fitting
# ------------------------------------------------------------------------------------------
def _stack(kinect: Sequence[np.ndarray], reference: Sequence[np.ndarray], groups):
    F, Y, G = [], [], []
    for i, (k, r) in enumerate(zip(kinect, reference)):
        k = np.asarray(k, float)
        r = np.asarray(r, float)
        if k.shape != r.shape or k.ndim != 3 or k.shape[1:] != (NUM_JOINTS, 3):
            raise ValueError(f'pair {i}: tracker {k.shape} and reference {r.shape} must both be '
                             f'(T, {NUM_JOINTS}, 3)')
        rot = body_frame(k)
        y = targets(k, r, rot)
        ok = np.isfinite(y).all(axis=(1, 2)) & np.isfinite(k).all(axis=(1, 2))
        F.append(features(k[ok], rot[ok]))
        Y.append(y[ok].reshape(-1, 3 * NUM_JOINTS))
        G.append(np.full(int(ok.sum()), i if groups is None else groups[i]))
    if not F or sum(len(f) for f in F) < 2:
        raise ValueError('no paired frame with a complete reference')
    return np.concatenate(F), np.concatenate(Y), np.concatenate(G)


def _ridge(F: np.ndarray, Y: np.ndarray, alpha: float):
    mean_f = F.mean(0)
    b = Y.mean(0)
    A = F - mean_f
    lam = alpha * len(A)
    W = np.linalg.solve(A.T @ A + lam * np.eye(A.shape[1]), A.T @ (Y - b))
    return mean_f, b, W


def fit(kinect: Sequence[np.ndarray], reference: Sequence[np.ndarray], tracker: str,
        groups: Optional[Sequence] = None, posture: bool = True,
        grid: Sequence[float] = RIDGE_GRID, meta: Optional[Dict] = None) -> SensorCorrection:
    """Learn a correction from pairs of (T, 20, 3) tracker / reference sequences in one frame.

    ``groups``: one label per pair (the subject): the ridge strength is the value of ``grid``
    with the lowest mean joint error over leave-one-group-out folds of the training pairs (with
    fewer than two groups, the middle of the grid). ``posture`` False: the per-joint offset only.
    Reference rows with NaN (outside the reference recording, a missing marker) are skipped."""
    F, Y, G = _stack(kinect, reference, groups)
    labels = list(dict.fromkeys(G.tolist()))
    scores = {}
    if not posture:
        mean_f, b = F.mean(0), Y.mean(0)
        W = np.zeros((NUM_FEATURES, 3 * NUM_JOINTS))
        alpha = None
    else:
        if len(labels) >= 2 and len(grid) > 1:
            for a in grid:
                err, n = 0.0, 0
                for g in labels:
                    tr = G != g
                    mf, bb, W = _ridge(F[tr], Y[tr], a)
                    res = Y[~tr] - bb - (F[~tr] - mf) @ W
                    err += float(np.linalg.norm(res.reshape(-1, NUM_JOINTS, 3), axis=-1).sum())
                    n += int((~tr).sum()) * NUM_JOINTS
                scores[a] = err / max(n, 1)
            alpha = min(scores, key=scores.get)
        else:
            alpha = float(grid[len(grid) // 2])
        mean_f, b, W = _ridge(F, Y, alpha)
    info = {'frames': int(len(F)), 'pairs': len(kinect), 'ridge_alpha': alpha,
            'ridge_scores_m': {str(k): v for k, v in scores.items()},
            'model': 'offset+ridge(bone directions)' if posture else 'offset',
            **reference_proportions(reference, groups)}
    return SensorCorrection(tracker=tracker, offset=b.reshape(NUM_JOINTS, 3), weights=W,
                            feature_mean=mean_f, meta={**info, **(meta or {})})


def reference_proportions(reference: Sequence[np.ndarray],
                          groups: Optional[Sequence] = None) -> Dict:
    """The segment proportions of the layout the correction maps to (its reference's joint
    centres), for the length prior (:mod:`.length_prior`): per group (subject) the median over
    its sequences of each sequence's median segment length, divided by the sum of the segments
    every group has; ``reference_length_ratio_mean`` / ``_std`` (19 numbers or None where the
    reference has no segment, e.g. the hands) the mean and the spread (ddof 1) over the groups,
    ``reference_length_groups`` their number (only that with fewer than two: no spread).

    Why: the corrected joints sit where the reference puts the joint centres (on UI-PRMD the
    Plug-in-Gait centres: hip segments ~10 cm, the Kinect's 7-9, the CMU database bodies' others
    again), so the database bodies' proportions do not describe the corrected skeleton and a
    prior built from them pulls its lengths away from what the sensor, corrected, measures."""
    labels = list(range(len(reference))) if groups is None else list(groups)
    per: Dict = {}
    for g, r in zip(labels, reference):
        r = np.asarray(r, float)
        L = np.linalg.norm(r[:, _SC] - r[:, _SP], axis=-1)
        ok = np.isfinite(L)
        med = np.full(NUM_SEGMENTS, np.nan)
        have = ok.any(axis=0)
        med[have] = [np.median(L[ok[:, i], i]) for i in np.flatnonzero(have)]
        per.setdefault(g, []).append(med)
    if len(per) < 2:
        return {'reference_length_groups': len(per)}
    Lg = np.full((len(per), NUM_SEGMENTS), np.nan)
    for k, v in enumerate(per.values()):
        v = np.array(v)
        for i in range(NUM_SEGMENTS):
            f = v[np.isfinite(v[:, i]), i]
            if len(f):
                Lg[k, i] = np.median(f)
    common = np.isfinite(Lg).all(axis=0) & (Lg > 0).all(axis=0)
    if not common.any():
        return {'reference_length_groups': len(per)}
    ratios = Lg[:, common] / Lg[:, common].sum(axis=1, keepdims=True)
    mean = np.full(NUM_SEGMENTS, np.nan)
    std = np.full(NUM_SEGMENTS, np.nan)
    mean[common] = ratios.mean(axis=0)
    std[common] = ratios.std(axis=0, ddof=1)
    as_list = lambda a: [float(x) if np.isfinite(x) else None for x in a]  # noqa: E731
    return {'reference_length_ratio_mean': as_list(mean),
            'reference_length_ratio_std': as_list(std), 'reference_length_groups': len(per)}


def digest(correction: SensorCorrection) -> str:
    """Short content hash (cache keys)."""
    h = hashlib.sha256()
    for a in (correction.offset, correction.weights, correction.feature_mean):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(correction.tracker.encode())
    return h.hexdigest()[:12]


__all__ = ['SensorCorrection', 'CorrectionFileError', 'TrackerMismatch', 'TRACKERS', 'fit',
           'load', 'check_tracker', 'select', 'features', 'targets', 'body_frame', 'digest']


# ------------------------------------------------------------------------------------------
# Building from paired recordings (UI-PRMD layout: Kinect/ + Vicon/ positions)
# ------------------------------------------------------------------------------------------
from skeleton_data.uiprmd import TRACKER as UIPRMD_TRACKER  # noqa: E402 - Kinect v2 SDK


def default_source() -> Optional[Path]:
    """The paired development recordings (``<shared>/kinect/ui-prmd``) if present."""
    shared = default_shared_dir()
    p = None if shared is None else Path(shared) / 'kinect' / 'ui-prmd'
    return p if p is not None and (p / 'Vicon' / 'Positions').is_dir() else None


def default_path(tracker: str = UIPRMD_TRACKER) -> Path:
    return default_cache_dir() / f'sensor_correction_{tracker}.npz'


def _source_digest(src: Path) -> str:
    h = hashlib.sha256()
    for sub in ('Kinect/Positions', 'Kinect/Angles', 'Vicon/Positions'):
        d = src / sub
        for f in sorted(d.iterdir()) if d.is_dir() else ():
            st = f.stat()
            h.update(f'{sub}/{f.name}:{st.st_size}:{st.st_mtime_ns};'.encode())
    here = Path(__file__).resolve()
    h.update(here.read_bytes())
    try:
        import skeleton_data.uiprmd as ui
        import skeleton_data.vicon as vi
        import skeleton_eval.paired as pa
        import skeleton_eval.registration as reg
        for m in (reg, ui, vi, pa):
            h.update(Path(m.__file__).read_bytes())
    except ImportError:  # pragma: no cover
        pass
    return h.hexdigest()[:16]


def paired_sequences(clips, subjects: Optional[Sequence[int]] = None):
    """(kinect list, reference list, subject labels, clip names) of loaded UI-PRMD clips with a
    registered reference, tracking-failure clips left out, optionally only ``subjects``."""
    K, R, G, N = [], [], [], []
    for rc in clips:
        if rc.reference is None or rc.clip.is_tracking_failure:
            continue
        if subjects is not None and rc.clip.subject not in subjects:
            continue
        K.append(rc.kinect.positions)
        R.append(rc.reference)
        G.append(f's{rc.clip.subject:02d}')
        N.append(rc.clip.name)
    return K, R, G, N


def build_from_clips(clips, subjects: Optional[Sequence[int]] = None, posture: bool = True,
                     meta: Optional[Dict] = None) -> SensorCorrection:
    """Fit a correction on loaded UI-PRMD clips (:func:`skeleton_eval.paired.load_dataset`)."""
    K, R, G, N = paired_sequences(clips, subjects)
    if not K:
        raise ValueError('no clip with a registered marker reference to learn from')
    return fit(K, R, UIPRMD_TRACKER, groups=G, posture=posture,
               meta={'subjects': sorted(set(G)), 'clips': len(N), **(meta or {})})


def build(src, out=None, subjects: Optional[Sequence[int]] = None,
          posture: bool = True) -> tuple:
    """Load paired recordings under ``src`` (UI-PRMD layout), fit, save; (correction, path)."""
    src = Path(src)
    clips, skipped, _ = load_dataset(src, subjects=subjects)
    corr = build_from_clips(clips, subjects, posture,
                            meta={'source': str(src.resolve()), 'source_digest':
                                  _source_digest(src), 'skipped_files': len(skipped)})
    path = corr.save(out if out is not None else default_path(corr.tracker))
    return corr, path


def load_or_build_default(src=None, rebuild: bool = False, log=None) -> Optional[SensorCorrection]:
    """The default correction: ``cache/sensor_correction_kinect_v2_sdk.npz`` when it was built
    from the current paired recordings, else built from them (``<shared>/kinect/ui-prmd``);
    None when there are no paired recordings and no file (the correction is then off)."""
    src = Path(src) if src is not None else default_source()
    path = default_path()
    if src is None:
        if path.is_file():
            return load(path)
        return None
    dig = _source_digest(src)
    if path.is_file() and not rebuild:
        try:
            corr = load(path)
            if corr.meta.get('source_digest') == dig and 'reference_length_groups' in corr.meta:
                return corr
            if log and corr.meta.get('source_digest') == dig:
                log(f'{path} was built before corrections stored their reference\'s segment '
                    'proportions; rebuilding')
        except CorrectionFileError as e:
            if log:
                log(f'{e}; rebuilding')
    if log:
        log(f'building the sensor correction from {src} into {path}')
    corr, _ = build(src, path)
    return corr


BUILD_COMMAND = 'make build-correction'


def select(name: str, tracker: str, log=None, warn=None) -> Optional[SensorCorrection]:
    """The correction for a stream of skeleton tracker ``tracker`` ('' = undeclared), as the
    ``sensor_correction`` parameter / ``--correction`` option names it: '' = off; 'auto' = the
    file for that tracker, :func:`default_path` (``cache/sensor_correction_<tracker>.npz``, never
    built here: for ``kinect_v2_sdk`` a missing file raises FileNotFoundError naming
    ``make build-correction``), None when there is none; a path = that file, which must exist and be valid
    (:class:`CorrectionFileError`, one line). A correction for another tracker (or a stream whose
    tracker is unknown) is refused with one line through ``warn`` and None is returned."""
    info = log or (lambda m: None)
    warn = warn or info
    corr = None
    if name == 'auto':
        if not tracker:
            info('sensor correction off: the input stream declares no skeleton tracker '
                 '(/kinect/tracker) and input_tracker is not set')
            return None
        path = default_path(tracker)
        if path.is_file():
            try:
                corr = load(path)
            except CorrectionFileError as e:   # one line, with its producer
                raise ValueError(f'{e}: rebuild it with `{BUILD_COMMAND}`') from None
        elif tracker == UIPRMD_TRACKER:   # the shipped producer's tracker: a missing build step
            raise FileNotFoundError(f'sensor correction {str(path)!r} does not exist: build it '
                                    f"with `{BUILD_COMMAND}` (or sensor_correction:='' for none)")
        else:
            info(f'sensor correction off: none learned for {tracker} skeletons ({path} does not '
                 f'exist; build_correction --bag ... --reference ... learns one)')
            return None
    elif name:
        corr = load(name)  # CorrectionFileError (a ValueError): one line
    if corr is None:
        return None
    try:
        check_tracker(corr, tracker)
    except TrackerMismatch as e:
        warn(str(e))
        return None
    return corr
