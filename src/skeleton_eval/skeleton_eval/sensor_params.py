"""The sensor model's parameters: the built-in defaults (:data:`DEFAULT_PARAMS`, the same numbers
as ``config/sensor_model.yaml``, so the model runs without the file), loading and merging a YAML
file or overrides (:func:`load_params`), the scenario classes and the joint groups of the
per-group noise tables."""
from __future__ import annotations

import copy
import os
from pathlib import Path
from typing import Dict, Optional, Tuple, Union

import numpy as np
import yaml

from skeleton_core.model import JOINT_NAMES


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
    'tracker': 'sensor_model',
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
    'reporting': {'tracking_states': True, 'unseen': 'hold', 'predicted_error_mm': 0.0,
                  'predicted_rho': 0.95},
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


# Per-tracker variants of the model: overrides merged over the base parameters by
# :func:`tracker_params`; each is also a YAML file in config/ (``sensor_model_<tracker>.yaml``,
# where the sources of its numbers are cited), which the tests keep equal to this table.
TRACKER_VARIANTS: Dict[str, Dict] = {
    'azure_kinect_bt': {
        'tracker': 'azure_kinect_bt',
        'fps': 30.0,
        'placement': {'min_range_m': 0.5, 'max_range_m': 3.86,
                      'horizontal_fov_deg': 75.0, 'vertical_fov_deg': 65.0},
        'jitter': {'depth_coeff_mm': 0.5,
                   'base_mm': dict(torso=1.5, head=2.0, shoulder=2.0, elbow=3.5, wrist=5.0,
                                   hand=6.0, hip=2.0, knee=3.5, ankle=5.0, foot=6.0)},
        'slow_drift': {'sigma_mm': dict(torso=2.5, head=3.5, shoulder=5.5, elbow=7.0, wrist=8.5,
                                        hand=10.0, hip=2.0, knee=7.0, ankle=8.5, foot=10.0)},
        'systematic': {'sigma_mm': dict(torso=13.0, head=10.0, shoulder=23.0, elbow=22.0,
                                        wrist=16.0, hand=18.0, hip=18.0, knee=22.0, ankle=20.0,
                                        foot=29.0)},
        'reporting': {'tracking_states': False, 'unseen': 'predict', 'predicted_error_mm': 40.0,
                      'predicted_rho': 0.95},
    },
}
VARIANT_YAML = {name: f'sensor_model_{name}.yaml' for name in TRACKER_VARIANTS}


def tracker_params(tracker: str, base: Union[None, str, Path, Dict] = None) -> Dict:
    """The sensor model's parameters for the skeleton tracker ``tracker``
    (:data:`skeleton_core.tracker.TRACKERS`): its variant (:data:`TRACKER_VARIANTS`) merged over
    ``base`` (as :func:`load_params` takes). A tracker without a variant ('' , ``sensor_model``,
    the Kinect SDKs, NiTE2) gets the base model; an unknown name is a one-line ``ValueError``."""
    from skeleton_core.tracker import check
    name = check(tracker)
    params = load_params(base)
    variant = TRACKER_VARIANTS.get(name)
    return _merge(params, variant) if variant else params


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
        with open(params) as f:
            data = yaml.safe_load(f) or {}
        if '/**' in data:  # tolerate a ROS-style wrapper
            data = data['/**'].get('ros__parameters', {})
        return _merge(DEFAULT_PARAMS, data)
    if isinstance(params, dict):
        return _merge(DEFAULT_PARAMS, params)
    raise TypeError(f'params must be None, a YAML path or a dict, got {type(params).__name__}')


def _group_array(table: Dict[str, float]) -> np.ndarray:
    return np.array([float(table[g]) for g in JOINT_GROUP])

