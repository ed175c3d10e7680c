"""Shum et al. 2013 Table III: reconstruction from joint subsets, (a) left hand + foot ... (e) all
parts. The other joints are NOT_TRACKED (reliability 0, frozen at the first frame) on a noise-only
stream. ``calibration='tpose'`` (the paper's protocol: a calibrated user) first shows each method a
short, unscored segment of the same user standing in a T-pose (or ``'standing'``, arms down) with
every joint tracked; ``'none'`` hides the other joints from the very first frame.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np

from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import (ELBOW_LEFT, ELBOW_RIGHT, FOOT_LEFT, FOOT_RIGHT, HAND_LEFT,
                                 HAND_RIGHT, JOINT_NAMES, KNEE_LEFT, KNEE_RIGHT, NOT_TRACKED,
                                 NUM_JOINTS, SHOULDER_LEFT, SHOULDER_RIGHT, TRACKED, WRIST_LEFT,
                                 WRIST_RIGHT, estimate_height, standard_body)
from skeleton_data.mocap import MotionClip, load_cmu_clip
from .clips import shared_dir
from .evaluation import evaluate_streams, make_streams, run_meta, stream_frames
from .sensor_model import SensorModel
from .sensor_stream import KinectStream

TABLE3_SUBSETS = {
    'a': ('Left Hand, Left Foot', (HAND_LEFT, FOOT_LEFT)),
    'b': ('Hands', (HAND_LEFT, HAND_RIGHT)),
    'c': ('Hands, Feet', (HAND_LEFT, HAND_RIGHT, FOOT_LEFT, FOOT_RIGHT)),
    'd': ('Hands, Feet, Elbows, Knees', (HAND_LEFT, HAND_RIGHT, FOOT_LEFT, FOOT_RIGHT, ELBOW_LEFT,
                                         ELBOW_RIGHT, KNEE_LEFT, KNEE_RIGHT)),
    'e': ('All Parts', tuple(range(NUM_JOINTS))),
}


def subset_frames(stream: KinectStream, joints: Sequence[int]) -> List[SkeletonFrame]:
    """Frames where only ``joints`` are TRACKED (reliability 1); the others are NOT_TRACKED,
    reliability 0 and frozen at their first-frame position."""
    keep = np.zeros(NUM_JOINTS, bool)
    keep[list(joints)] = True
    frames = []
    for f in stream_frames(stream):
        f.positions[~keep] = stream.positions[0][~keep]
        f.tracking_state[~keep] = NOT_TRACKED
        f.tracking_state[keep] = TRACKED
        f.reliability = np.where(keep, 1.0, 0.0).astype(np.float32)
        frames.append(f)
    return frames


CALIBRATIONS = ('tpose', 'standing', 'none')
CALIBRATION_SECONDS = 1.0


def calibration_pose(clip, pose: str = 'tpose', cmu_dir=None):
    """The clip's own user standing in a calibration pose, in the clip's world frame (REP-103,
    floor at z = 0): ``(positions (20, 3), description)``.

    * CMU clips (``source`` 'cmu:<file>'): frame 0 of the cgspeed BVH file, a synthetic T-pose of
      that subject (``mocap.load_cmu_clip`` drops it from the motion);
    * built-in motions (``source`` 'builtin:...'): the T-pose of the standard body they are
      driven on;
    * any other clip: the standard body's T-pose at the height of the clip's first frame.

    ``pose='standing'``: the same skeleton with both arms hanging straight down from the
    shoulders (the reliability estimator's second reference posture)."""
    if pose not in ('tpose', 'standing'):
        raise ValueError(f"calibration pose must be 'tpose' or 'standing', got {pose!r}")
    src = str(getattr(clip, 'source', '') or '')
    p = None
    if src.startswith('cmu:'):
        folder = Path(cmu_dir) if cmu_dir is not None else shared_dir() / 'mocap' / 'cmu'
        path = folder / src[4:]
        if path.is_file():
            full = load_cmu_clip(path, getattr(clip, 'motion_class', None), drop_first=False)
            p, desc = full.positions[0].copy(), f'{path.name} frame 0 (BVH T-pose)'
    if p is None and src.startswith('builtin:'):
        p, desc = standard_body().rest_positions(), 'standard body T-pose (built-in motions)'
    if p is None:
        h = float(np.clip(estimate_height(np.asarray(clip.positions[0], float)), 1.0, 2.4))
        p, desc = standard_body(h).rest_positions(), f'standard body T-pose at {h:.2f} m'
    if pose == 'standing':
        p = p.copy()
        for chain in ((SHOULDER_LEFT, ELBOW_LEFT, WRIST_LEFT, HAND_LEFT),
                      (SHOULDER_RIGHT, ELBOW_RIGHT, WRIST_RIGHT, HAND_RIGHT)):
            lengths = [np.linalg.norm(p[b] - p[a]) for a, b in zip(chain[:-1], chain[1:])]
            for a, b, length in zip(chain[:-1], chain[1:], lengths):
                p[b] = p[a] + (0.0, 0.0, -length)
        desc += ', arms down'
    return p, desc


def calibration_stream(sensor: SensorModel, clip, pose: str = 'tpose', seed: int = 0,
                       seconds: float = CALIBRATION_SECONDS, cmu_dir=None,
                       start_ns: int = 0) -> KinectStream:
    """``seconds`` of the clip's user standing still in :func:`calibration_pose`, through the
    sensor model's 'clean' path (same placement and noise model as the clip's stream). It is the
    same session as ``sensor.corrupt(clip, 'clean', seed)``: the same systematic joint-centre
    offsets, with independent jitter and drift. Stamps end one frame before ``start_ns``."""
    pos, desc = calibration_pose(clip, pose, cmu_dir)
    fps = sensor.fps
    n = max(1, int(round(float(seconds) * fps)))
    quats = np.zeros((n, NUM_JOINTS, 4))
    quats[..., 3] = 1.0
    cal = MotionClip(name=str(getattr(clip, 'name', '')), motion_class='calibration', fps=fps,
                     positions=np.repeat(pos[None], n, axis=0), orientations=quats,
                     source=desc)
    cs = sensor.corrupt(cal, 'clean', seed, seed_tag=f'clean/calibration/{pose}',
                        sys_offset=sensor.session_offsets(clip, 'clean', seed))
    stamps = start_ns - np.round(np.arange(n, 0, -1) * 1e9 / fps).astype(np.int64)
    return replace(cs, stamps_ns=stamps, clip_name=f'{cal.name} ({desc})')


def calibration_frames(stream: KinectStream) -> List[SkeletonFrame]:
    """A calibration stream as frames with every joint TRACKED and reliability 1."""
    frames = []
    for f in stream_frames(stream):
        f.tracking_state[:] = TRACKED
        f.reliability = np.ones(NUM_JOINTS, np.float32)
        frames.append(f)
    return frames


def table3(methods, clips, seed: int = 0, max_frames: Optional[int] = None, sensor_params=None,
           data_source: str = '', subsets=tuple(TABLE3_SUBSETS), progress=None,
           repeats: int = 1, reference: str = 'input', calibration: str = 'tpose',
           calibration_seconds: float = CALIBRATION_SECONDS, cmu_dir=None) -> Dict:
    """Shum 2013 Table III: each method given only a subset of joints of a noise-only ('clean')
    stream. ``reference='input'`` (the paper's choice) scores against the full input skeleton,
    ``'truth'`` against the true motion. Results keyed by subset letter instead of scenario.

    ``calibration``: 'tpose' / 'standing' — before each clip's subset frames the method sees
    ``calibration_seconds`` of the same user in that pose with every joint tracked
    (:func:`calibration_stream`, not scored; the subset frames are the same as without it), as
    a user calibrated at the start of a session (the paper's protocol); 'none' — no calibration,
    the other joints are hidden from the first frame."""
    if reference not in ('input', 'truth'):
        raise ValueError("reference must be 'input' or 'truth'")
    if calibration not in CALIBRATIONS:
        raise ValueError(f'calibration must be one of {CALIBRATIONS}, got {calibration!r}')
    if calibration != 'none' and not float(calibration_seconds) > 0:
        raise ValueError('calibration_seconds must be > 0')
    sensor = SensorModel(sensor_params, seed=seed)
    base = make_streams(clips, ('clean',), seed, max_frames, sensor, repeats)['clean']
    if reference == 'input':
        base = [replace(s, truth=s.positions.copy()) for s in base]
    warmup = None
    cal_meta: Dict = {'pose': calibration, 'seconds': 0.0, 'frames': 0, 'scored': False}
    if calibration != 'none':
        # the same order as make_streams: repeats outer, clips inner
        pairs = [(c, seed + r) for r in range(max(1, int(repeats))) for c in clips]
        cal_streams = [calibration_stream(sensor, c, calibration, sd, calibration_seconds,
                                          cmu_dir, int(s.stamps_ns[0]))
                       for s, (c, sd) in zip(base, pairs)]
        cal = {id(s): calibration_frames(cs) for s, cs in zip(base, cal_streams)}
        cal_meta.update(seconds=float(calibration_seconds),
                        frames=len(cal_streams[0]) if cal_streams else 0,
                        sources=sorted({cs.clip_name for cs in cal_streams}))

        def warmup(s, cal=cal):
            return [f.copy() for f in cal[id(s)]]
    results: Dict = {}
    params: Dict = {}
    for key in subsets:
        label, joints = TABLE3_SUBSETS[key]
        r = evaluate_streams(methods, {key: base},
                             frame_transform=lambda s, j=joints: subset_frames(s, j),
                             progress=progress, warmup=warmup)
        params.update(r['method_params'])
        for m, v in r['results'].items():
            results.setdefault(m, {})[key] = v[key]
    return {'experiment': 'table3', 'results': results, 'method_params': params,
            'reference': reference, 'calibration': cal_meta,
            'subsets': {k: {'parts': TABLE3_SUBSETS[k][0],
                            'joints': [JOINT_NAMES[j] for j in TABLE3_SUBSETS[k][1]]}
                        for k in subsets},
            'meta': run_meta(clips, seed, sensor, max_frames, data_source,
                             {'scenarios': ['clean'], 'calibration': cal_meta})}
