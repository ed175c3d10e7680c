"""``optimizer`` node: methods B / C, the natural-posture-space optimizer (Shum et al. 2013).
``/kinect/skeletons_reliability`` -> ``/posture/reconstructed`` (SkeletonArray). Input skeletons
without a reliability get one estimated here (Eq. 1-8); ``method`` B ignores it."""
from __future__ import annotations

from typing import Any, Dict, Optional

from skeleton_core.rosnode import ParamSpec, run_node

from .node_common import (RELIABILITY_NAMES, RELIABILITY_SPECS, DatabaseNode,
                          check_reliability_params, common_specs)
from .optimizer import KNN_MODES, SOLVERS
from .reconstructor import Reconstructor

SPECS = [
    ParamSpec('database', '', "motion database file ('' = built-in / CMU default)"),
    ParamSpec('method', 'C', 'C: reliability-weighted (paper); B: every reliability 1',
              choices=('B', 'C')),
    ParamSpec('k', 30, 'Table V: neighbours of the KNN search (Eq. 9)', (2, 1000)),
    ParamSpec('pca_dims', 20, 'Table V: dimensions of the natural posture space', (1, 60)),
    ParamSpec('steps', 20, 'Table V: maximum optimisation steps', (0, 1000)),
    ParamSpec('samples', 100, 'Table V: samples per optimisation step', (1, 100000)),
    ParamSpec('w_control', 1.0, 'Eq. 15: weight of the control term E_c', (0.0, 1000.0)),
    ParamSpec('w_style', 8.0, 'Eq. 15: weight of the style term E_s (paper 0.5; 8 measured on '
              'the sensor-model streams)', (0.0, 1000.0)),
    ParamSpec('w_kinematics', 1.5, 'Eq. 15: weight of the kinematics term E_k', (0.0, 1000.0)),
    ParamSpec('w_continuity', 0.25, 'Eq. 15: weight of the continuity term E_m', (0.0, 1000.0)),
    ParamSpec('step_scale', 0.5, 'stochastic search: sample spread in neighbour standard deviations',
              (1e-4, 100.0)),
    ParamSpec('solver', 'stochastic', 'stochastic (paper) or gauss_newton (deterministic)',
              choices=SOLVERS),
    ParamSpec('gn_iterations', 6, 'gauss_newton: maximum iterations', (1, 1000)),
    ParamSpec('seed', 0, 'random seed of the stochastic search', (0, 2 ** 31 - 1)),
    ParamSpec('knn', 'brute', 'KNN search: brute (exact BLAS) or kdtree (approximate)',
              choices=KNN_MODES),
    ParamSpec('kdtree_dims', 12, 'kdtree: global PCA dimensions of the tree', (1, 60)),
    ParamSpec('kdtree_candidates', 4, 'kdtree: candidates fetched per neighbour', (1, 100)),
    ParamSpec('reliable_threshold', 0.5, 'a joint at or above this reliability counts as reliable',
              (0.0, 1.0)),
    ParamSpec('trust_sensor_distance', 0.12,
              'nearest database posture farther than this (RMS m per reliable joint): reliable '
              'joints blend towards their observed positions (fully at twice it)', (0.0, 100.0)),
    ParamSpec('output_scale', 'user', "user: result retargeted to the user's bone lengths; "
              'standard: the database body', choices=('user', 'standard')),
    ParamSpec('use_input_reliability', True,
              'use the reliability field of the input when it is filled (else estimate it)'),
    ParamSpec('output_mode', 'segments',
              'segments: blended segment directions, constant user lengths, chained from the root, '
              'smoothed; blend: solution blended towards the observed joints (paper)',
              choices=('segments', 'blend')),
    ParamSpec('trust_mode', 'noise_ratio',
              "trust in the sensor from noise_ratio (database distance / the sensor's measured "
              'noise) or distance (trust_sensor_distance, earlier rule)',
              choices=('noise_ratio', 'distance')),
    ParamSpec('trust_sensor_ratio', 8.0,
              'noise_ratio: database distance / sensor noise at which the trust starts to rise '
              '(full at twice it)', (1e-3, 1e6)),
    ParamSpec('noise_alpha', 0.05, 'noise_ratio: exponential-average rate of the noise estimate',
              (1e-4, 1.0)),
    ParamSpec('observation_weight', 0.3,
              'segments: weight of the observed direction of a segment with two reliable ends',
              (0.0, 1.0)),
    ParamSpec('length_frames', 15,
              'segments: reliable observations averaged per segment length, then frozen',
              (1, 100000)),
    ParamSpec('symmetric_lengths', True, 'segments: left and right limbs share their mean lengths'),
    ParamSpec('smooth_min_cutoff', 3.0,
              'segments: One Euro minimum cutoff (Hz) of segment and root smoothing, 0 = off',
              (0.0, 1000.0)),
    ParamSpec('smooth_beta', 10.0, 'segments: One Euro speed coefficient (s/m)', (0.0, 1e6)),
    ParamSpec('smooth_d_cutoff', 1.0, 'segments: One Euro speed cutoff (Hz)', (1e-3, 1000.0)),
    ParamSpec('smooth_filled_scale', 0.2,
              'segments: cutoff factor of a segment the database fills in (an end with '
              'reliability 0; 1 at or above reliable_threshold, linear between), 1 = same '
              'smoothing everywhere', (0.01, 1.0)),
    ParamSpec('float_root', True,
              'when the root joint is unreliable, match the database translation-invariantly '
              'and place the root (and the query) where the neighbours put it'),
    ParamSpec('height_frames', 30,
              'no frame with every joint tracked yet: frames of scale-invariant database fits '
              "whose median is taken as the user's height (query scale, standard-body lengths), "
              'then kept; 0 = off (standard height)', (0, 100000)),
    ParamSpec('yaw_rate', 0.5,
              'few reliable joints (hips, shoulders and every segment unreliable): fraction per frame '
              'of the heading correction that best fits the reliable joints to the database; 0 = keep the last heading',
              (0.0, 1.0)),
    ParamSpec('yaw_search', 12,
              'few reliable joints from the first frame: headings tried against '
              'the database (from the one the unreliable torso gives); 0 = take that one',
              (0, 360)),
    ParamSpec('yaw_neighbours', 5,
              'few reliable joints: database postures whose best rotations (each a weighted 2-D '
              'Procrustes of the reliable joints) are averaged into the heading correction',
              (1, 1000)),
    ParamSpec('smooth_filled_speed', False,
              'segments: smooth_filled_scale lowers only the minimum cutoff of a filled segment '
              '(the One Euro speed term is kept: less lag in fast motion, more jitter: class c '
              '22.4 -> 29.3 m/s2 against raw 23.4)'),
    ParamSpec('smooth_anchored_speed', True,
              'segments, few reliable joints (hips, shoulders and every segment unreliable): a '
              'filled segment with a reliable joint at or below its child keeps the One Euro '
              'speed term (as smooth_filled_speed, for it alone): the body no longer trails the '
              'tracked hands and feet (Table III hands+feet 8.63 -> 8.34 cm)'),
]
CORE_NAMES = [s.name for s in SPECS if s.name not in ('database', 'method')]


class OptimizerNode(DatabaseNode):
    def __init__(self, database_obj=None, **kwargs):
        specs = (common_specs('/kinect/skeletons_reliability', '/posture/reconstructed') + SPECS
                 + RELIABILITY_SPECS)
        super().__init__('optimizer', specs, database_obj=database_obj, **kwargs)

    def validate(self, values: Dict[str, Any]) -> Optional[str]:
        return check_reliability_params(values)

    def make_processor(self, values: Dict[str, Any]):
        params = {k: values[k] for k in RELIABILITY_NAMES + CORE_NAMES}
        return Reconstructor(self.db, method=values['method'], **params)


def main(args=None) -> int:
    return run_node(OptimizerNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
