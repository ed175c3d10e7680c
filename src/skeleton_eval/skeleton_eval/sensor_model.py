"""A Kinect v1 skeleton sensor model: turns clean mocap into Kinect-like skeleton streams.

The model (parameters and the published values behind them: ``config/sensor_model.yaml``; the same
numbers are embedded here as :data:`DEFAULT_PARAMS` so it runs without the file):

1. *Placement* — the clip is resampled to 30 Hz, centred ``distance_m`` in front of the sensor and
   turned to face it; output is in the sensor frame (REP-103: x forward out of the sensor, y left,
   z up; the floor at ``z = -sensor_height_m``).
2. *Noise* — per joint: a fast AR(1) jitter (lateral ``base_mm`` + depth term ``k Z^2`` after
   Khoshelham & Elberink 2012), a slow AR(1) drift (frame-to-frame bone-length changes) and a
   per-session systematic joint-centre offset carried in the body frame.
3. *Occlusion* — geometric: a joint whose line of sight is blocked by a body capsule or the
   scenario's object is INFERRED at its last reported position; random episodes: the distal joints
   of a limb are INFERRED (frozen or collapsed onto the body) or NOT_TRACKED.
4. *False positives* — a joint latches onto a nearby external point and vibrates there while the
   SDK still reports it TRACKED (random onsets; in class c also when a hand comes near the object).
5. *Turning away* — smooth yaw excursions of the user; past ``degrade_deg`` the far limbs are
   INFERRED and jitter grows, past ``confusion_deg`` left and right are swapped.

Offline: :meth:`SensorModel.corrupt` -> :class:`KinectStream`; live:
:meth:`SensorModel.stream` yields ``(positions, tracking_state, truth)`` frame by frame. Both run the
same per-frame state machine, so they have the same statistics. A clip is any object with ``name``,
``fps`` and ``positions`` (T, 20, 3) in a world frame (REP-103, floor at z = 0), e.g.
``skeleton_data.mocap.MotionClip``.
"""
from __future__ import annotations

import copy
import os
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Sequence, Tuple, Union

import numpy as np

from skeleton_core.geometry import facing_yaw, yaw_matrix
from skeleton_core.model import forward_kinematics, parent_relative
from skeleton_core.model import (CHILDREN, FOOT_LEFT, FOOT_RIGHT, HAND_LEFT, HAND_RIGHT, HIP_CENTER,
                                 HIP_LEFT, HIP_RIGHT, INFERRED, JOINT_INDEX,
                                 JOINT_NAMES, LIMB_JOINTS, MIRROR, NOT_TRACKED, NUM_JOINTS, PARENTS,
                                 SEGMENT_CHILDREN, SEGMENT_CHILD_INDEX, SEGMENT_PARENTS,
                                 SEGMENT_PARENT_INDEX, SHOULDER_LEFT, SHOULDER_RIGHT, SPINE,
                                 TRACKED, estimate_height, segment_lengths, standard_body)
from skeleton_core.model import SEGMENT_NAMES

SCENARIOS = ('clean', 'a', 'b', 'c', 'd', 'e')
CONFIDENT_FAILURES = ('hand_snap', 'limb_swap', 'foot_slide', 'person_jump')

# Joint -> group used by the per-group noise tables
JOINT_GROUP: Tuple[str, ...] = tuple(
    'torso' if n in ('HipCenter', 'Spine', 'ShoulderCenter') else
    'head' if n == 'Head' else
    n.replace('Left', '').replace('Right', '').lower()
    for n in JOINT_NAMES)
GROUPS = ('torso', 'head', 'shoulder', 'elbow', 'wrist', 'hand', 'hip', 'knee', 'ankle', 'foot')
LIMBS = ('left_arm', 'right_arm', 'left_leg', 'right_leg')

_GROUP_TABLE = dict(torso=3.0, head=3.0, shoulder=4.0, elbow=6.0, wrist=8.0, hand=10.0, hip=4.0,
                    knee=6.0, ankle=8.0, foot=10.0)
DEFAULT_PARAMS: Dict = {
    'fps': 30.0,
    'placement': {'distance_m': 2.5, 'sensor_height_m': 0.8, 'lateral_offset_m': 0.0,
                  'face_sensor': True, 'min_range_m': 0.8, 'max_range_m': 4.0,
                  'horizontal_fov_deg': 57.0, 'vertical_fov_deg': 43.0, 'max_travel_m': 1.5,
                  'travel_window_s': 2.0, 'keep_facing': True},
    'jitter': {'depth_coeff_mm': 1.6, 'rho': 0.3, 'base_mm': dict(_GROUP_TABLE)},
    'slow_drift': {'rho': 0.95, 'sigma_mm': dict(torso=3.5, head=5.0, shoulder=8.0, elbow=10.0,
                                                 wrist=12.0, hand=14.0, hip=3.0, knee=10.0,
                                                 ankle=12.0, foot=14.0)},
    'systematic': {'sigma_mm': dict(torso=19.0, head=14.0, shoulder=33.0, elbow=32.0, wrist=23.0,
                                    hand=25.0, hip=26.0, knee=32.0, ankle=28.0, foot=42.0)},
    'occlusion_geometry': {'radius_scale': 0.8, 'hold_noise_mm': 15.0},
    'episodes': {'duration_s': [0.3, 2.0], 'collapse_frames': 4, 'elbow_knee_probability': 0.5},
    'false_positive': {'duration_s': [0.3, 1.5], 'offset_m': [0.1, 0.35], 'vibration_mm': 30.0,
                       'parent_probability': 0.5, 'proximity_m': 0.15, 'proximity_per_s': 1.0},
    'turn': {'duration_s': [2.0, 5.0], 'peak_deg': [40.0, 160.0], 'degrade_deg': 65.0,
             'confusion_deg': 120.0, 'hysteresis_deg': 10.0, 'jitter_gain': 2.0},
    'confident_failure': {
        'hand_snap': {'enabled': True, 'duration_s': [0.3, 1.5], 'surface_reach_m': 0.4,
                      'other_hand_m': 0.5, 'surface_offset_m': [0.15, 0.35],
                      'wrist_probability': 0.5},
        'limb_swap': {'enabled': True, 'side_on_deg': 45.0, 'duration_s': [0.3, 1.5],
                      'legs_probability': 0.5},
        'foot_slide': {'enabled': True, 'duration_s': [0.5, 2.0], 'speed_m_s': [0.1, 0.4],
                       'sink_m': [0.0, 0.15], 'ankle_probability': 0.5},
        'person_jump': {'enabled': True, 'duration_frames': [2, 8], 'distance_m': [0.6, 1.5]},
    },
    'tracked_error': {'enabled': True, 'duration_s': [1.0, 5.0], 'offset_m': [0.05, 0.15],
                      'ramp_s': 0.5, 'rest_probability': 0.5, 'neighbour_fraction': [0.3, 0.7],
                      'vibration_mm': 4.0,
                      'joints': ['HandLeft', 'HandRight', 'WristLeft', 'WristRight', 'ElbowLeft',
                                 'ElbowRight', 'KneeLeft', 'KneeRight', 'AnkleLeft', 'AnkleRight',
                                 'FootLeft', 'FootRight', 'ShoulderLeft', 'ShoulderRight']},
    'scenarios': {
        'clean': {'description': 'sensor noise only (no occlusion, false positives or turning)',
                  'self_occlusion': False, 'occlusion_per_min': 0.0,
                  'false_positive_per_min': 0.0, 'turn_per_min': 0.0,
                  'limb_weights': [1, 1, 1, 1], 'not_tracked_fraction': 0.0,
                  'collapse_fraction': 0.0, 'fp_joints': ['HandLeft', 'HandRight'],
                  'object': None},
        'a': {'description': 'self-occluded and unoccluded movement, open space',
              'self_occlusion': True, 'occlusion_per_min': 2.0, 'false_positive_per_min': 0.5,
              'turn_per_min': 0.5, 'limb_weights': [1, 1, 0.5, 0.5],
              'not_tracked_fraction': 0.2, 'collapse_fraction': 0.5,
              'fp_joints': ['HandLeft', 'HandRight', 'FootLeft', 'FootRight'], 'object': None},
        'b': {'description': 'occluded by environment objects (desk/box between the user and the '
                             'sensor)',
              'self_occlusion': True, 'occlusion_per_min': 3.0, 'false_positive_per_min': 1.5,
              'turn_per_min': 0.5, 'limb_weights': [0.5, 0.5, 1, 1],
              'not_tracked_fraction': 0.3, 'collapse_fraction': 0.5,
              'fp_joints': ['HandLeft', 'HandRight', 'FootLeft', 'FootRight', 'KneeLeft',
                            'KneeRight'],
              'object': {'gap_m': [0.6, 1.2], 'depth_m': 0.4, 'width_m': [0.5, 1.0],
                         'top_m': [0.5, 0.9], 'lateral_m': [-0.3, 0.3], 'proximity_fp': False}},
        'c': {'description': 'interacting with and occluded by objects (box/table within reach)',
              'self_occlusion': True, 'occlusion_per_min': 4.0, 'false_positive_per_min': 3.0,
              'turn_per_min': 0.5, 'limb_weights': [1, 1, 0.5, 0.5],
              'not_tracked_fraction': 0.3, 'collapse_fraction': 0.5,
              'fp_joints': ['HandLeft', 'HandRight', 'WristLeft', 'WristRight'],
              'object': {'gap_m': [0.35, 0.55], 'depth_m': 0.4, 'width_m': [0.5, 0.8],
                         'top_m': [0.8, 1.05], 'lateral_m': [-0.3, 0.3], 'proximity_fp': True}},
        'd': {'description': 'confident failures: joints reported TRACKED at a wrong place '
                             '(hand snaps, left/right limb swaps, foot slides, jumps to another '
                             'person), beside a table',
              'self_occlusion': True, 'occlusion_per_min': 2.0, 'false_positive_per_min': 0.5,
              'turn_per_min': 4.0, 'limb_weights': [1, 1, 0.5, 0.5],
              'not_tracked_fraction': 0.2, 'collapse_fraction': 0.5,
              'fp_joints': ['HandLeft', 'HandRight', 'FootLeft', 'FootRight'],
              'hand_snap_per_min': 10.0, 'limb_swap_per_min': 30.0, 'foot_slide_per_min': 6.0,
              'person_jump_per_min': 4.0,
              'object': {'gap_m': [0.0, 0.2], 'depth_m': 0.4, 'width_m': [0.4, 0.6],
                         'top_m': [0.7, 0.9], 'lateral_m': [0.45, 0.7], 'proximity_fp': False}},
        'e': {'description': 'small persistent errors of TRACKED joints (a hand resting on an '
                             'object, a joint centre drifting; the neighbouring joint pulled '
                             'partway), beside a table',
              'self_occlusion': True, 'occlusion_per_min': 2.0, 'false_positive_per_min': 0.5,
              'turn_per_min': 0.5, 'limb_weights': [1, 1, 0.5, 0.5],
              'not_tracked_fraction': 0.2, 'collapse_fraction': 0.5,
              'fp_joints': ['HandLeft', 'HandRight', 'FootLeft', 'FootRight'],
              'tracked_error_per_min': 8.0,
              'object': {'gap_m': [0.2, 0.4], 'depth_m': 0.4, 'width_m': [0.5, 0.8],
                         'top_m': [0.7, 0.95], 'lateral_m': [-0.3, 0.3], 'proximity_fp': False}},
    },
}


def default_yaml_path() -> Optional[Path]:
    """``config/sensor_model.yaml`` of the source tree, if it can be found (else None)."""
    env = os.environ.get('KP_SENSOR_MODEL')
    if env and Path(env).is_file():
        return Path(env)
    here = Path(__file__).resolve()
    for parent in here.parents:
        cand = parent / 'config' / 'sensor_model.yaml'
        if cand.is_file():
            return cand
    return None


def _merge(base: Dict, over: Dict) -> Dict:
    out = copy.deepcopy(base)
    for k, v in (over or {}).items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def load_params(params: Union[None, str, Path, Dict] = None) -> Dict:
    """Parameters: None = the YAML in config/ when present, else :data:`DEFAULT_PARAMS`;
    a path = that YAML file (merged over the defaults); a dict = overrides of the defaults."""
    if params is None:
        path = default_yaml_path()
        if path is None:
            return copy.deepcopy(DEFAULT_PARAMS)
        params = path
    if isinstance(params, (str, Path)):
        import yaml
        with open(params) as f:
            data = yaml.safe_load(f) or {}
        if '/**' in data:  # tolerate a ROS-style wrapper
            data = data['/**'].get('ros__parameters', {})
        return _merge(DEFAULT_PARAMS, data)
    if isinstance(params, dict):
        return _merge(DEFAULT_PARAMS, params)
    raise TypeError(f'params must be None, a YAML path or a dict, got {type(params).__name__}')


@dataclass
class KinectStream:
    """A corrupted clip in the sensor frame."""

    positions: np.ndarray       # (T, 20, 3) what the Kinect reports
    tracking_state: np.ndarray  # (T, 20) uint8
    truth: np.ndarray           # (T, 20, 3) the true joints, same frame
    stamps_ns: np.ndarray       # (T,) int64
    events: List[Dict]          # onset records: type, cause, frame, joints, duration
    scenario: str
    seed: int
    clean: np.ndarray = field(default=None)  # (T, 20) bool: joint unaffected by any event
    clip_name: str = ''
    fps: float = 30.0

    def __len__(self) -> int:
        return len(self.positions)


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def resample(positions: np.ndarray, fps_in: float, fps_out: float) -> np.ndarray:
    """Linear resampling of (T, 20, 3) positions from ``fps_in`` to ``fps_out``."""
    p = np.asarray(positions, float)
    if abs(fps_in - fps_out) < 1e-9 or len(p) < 2:
        return p.copy()
    t_in = np.arange(len(p)) / fps_in
    t_out = np.arange(0.0, t_in[-1] + 1e-9, 1.0 / fps_out)
    flat = p.reshape(len(p), -1)
    out = np.empty((len(t_out), flat.shape[1]))
    for k in range(flat.shape[1]):
        out[:, k] = np.interp(t_out, t_in, flat[:, k])
    return out.reshape(len(t_out), NUM_JOINTS, 3)


def _group_array(table: Dict[str, float]) -> np.ndarray:
    return np.array([float(table[g]) for g in JOINT_GROUP])


LOOP_BLEND_FRAMES = 15  # 0.5 s at 30 Hz: a looping clip ends in its first posture (stream())


def loop_blend(pos: np.ndarray, frames: int = LOOP_BLEND_FRAMES) -> np.ndarray:
    """(T, 20, 3) ``pos`` whose last ``frames`` (at most a third of the clip) turn smoothly
    into its first posture: the root moves linearly, every segment's direction is blended
    (normalised) with the same smooth-step weight at its own length, so a clip played in a loop
    has no teleport at the loop point and keeps its bone lengths."""
    p = np.array(pos, float)
    T = len(p)
    B = min(int(frames), T // 3)
    if B < 2:
        return p
    rel = parent_relative(p)
    u0 = rel[0, 1:] / np.maximum(np.linalg.norm(rel[0, 1:], axis=-1, keepdims=True), 1e-9)
    for k in range(B):
        i = T - B + k
        x = (k + 1) / (B + 1)
        w = x * x * (3 - 2 * x)
        seg = rel[i, 1:]
        L = np.linalg.norm(seg, axis=-1, keepdims=True)
        u = (1 - w) * seg / np.maximum(L, 1e-9) + w * u0
        u *= L / np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-9)
        root = (1 - w) * p[i, HIP_CENTER] + w * p[0, HIP_CENTER]
        r = rel[i].copy()
        r[1:] = u
        p[i] = forward_kinematics(r, root)
    return p


def _point_segment_2d(p, a, b):
    """Distance and parameter of 2-D points p (J,2) to segments a-b (S,2) -> (J,S)."""
    ab = b - a                                     # (S,2)
    ap = p[:, None, :] - a[None, :, :]             # (J,S,2)
    den = np.maximum((ab * ab).sum(-1), 1e-12)     # (S,)
    t = np.clip((ap * ab[None]).sum(-1) / den[None], 0.0, 1.0)
    d = np.linalg.norm(ap - t[..., None] * ab[None], axis=-1)
    return d, t


def _ray_box(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Does the segment from the sensor origin to each point (J,3) pass through the box?"""
    p = np.asarray(points, float)
    with np.errstate(divide='ignore', invalid='ignore'):
        inv = 1.0 / p
        t1 = lo[None] * inv
        t2 = hi[None] * inv
    tmin = np.nanmax(np.where(np.isfinite(np.minimum(t1, t2)), np.minimum(t1, t2), -np.inf), axis=1)
    tmax = np.nanmin(np.where(np.isfinite(np.maximum(t1, t2)), np.maximum(t1, t2), np.inf), axis=1)
    return (tmax >= np.maximum(tmin, 0.0)) & (tmin < 1.0)


def _box_distance(points: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    closest = np.clip(points, lo[None], hi[None])
    return np.linalg.norm(points - closest, axis=1), closest


def _occludable() -> np.ndarray:
    """(20, 19) mask: a joint is never hidden by a segment touching it or its tree neighbours."""
    m = np.ones((NUM_JOINTS, len(SEGMENT_CHILDREN)), bool)
    for j in range(NUM_JOINTS):
        near = {j, PARENTS[j], *CHILDREN[j]}
        for s in range(len(SEGMENT_CHILDREN)):
            if SEGMENT_CHILDREN[s] in near or SEGMENT_PARENTS[s] in near:
                m[j, s] = False
    return m


_OCCLUDABLE = _occludable()


def _shifted(positions: np.ndarray, frames: float) -> np.ndarray:
    """(T, J, 3) positions at frame times ``i + frames`` (linear; the ends held)."""
    t = np.clip(np.arange(len(positions)) + frames, 0, len(positions) - 1)
    i0 = np.floor(t).astype(int)
    i1 = np.minimum(i0 + 1, len(positions) - 1)
    w = (t - i0)[:, None, None]
    return positions[i0] * (1 - w) + positions[i1] * w


class _Corrupter:
    """Per-frame state machine shared by :meth:`SensorModel.corrupt` and :meth:`SensorModel.stream`."""

    def __init__(self, model: 'SensorModel', clip, scenario: str, seed: int, view=None,
                 time_shift_s: float = 0.0):
        if scenario not in model.params['scenarios']:
            raise ValueError(f'unknown scenario {scenario!r}; '
                             f'known: {sorted(model.params["scenarios"])}')
        self.p = model.params
        self.sc = self.p['scenarios'][scenario]
        self.scenario = scenario
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.turns_drawn = False   # several views: the turns are drawn ahead, in the truth
        self.fps = float(self.p['fps'])
        self.truth_all = model.place(clip)
        self.height = float(self.p['placement']['sensor_height_m'])
        if view is not None:
            # one of several sensors (see SensorModel.stream): the same people (and the same
            # turns, drawn from the stream's own seed) seen from this sensor, with its own noise,
            # occlusion and failures (drawn from a seed of the view)
            tag = zlib.crc32(' '.join(f'{v:.6f}' for v in view.xyz_ypr()).encode())
            self.rng = np.random.default_rng((seed * 1_000_003 + tag + 1) % (2 ** 31))
            self.truth_all = self._turned(self.truth_all, np.random.default_rng(seed))
            if time_shift_s:
                self.truth_all = _shifted(self.truth_all, float(time_shift_s) * self.fps)
            ref_truth = self.truth_all
            self.truth_all = view.inverse().apply(self.truth_all)
            self.height += float(view.translation[2])
        self.T = len(self.truth_all)
        rng = self.rng
        # body size for the capsules
        self.body = standard_body(float(np.clip(estimate_height(self.truth_all[0]), 1.0, 2.4)))
        self.radii = self.body.segment_radii * float(self.p['occlusion_geometry']['radius_scale'])
        # noise tables
        self.base = _group_array(self.p['jitter']['base_mm']) * 1e-3
        self.slow_sigma = _group_array(self.p['slow_drift']['sigma_mm']) * 1e-3
        self.sys_sigma = _group_array(self.p['systematic']['sigma_mm']) * 1e-3
        self.sys_offset = rng.standard_normal((NUM_JOINTS, 3)) * self.sys_sigma[:, None]
        self.e_fast = np.zeros((NUM_JOINTS, 3))
        self.e_slow = rng.standard_normal((NUM_JOINTS, 3)) * self.slow_sigma[:, None]
        self.first = True
        # object for classes b/c
        self.box = None
        obj = self.sc.get('object')
        if obj:
            # one object in the room: placed between the user and the *reference* sensor (drawn
            # from the stream's seed, so every view has the same one) and seen by each view from
            # its own place. Its box in a view's frame: the bounds of its corners there (exact for
            # views turned by multiples of 90 deg about z, the evaluation's front + side)
            orng = rng if view is None else np.random.default_rng(seed)
            ref = self.truth_all if view is None else ref_truth
            ref_height = float(self.p['placement']['sensor_height_m'])
            root = ref[:, HIP_CENTER]
            near_x = float(np.min(ref[..., 0]))
            gap = orng.uniform(*obj['gap_m'])
            width = orng.uniform(*obj['width_m'])
            top = orng.uniform(*obj['top_m']) - ref_height
            yc = float(np.median(root[:, 1])) + orng.uniform(*obj['lateral_m'])
            floor = -ref_height
            x1 = near_x - 0.02 if gap < 0.5 else near_x - gap + float(obj['depth_m'])
            x1 = min(x1, near_x - 0.02)
            x0 = x1 - float(obj['depth_m'])
            lo, hi = np.array([x0, yc - width / 2, floor]), np.array([x1, yc + width / 2, top])
            if view is not None:
                corners = np.array([[a[0], b[1], c[2]] for a in (lo, hi) for b in (lo, hi)
                                    for c in (lo, hi)])
                corners = view.inverse().apply(corners)
                lo, hi = corners.min(axis=0), corners.max(axis=0)
            self.box = (lo, hi)
            self.proximity_fp = bool(obj.get('proximity_fp', False))
        else:
            self.proximity_fp = False
        # dynamic state
        self.last = None               # last reported positions
        self.hold = None               # last position reported while TRACKED
        self.occ = None                # active random occlusion episode
        self.fps_eps: List[Dict] = []  # active false positives
        self.turn = None               # active turn episode
        self.mirrored = False
        self.cf: Dict[str, Optional[Dict]] = {k: None for k in CONFIDENT_FAILURES}
        self.te: Optional[Dict] = None  # active small tracked error (class e)
        self.floor = -self.height
        self.events: List[Dict] = list(getattr(self, 'turn_events', []))
        self.frame_index = 0
        self.fp_joints = [JOINT_INDEX[n] for n in self.sc.get('fp_joints', [])]
        w = np.asarray(self.sc.get('limb_weights', [1, 1, 1, 1]), float)
        self.limb_p = w / w.sum() if w.sum() > 0 else np.full(4, 0.25)

    # -------------------------------------------------------------------------------------
    def _per_frame(self, rate_per_min: float) -> float:
        return float(rate_per_min) / 60.0 / self.fps

    def _duration(self, rng_pair) -> int:
        return max(1, int(round(self.rng.uniform(*rng_pair) * self.fps)))

    def _turn_step(self, truth: np.ndarray, rng, fi: int) -> np.ndarray:
        """The user turning away: maybe begin a turn episode, apply the current one's yaw."""
        p, sc = self.p, self.sc
        if self.turn is None and rng.random() < self._per_frame(sc.get('turn_per_min', 0.0)):
            n = max(1, int(round(rng.uniform(*p['turn']['duration_s']) * self.fps)))
            peak = np.deg2rad(rng.uniform(*p['turn']['peak_deg'])) * rng.choice([-1.0, 1.0])
            prof = peak * 0.5 * (1 - np.cos(2 * np.pi * (np.arange(n) + 1) / (n + 1)))
            self.turn = {'profile': prof, 'k': 0}
            self.events.append({'type': 'turn', 'cause': 'random', 'frame': fi, 'joints': [],
                                'duration': n, 'peak_deg': float(np.rad2deg(peak))})
        if self.turn is not None:
            yaw = self.turn['profile'][self.turn['k']]
            self.turn['k'] += 1
            if self.turn['k'] >= len(self.turn['profile']):
                self.turn = None
            root = truth[HIP_CENTER].copy()
            truth = (truth - root) @ yaw_matrix(yaw).T + root
        return truth

    def _turned(self, truth_all: np.ndarray, rng) -> np.ndarray:
        """Several views: every frame's turn drawn ahead from ``rng`` (the same for every view)."""
        self.events, self.turn = [], None
        out = np.stack([self._turn_step(t, rng, i) for i, t in enumerate(truth_all)])
        self.turn_events = self.events
        self.turns_drawn = True
        return out

    def step(self, i: int):
        """Process truth frame ``i`` (of the placed clip); returns (positions, state, truth, clean)."""
        rng, p, sc = self.rng, self.p, self.sc
        fi = self.frame_index
        truth = self.truth_all[i].copy()
        clean = np.ones(NUM_JOINTS, bool)

        # --- the user turning away (changes the truth) ------------------------------------
        if not self.turns_drawn:
            truth = self._turn_step(truth, rng, fi)
        body_yaw = float(facing_yaw(truth))
        to_sensor = float(np.arctan2(-truth[HIP_CENTER, 1], -truth[HIP_CENTER, 0]))
        rel = abs(float(_wrap(body_yaw - to_sensor)))
        rel_deg = np.rad2deg(rel)
        tp = p['turn']
        gain = 1.0
        if rel_deg > tp['degrade_deg']:
            ramp = min(1.0, (rel_deg - tp['degrade_deg']) / max(90.0 - tp['degrade_deg'], 1e-6))
            gain = 1.0 + (float(tp['jitter_gain']) - 1.0) * ramp
            clean[:] = False

        # --- noise ------------------------------------------------------------------------
        depth = np.maximum(truth[:, 0], 0.1)
        sig = np.repeat((self.base * gain)[:, None], 3, axis=1)
        sig[:, 0] = np.hypot(sig[:, 0], float(p['jitter']['depth_coeff_mm']) * 1e-3 * depth ** 2)
        rho = float(p['jitter']['rho'])
        rs = float(p['slow_drift']['rho'])
        if self.first:
            self.e_fast = rng.standard_normal((NUM_JOINTS, 3)) * sig
            self.first = False
        else:
            self.e_fast = rho * self.e_fast + np.sqrt(1 - rho ** 2) * sig * \
                rng.standard_normal((NUM_JOINTS, 3))
        self.e_slow = rs * self.e_slow + np.sqrt(1 - rs ** 2) * self.slow_sigma[:, None] * \
            rng.standard_normal((NUM_JOINTS, 3))
        pos = truth + self.sys_offset @ yaw_matrix(body_yaw).T + self.e_fast + self.e_slow
        state = np.full(NUM_JOINTS, TRACKED, np.uint8)
        if self.hold is None:
            self.hold = pos.copy()
            self.last = pos.copy()
        hold_noise = float(p['occlusion_geometry']['hold_noise_mm']) * 1e-3

        def make_inferred(mask, st=INFERRED):
            idx = np.flatnonzero(mask)
            if len(idx):
                pos[idx] = self.hold[idx] + rng.standard_normal((len(idx), 3)) * hold_noise / 3
                state[idx] = np.minimum(state[idx], st)
                clean[idx] = False

        # --- field of view and range -------------------------------------------------------
        pl = p['placement']
        hang = np.abs(np.arctan2(truth[:, 1], truth[:, 0]))
        vang = np.abs(np.arctan2(truth[:, 2], truth[:, 0]))
        out = ((truth[:, 0] < pl['min_range_m']) | (truth[:, 0] > pl['max_range_m']) |
               (hang > np.deg2rad(pl['horizontal_fov_deg']) / 2) |
               (vang > np.deg2rad(pl['vertical_fov_deg']) / 2))
        make_inferred(out, NOT_TRACKED)

        # --- geometric occlusion ------------------------------------------------------------
        occluded = np.zeros(NUM_JOINTS, bool)
        if sc.get('self_occlusion'):
            occluded |= self._self_occluded(truth)
        if self.box is not None:
            occluded |= _ray_box(truth, *self.box)
        # turned away: the far-side limbs are inferred
        if rel_deg > tp['degrade_deg']:
            left_far = (np.linalg.norm(truth[SHOULDER_LEFT]) > np.linalg.norm(truth[SHOULDER_RIGHT]))
            side = ('left' if left_far else 'right')
            for limb in (side + '_arm', side + '_leg'):
                occluded[list(LIMB_JOINTS[limb][1:])] = True
        make_inferred(occluded & ~out)

        # --- random occlusion episodes ------------------------------------------------------
        if self.occ is None and rng.random() < self._per_frame(sc.get('occlusion_per_min', 0.0)):
            limb = LIMBS[rng.choice(4, p=self.limb_p)]
            chain = LIMB_JOINTS[limb]  # shoulder/hip, elbow/knee, wrist/ankle, hand/foot
            joints = list(chain[2:])
            if rng.random() < float(p['episodes']['elbow_knee_probability']):
                joints = [chain[1]] + joints
            u = rng.random()
            ntf = float(sc.get('not_tracked_fraction', 0.0))
            mode = 'not_tracked' if u < ntf else (
                'collapse' if rng.random() < float(sc.get('collapse_fraction', 0.5)) else 'freeze')
            n = self._duration(p['episodes']['duration_s'])
            self.occ = {'joints': joints, 'mode': mode, 'left': n, 'k': 0, 'limb': limb,
                        'start': self.last[joints].copy()}
            self.events.append({'type': 'occlusion', 'cause': 'random', 'frame': fi,
                                'joints': joints, 'duration': n, 'mode': mode, 'limb': limb})
        if self.occ is not None:
            o = self.occ
            j = o['joints']
            if o['mode'] == 'not_tracked':
                pos[j] = self.hold[j]
                state[j] = NOT_TRACKED
            elif o['mode'] == 'freeze':
                pos[j] = o['start'] + rng.standard_normal((len(j), 3)) * hold_noise / 3
                state[j] = INFERRED
            else:  # collapse: arms fall onto the hip/spine side, legs straight under the hip
                target = self._collapse_targets(truth, o['limb'], j)
                a = min(1.0, (o['k'] + 1) / max(1, int(p['episodes']['collapse_frames'])))
                pos[j] = (1 - a) * o['start'] + a * target + \
                    rng.standard_normal((len(j), 3)) * hold_noise / 3
                state[j] = INFERRED
            clean[j] = False
            o['k'] += 1
            o['left'] -= 1
            if o['left'] <= 0:
                self.occ = None

        # --- false positives ----------------------------------------------------------------
        fpp = p['false_positive']
        active = {j for e in self.fps_eps for j in e['joints']}
        cands = [j for j in self.fp_joints if j not in active]
        onset = None
        if cands and rng.random() < self._per_frame(sc.get('false_positive_per_min', 0.0)):
            onset = ('random', int(rng.choice(cands)), None)
        elif cands and self.proximity_fp and self.box is not None:
            d, closest = _box_distance(truth[cands], *self.box)
            near = np.flatnonzero(d < float(fpp['proximity_m']))
            if len(near) and rng.random() < float(fpp['proximity_per_s']) / self.fps * len(near):
                k = int(rng.choice(near))
                onset = ('proximity', cands[k], closest[k])
        if onset is not None:
            cause, j, point = onset
            joints = [j]
            par = PARENTS[j]
            if (JOINT_GROUP[j] in ('hand', 'foot') and par not in active and
                    rng.random() < float(fpp['parent_probability'])):
                joints.append(par)
            if point is None:
                d = rng.standard_normal(3)
                d[2] *= 0.5
                d /= np.linalg.norm(d)
                point = truth[j] + d * rng.uniform(*fpp['offset_m'])
            n = self._duration(fpp['duration_s'])
            pts = np.array([point + (truth[k] - truth[j]) * 0.3 for k in joints])
            self.fps_eps.append({'joints': joints, 'points': pts, 'left': n})
            self.events.append({'type': 'false_positive', 'cause': cause, 'frame': fi,
                                'joints': joints, 'duration': n})
        vib = float(fpp['vibration_mm']) * 1e-3
        for e in self.fps_eps:
            j = e['joints']
            pos[j] = e['points'] + rng.standard_normal((len(j), 3)) * vib
            state[j] = TRACKED
            clean[j] = False
            e['left'] -= 1
        self.fps_eps = [e for e in self.fps_eps if e['left'] > 0]

        # --- left/right confusion when facing away ----------------------------------------
        h = tp['hysteresis_deg']
        if not self.mirrored and rel_deg > tp['confusion_deg']:
            self.mirrored = True
            self.events.append({'type': 'mirror', 'cause': 'turn', 'frame': fi, 'joints': [],
                                'duration': 0})
        elif self.mirrored and rel_deg < tp['confusion_deg'] - h:
            self.mirrored = False
        if self.mirrored:
            pos = pos[list(MIRROR)]
            state = state[list(MIRROR)]
            clean[:] = False

        # --- confident failures (class d): wrong places reported TRACKED ---------------------
        self._confident_failures(fi, i, truth, pos, state, clean, rel_deg)
        # --- small persistent errors of TRACKED joints (class e) -----------------------------
        self._tracked_error(fi, truth, pos, state, clean)

        tracked = state == TRACKED
        self.hold[tracked] = pos[tracked]
        self.last = pos.copy()
        self.frame_index += 1
        return pos, state, truth, clean

    def _confident_failures(self, fi, i, truth, pos, state, clean, rel_deg):
        """Class d (``confident_failure`` parameters; rates in the scenario, per minute; the limb
        swap's per minute of side-on time): every mode keeps the joints TRACKED.

        * hand_snap — a hand (with ``wrist_probability`` its wrist too) snaps to the nearest point
          of the scenario's object when within ``surface_reach_m``, else to the other hand when
          within ``other_hand_m`` (and follows it), else to a static surface point
          ``surface_offset_m`` away, and stays there with the ordinary sensor noise (no
          vibration, so the behaviour term of Eq. 1-4 does not see it);
        * limb_swap — while the user is turned at least ``side_on_deg`` from the sensor, the two
          arms (or, with ``legs_probability``, the two legs), girdle joints included, swap;
        * foot_slide — a foot (with ``ankle_probability`` its ankle too) slides along the floor at
          ``speed_m_s`` from where it was reported and sinks up to ``sink_m`` into it;
        * person_jump — for ``duration_frames`` the whole skeleton is another person: the clip's
          posture of another moment, turned and placed ``distance_m`` to the side."""
        cfp = self.p.get('confident_failure') or {}
        sc, rng = self.sc, self.rng

        def rate(mode):
            if not (cfp.get(mode) or {}).get('enabled', False):
                return 0.0
            return self._per_frame(sc.get(f'{mode}_per_min', 0.0))

        def begin(mode, joints, n, cause, **extra):
            self.events.append({'type': mode, 'cause': cause, 'frame': fi, 'joints': list(joints),
                                'duration': int(n), **extra})
            return {'joints': list(joints), 'left': int(n), 'k': 0, 'cause': cause, **extra}

        # hand snap
        hs = cfp.get('hand_snap') or {}
        if self.cf['hand_snap'] is None and self._onset(rate('hand_snap')):
            hand = HAND_LEFT if rng.random() < 0.5 else HAND_RIGHT
            other = HAND_RIGHT if hand == HAND_LEFT else HAND_LEFT
            joints = [hand] + ([PARENTS[hand]] if rng.random() < float(hs['wrist_probability'])
                               else [])
            n = self._duration(hs['duration_s'])
            target, cause = None, 'surface'
            if self.box is not None:
                d, closest = _box_distance(pos[[hand]], *self.box)
                if d[0] < float(hs['surface_reach_m']):
                    target, cause = closest[0], 'object'
            if target is None and np.linalg.norm(pos[other] - pos[hand]) < float(hs['other_hand_m']):
                cause = 'other_hand'
            elif target is None:
                d = rng.standard_normal(3)
                d[2] *= 0.5
                d /= np.linalg.norm(d)
                target = pos[hand] + d * rng.uniform(*hs['surface_offset_m'])
            rel = pos[joints] - pos[hand]
            self.cf['hand_snap'] = begin('hand_snap', joints, n, cause, other=int(other),
                                         target=target, rel=rel)
        e = self.cf['hand_snap']
        if e is not None:
            j = e['joints']
            hand = j[0]
            # the ordinary noise of the joint (its fast and slow error) rides on the wrong point
            noise = self.e_fast[j] + self.e_slow[j]
            if e['cause'] == 'other_hand':
                anchor = pos[e['other']] + 0.03 * np.array([0.0, 1.0 if hand == HAND_RIGHT else
                                                             -1.0, 0.0])
            else:
                anchor = e['target']
            pos[j] = anchor + e['rel'] + noise
            state[j] = TRACKED
            clean[j] = False
            self._tick('hand_snap')

        # left/right limb swap while side-on
        ls = cfp.get('limb_swap') or {}
        side_on = rel_deg >= float(ls.get('side_on_deg', 45.0))
        if self.cf['limb_swap'] is None and side_on and self._onset(rate('limb_swap')):
            legs = rng.random() < float(ls['legs_probability'])
            a, b = (('left_leg', 'right_leg') if legs else ('left_arm', 'right_arm'))
            joints = list(LIMB_JOINTS[a]) + list(LIMB_JOINTS[b])
            self.cf['limb_swap'] = begin('limb_swap', joints, self._duration(ls['duration_s']),
                                         'side_on', limbs='legs' if legs else 'arms')
        e = self.cf['limb_swap']
        if e is not None:
            j = e['joints']
            h = len(j) // 2
            sw = j[h:] + j[:h]
            pos[j] = pos[sw]
            state[j] = state[sw]
            clean[j] = False
            self._tick('limb_swap')

        # foot slide
        fs = cfp.get('foot_slide') or {}
        if self.cf['foot_slide'] is None and self._onset(rate('foot_slide')):
            foot = FOOT_LEFT if rng.random() < 0.5 else FOOT_RIGHT
            joints = [foot] + ([PARENTS[foot]] if rng.random() < float(fs['ankle_probability'])
                               else [])
            ang = rng.uniform(0, 2 * np.pi)
            vel = rng.uniform(*fs['speed_m_s']) / self.fps * np.array([np.cos(ang), np.sin(ang),
                                                                         0.0])
            self.cf['foot_slide'] = begin('foot_slide', joints, self._duration(fs['duration_s']),
                                          'random', start=pos[joints].copy(), vel=vel,
                                          sink=float(rng.uniform(*fs['sink_m'])))
        e = self.cf['foot_slide']
        if e is not None:
            j = e['joints']
            e['k'] += 1
            p_new = e['start'] + e['k'] * e['vel']
            sink = e['sink'] * min(1.0, e['k'] / 5.0)
            foot_z = self.floor - sink
            p_new[0, 2] = foot_z
            if len(j) > 1:
                p_new[1, 2] = min(p_new[1, 2], foot_z + 0.05)
            pos[j] = p_new + self.e_fast[j]
            state[j] = TRACKED
            clean[j] = False
            self._tick('foot_slide', count=False)

        # the whole skeleton jumps to another person
        pj = cfp.get('person_jump') or {}
        if self.cf['person_jump'] is None and self._onset(rate('person_jump')):
            lo, hi = (int(v) for v in pj['duration_frames'])
            n = int(rng.integers(lo, hi + 1))
            other = self.truth_all[int(rng.integers(0, self.T))]
            root = other[HIP_CENTER]
            yaw = rng.uniform(-np.pi, np.pi)
            shift = np.array([rng.uniform(-0.3, 0.3),
                              rng.choice([-1.0, 1.0]) * rng.uniform(*pj['distance_m']), 0.0])
            ghost = (other - root) @ yaw_matrix(yaw).T + root + shift
            ghost[:, 2] += truth[:, 2].min() - ghost[:, 2].min()
            self.cf['person_jump'] = begin('person_jump', range(NUM_JOINTS), n, 'random',
                                           ghost=ghost)
        e = self.cf['person_jump']
        if e is not None:
            pos[:] = e['ghost'] + self.e_fast + self.e_slow
            state[:] = TRACKED
            clean[:] = False
            self._tick('person_jump')

    def _tracked_error(self, fi, truth, pos, state, clean):
        """Class e (``tracked_error`` parameters, rate ``tracked_error_per_min`` in the
        scenario): a joint of ``joints`` that the sensor reports TRACKED sits 5-15 cm
        (``offset_m``) from its true centre for ``duration_s``, still TRACKED, with a little
        vibration (``vibration_mm``) and the ordinary noise; its parent joint (the neighbour the
        SDK's skeleton fit drags along) is pulled by ``neighbour_fraction`` of that offset. Two
        modes: with ``rest_probability`` *rest* (a hand or foot resting on an object: the joint is
        reported at a point fixed in the room, ``offset_m`` from where it was; the offset changes
        as the limb moves), else *drift* (a joint centre drifting: an offset of fixed direction
        and size carried with the joint). Both ramp in and out over ``ramp_s``. Unlike class d's
        snaps the errors are small (the length of a hand) and last seconds; unlike the false
        positives they do not vibrate, so the behaviour term of Eq. 1-4 cannot see them."""
        te = self.p.get('tracked_error') or {}
        rate = 0.0
        if te.get('enabled', False):
            rate = self._per_frame(self.sc.get('tracked_error_per_min', 0.0))
        rng = self.rng
        if self.te is None and self._onset(rate):
            cands = [JOINT_INDEX[n] for n in te['joints']]
            cands = [j for j in cands if state[j] == TRACKED and state[PARENTS[j]] == TRACKED]
            if cands:
                j = int(rng.choice(cands))
                n = self._duration(te['duration_s'])
                d = rng.standard_normal(3)
                d /= np.linalg.norm(d)
                size = float(rng.uniform(*te['offset_m']))
                rest = rng.random() < float(te['rest_probability'])
                frac = float(rng.uniform(*te['neighbour_fraction']))
                self.te = {'joint': j, 'parent': int(PARENTS[j]), 'left': n, 'n': n, 'k': 0,
                           'mode': 'rest' if rest else 'drift', 'frac': frac,
                           'offset': d * size, 'point': pos[j] + d * size}
                self.events.append({'type': 'tracked_error', 'cause': self.te['mode'],
                                    'frame': fi, 'joints': [j, int(PARENTS[j])], 'duration': n,
                                    'offset_m': size, 'neighbour_fraction': frac})
        e = self.te
        if e is None:
            return
        j, par = e['joint'], e['parent']
        ramp = max(1, int(round(float(te.get('ramp_s', 0.5)) * self.fps)))
        a = min(1.0, (e['k'] + 1) / ramp, e['left'] / ramp)
        if e['mode'] == 'rest':
            off = e['point'] - truth[j]
            size = np.linalg.norm(off)
            lo, hi = (float(v) for v in te['offset_m'])
            if size > hi:   # the limb moved away: the joint lets go of the point partway
                off *= hi / size
            elif size < lo:
                off = off * (lo / max(size, 1e-6)) if size > 1e-6 else e['offset']
        else:
            off = e['offset']
        vib = rng.standard_normal(3) * float(te.get('vibration_mm', 0.0)) * 1e-3
        if state[j] == TRACKED:
            pos[j] = pos[j] + a * off + vib
            clean[j] = False
        if state[par] == TRACKED:
            pos[par] = pos[par] + a * e['frac'] * off
            clean[par] = False
        e['k'] += 1
        e['left'] -= 1
        if e['left'] <= 0:
            self.te = None

    def _onset(self, p: float) -> bool:
        """A Bernoulli draw with probability ``p``; no draw at all when ``p`` is 0, so classes
        without confident failures keep the random sequence (and streams) they had before."""
        return p > 0.0 and self.rng.random() < p

    def _tick(self, mode, count=True):
        e = self.cf[mode]
        if count:
            e['k'] += 1
        e['left'] -= 1
        if e['left'] <= 0:
            self.cf[mode] = None

    def _collapse_targets(self, truth, limb, joints):
        """Where the SDK puts a collapsed limb: an arm folded onto the side of the trunk (joints
        spread from the spine down to the hip), a leg hanging straight under its hip (joints at
        their bone-length distances below it, not below the floor)."""
        if limb.endswith('arm'):
            hip = truth[HIP_LEFT if limb.startswith('left') else HIP_RIGHT]
            spine = truth[SPINE]
            a = (np.arange(len(joints)) + 1.0) / len(joints)
            return (1 - a)[:, None] * spine + a[:, None] * hip
        hip_j = HIP_LEFT if limb.startswith('left') else HIP_RIGHT
        hip = truth[hip_j]
        floor = float(truth[:, 2].min())
        bone = self.body.bone_lengths_by_joint()
        out = []
        for j in joints:
            drop, k = 0.0, j
            while k != hip_j and k > 0:
                drop += bone[k] if JOINT_GROUP[k] != 'foot' else 0.0
                k = PARENTS[k]
            out.append([hip[0], hip[1], max(hip[2] - drop, floor)])
        return np.array(out)

    def _self_occluded(self, truth: np.ndarray) -> np.ndarray:
        x = np.maximum(truth[:, 0], 1e-3)
        uv = truth[:, 1:] / x[:, None]
        a = uv[SEGMENT_PARENT_INDEX]
        b = uv[SEGMENT_CHILD_INDEX]
        d, t = _point_segment_2d(uv, a, b)                     # (20, 19)
        xa = truth[SEGMENT_PARENT_INDEX, 0]
        xb = truth[SEGMENT_CHILD_INDEX, 0]
        xs = xa[None] + t * (xb - xa)[None]                     # depth of the closest point
        rad = self.radii[None] / np.maximum(xs, 1e-3)           # angular radius
        occ = (d < rad) & (xs + self.radii[None] * 0.5 < x[:, None]) & _OCCLUDABLE
        return occ.any(axis=1)


class SensorModel:
    """Kinect v1 skeleton sensor model. ``params``: None (config/sensor_model.yaml or built-in
    defaults), a YAML path, or a dict of overrides. ``seed``: base seed of every stream."""

    def __init__(self, params: Union[None, str, Path, Dict] = None, seed: int = 0):
        self.params = load_params(params)
        self.seed = int(seed)
        self.fps = float(self.params['fps'])

    # ------------------------------------------------------------------------------------
    def place(self, clip) -> np.ndarray:
        """The clip's joints resampled to the sensor rate and put in front of the sensor (T,20,3)."""
        pos = np.asarray(clip.positions, float)
        pos = resample(pos, float(getattr(clip, 'fps', self.fps)), self.fps)
        pl = self.params['placement']
        ok = np.isfinite(pos).all(axis=(1, 2))
        if not ok.all():  # fill gaps in the input by holding the previous valid frame
            idx = np.maximum.accumulate(np.where(ok, np.arange(len(pos)), 0))
            pos = pos[idx]
        if pl.get('keep_facing', True) and len(pos) > 1:
            # the user keeps facing the screen: remove the slow part of the heading (moving average
            # of the unwrapped yaw over travel_window_s), turning each frame about its own root;
            # turning away is then modelled by the turn episodes at their configured rate
            w = max(1, int(round(float(pl.get('travel_window_s', 2.0)) * self.fps)))
            yaw = np.unwrap(facing_yaw(pos))
            padded = np.pad(yaw, (w // 2, w - 1 - w // 2), mode='edge')
            slow = np.convolve(padded, np.ones(w) / w, mode='valid')
            corr = -(slow - slow[0])
            c, sn = np.cos(corr), np.sin(corr)
            rot = np.zeros((len(pos), 3, 3))
            rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1] = c, -sn, sn, c
            rot[:, 2, 2] = 1.0
            r0 = pos[:, HIP_CENTER:HIP_CENTER + 1, :]
            pos = np.einsum('tij,tkj->tki', rot, pos - r0) + r0
        root = pos[:, HIP_CENTER, :2]
        travel = float(np.max(np.ptp(root, axis=0))) if len(root) else 0.0
        if travel > float(pl.get('max_travel_m', np.inf)):
            # treadmill: remove the slow part of the horizontal root path (moving average over
            # travel_window_s) so locomotion stays inside the play space
            w = max(1, int(round(float(pl.get('travel_window_s', 2.0)) * self.fps)))
            kernel = np.ones(w) / w
            padded = np.pad(root, ((w // 2, w - 1 - w // 2), (0, 0)), mode='edge')
            slow = np.stack([np.convolve(padded[:, k], kernel, mode='valid') for k in range(2)], 1)
            pos = pos.copy()
            pos[..., :2] -= (slow - slow.mean(axis=0))[:, None, :]
        centre = np.array([*np.mean(pos[:, HIP_CENTER, :2], axis=0), 0.0])
        pos = pos - centre
        if pl.get('face_sensor', True):
            yaws = facing_yaw(pos)
            mean_yaw = float(np.arctan2(np.mean(np.sin(yaws)), np.mean(np.cos(yaws))))
            # face -x (towards the sensor)
            pos = pos @ yaw_matrix(np.pi - mean_yaw).T
        pos = pos + np.array([float(pl['distance_m']), float(pl['lateral_offset_m']),
                              -float(pl['sensor_height_m'])])
        return pos

    def stream_seed(self, clip, scenario: str, seed: Optional[int] = None) -> int:
        base = self.seed if seed is None else int(seed)
        tag = f'{getattr(clip, "name", "")}/{scenario}'.encode()
        return (base * 1_000_003 + zlib.crc32(tag)) % (2 ** 31)

    def corrupt(self, clip, scenario: str = 'a', seed: Optional[int] = None,
                max_frames: Optional[int] = None, start_ns: int = 0,
                seed_tag: Optional[str] = None,
                sys_offset: Optional[np.ndarray] = None, view=None,
                time_shift_s: float = 0.0) -> KinectStream:
        """The whole clip through the sensor model (offline). ``seed_tag``: the stream's random
        seed from this tag instead of the scenario's name (another recording of the same user);
        ``sys_offset`` (20, 3): the systematic joint-centre offsets to use (e.g. those of
        :meth:`session_offsets`: the same sensor session) instead of drawing new ones; ``view``:
        see :meth:`stream`; ``time_shift_s`` (with a ``view``): this sensor captures that much
        later in the motion than the reference (an unsynchronised sensor's phase)."""
        s = self.stream_seed(clip, scenario if seed_tag is None else seed_tag, seed)
        if time_shift_s and view is None:
            raise ValueError('time_shift_s needs a view')
        c = _Corrupter(self, clip, scenario, s, view, time_shift_s)
        if sys_offset is not None:
            c.sys_offset = np.array(sys_offset, float).reshape(NUM_JOINTS, 3)
        n = c.T if max_frames is None else min(c.T, int(max_frames))
        pos = np.empty((n, NUM_JOINTS, 3))
        st = np.empty((n, NUM_JOINTS), np.uint8)
        tr = np.empty((n, NUM_JOINTS, 3))
        cl = np.empty((n, NUM_JOINTS), bool)
        for i in range(n):
            pos[i], st[i], tr[i], cl[i] = c.step(i)
        stamps = start_ns + np.round(np.arange(n) * 1e9 / self.fps).astype(np.int64)
        return KinectStream(positions=pos, tracking_state=st, truth=tr, stamps_ns=stamps,
                            events=c.events, scenario=scenario, seed=s, clean=cl,
                            clip_name=str(getattr(clip, 'name', '')), fps=self.fps)

    def session_offsets(self, clip, scenario: str = 'a', seed: Optional[int] = None) -> np.ndarray:
        """(20, 3) the systematic joint-centre offsets of ``corrupt(clip, scenario, seed)``."""
        return _Corrupter(self, clip, scenario,
                          self.stream_seed(clip, scenario, seed)).sys_offset.copy()

    def stream(self, clip, scenario: str = 'a', loop: bool = True, seed: Optional[int] = None,
               view=None) -> Iterator[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Live: yields ``(positions, tracking_state, truth)`` per frame (forever if ``loop``;
        then the clip's last :data:`LOOP_BLEND_FRAMES` turn into its first posture,
        :func:`loop_blend`: no teleport at the loop point).

        ``view`` (a :class:`skeleton_core.tf.Transform`, None = the one sensor): several sensors
        watching the same people. The clip is placed for the *reference* sensor (``placement``)
        and ``view`` is this sensor's pose in the reference sensor's frame; the output is in this
        sensor's frame. Every view of one clip, scenario and seed shares the motion and the
        user's turns; noise, offsets, occlusion (line of sight from this sensor; the scenario's
        object between the user and this sensor) and failures are drawn per view. The sensors
        are assumed level (the floor at ``-(sensor_height_m + view z)``)."""
        c = _Corrupter(self, clip, scenario, self.stream_seed(clip, scenario, seed), view)
        if loop:
            c.truth_all = loop_blend(c.truth_all)
        while True:
            for i in range(c.T):
                pos, st, tr, _ = c.step(i)
                yield pos, st, tr
            if not loop:
                return

    # ------------------------------------------------------------------------------------
    def expected_jitter_mm(self, depth_m: Union[float, np.ndarray]) -> np.ndarray:
        """Model std (mm, RMS over the 3 axes) of the random error (fast + slow) per joint at a depth."""
        base = _group_array(self.params['jitter']['base_mm'])
        slow = _group_array(self.params['slow_drift']['sigma_mm'])
        dz = float(self.params['jitter']['depth_coeff_mm']) * np.asarray(depth_m, float) ** 2
        var = (3 * base ** 2 + dz ** 2) / 3 + slow ** 2
        return np.sqrt(var)


def statistics(streams: Sequence[KinectStream]) -> Dict:
    """Noise statistics of corrupted streams, for the report and the calibration test.

    * ``jitter_mm`` (20,): std of the random error (reported - truth, less its per-stream mean, i.e.
      less the systematic offset), RMS over axes, on clean frames only;
    * ``offset_mm`` (20,): RMS of the per-stream mean error (the systematic joint-centre offsets);
    * ``bone_length_std_mm`` (19,): std over time of each segment length on clean frames;
    * ``occluded_fraction``: per scenario, the fraction of joint-frames not TRACKED, and per joint
      group; ``false_positive_fraction``: per scenario, joint-frames latched but TRACKED;
    * ``events_per_min``: per scenario and event type/cause.
    """
    streams = list(streams)
    res_sq = np.zeros(NUM_JOINTS)
    res_n = np.zeros(NUM_JOINTS)
    off_sq = np.zeros(NUM_JOINTS)
    off_n = np.zeros(NUM_JOINTS)
    bl_var = np.zeros(len(SEGMENT_CHILDREN))
    bl_n = np.zeros(len(SEGMENT_CHILDREN))
    per_sc: Dict[str, Dict] = {}
    depth = []
    for s in streams:
        err = s.positions - s.truth
        cl = s.clean if s.clean is not None else np.ones(s.tracking_state.shape, bool)
        for j in range(NUM_JOINTS):
            e = err[cl[:, j], j]
            if len(e) >= 3:
                mu = e.mean(axis=0)
                res_sq[j] += ((e - mu) ** 2).sum() / 3
                res_n[j] += len(e) - 1
                off_sq[j] += (mu ** 2).sum() / 3
                off_n[j] += 1
        depth.append(s.truth[..., 0][cl])
        lengths = segment_lengths(s.positions)
        for k, (a, b) in enumerate(zip(SEGMENT_PARENTS, SEGMENT_CHILDREN)):
            m = cl[:, a] & cl[:, b]
            if m.sum() >= 3:
                bl_var[k] += lengths[m, k].var() * (m.sum() - 1)
                bl_n[k] += m.sum() - 1
        d = per_sc.setdefault(s.scenario, {'frames': 0, 'not_tracked': 0, 'inferred': 0,
                                           'joint_frames': 0, 'events': {}, 'group_nt': {},
                                           'fp_frames': 0})
        T = len(s)
        d['frames'] += T
        d['joint_frames'] += T * NUM_JOINTS
        d['not_tracked'] += int((s.tracking_state == NOT_TRACKED).sum())
        d['inferred'] += int((s.tracking_state == INFERRED).sum())
        for g in GROUPS:
            idx = [j for j in range(NUM_JOINTS) if JOINT_GROUP[j] == g]
            gd = d['group_nt'].setdefault(g, [0, 0])
            gd[0] += int((s.tracking_state[:, idx] != TRACKED).sum())
            gd[1] += T * len(idx)
        for e in s.events:
            key = f'{e["type"]}:{e["cause"]}'
            d['events'][key] = d['events'].get(key, 0) + 1
            if e['type'] == 'false_positive':
                d['fp_frames'] += e['duration'] * len(e['joints'])
    out = {
        'jitter_mm': (np.sqrt(res_sq / np.maximum(res_n, 1)) * 1e3).tolist(),
        'offset_mm': (np.sqrt(off_sq / np.maximum(off_n, 1)) * 1e3).tolist(),
        'bone_length_std_mm': (np.sqrt(bl_var / np.maximum(bl_n, 1)) * 1e3).tolist(),
        'mean_depth_m': float(np.concatenate(depth).mean()) if depth else float('nan'),
        'scenarios': {},
    }
    for sc, d in per_sc.items():
        minutes = d['frames'] / (streams[0].fps * 60.0)
        out['scenarios'][sc] = {
            'frames': d['frames'],
            'minutes': minutes,
            'not_tracked_fraction': d['not_tracked'] / d['joint_frames'],
            'inferred_fraction': d['inferred'] / d['joint_frames'],
            'occluded_fraction': (d['not_tracked'] + d['inferred']) / d['joint_frames'],
            'occluded_fraction_by_group': {g: v[0] / max(v[1], 1) for g, v in d['group_nt'].items()},
            'false_positive_fraction': d['fp_frames'] / d['joint_frames'],
            'events_per_min': {k: v / max(minutes, 1e-9) for k, v in sorted(d['events'].items())},
        }
    return out


def format_statistics(stats: Dict) -> str:
    """Markdown summary of :func:`statistics`."""
    lines = ['### Sensor model noise statistics', '',
             f'mean depth of clean joints: {stats["mean_depth_m"]:.2f} m', '',
             '| joint | jitter (mm) | systematic offset (mm) |', '|---|---:|---:|']
    for j, n in enumerate(JOINT_NAMES):
        lines.append(f'| {n} | {stats["jitter_mm"][j]:.1f} | {stats["offset_mm"][j]:.1f} |')
    lines += ['', '| segment | length std (mm) |', '|---|---:|']
    for k, n in enumerate(SEGMENT_NAMES):
        lines.append(f'| {n} | {stats["bone_length_std_mm"][k]:.1f} |')
    lines += ['', '| scenario | minutes | not tracked | inferred | false positive | events/min |',
              '|---|---:|---:|---:|---:|---|']
    for sc, d in stats['scenarios'].items():
        ev = ', '.join(f'{k} {v:.2f}' for k, v in d['events_per_min'].items())
        lines.append(f'| {sc} | {d["minutes"]:.2f} | {100 * d["not_tracked_fraction"]:.1f}% | '
                     f'{100 * d["inferred_fraction"]:.1f}% | '
                     f'{100 * d["false_positive_fraction"]:.1f}% | {ev} |')
    return '\n'.join(lines)
