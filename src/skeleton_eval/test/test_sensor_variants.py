"""The sensor model's per-tracker variants (skeleton_eval.sensor_params.TRACKER_VARIANTS): the
Azure Kinect body tracking's (``azure_kinect_bt``) is selected by the tracker's name, its YAML is
the built-in table, and its streams differ from the Kinect v1 model's as the tracker does: wider
view, less noise, every joint reported TRACKED (its ROS message carries no joint state), an
unseen joint predicted near the truth instead of held where it was lost."""
from pathlib import Path

import numpy as np
import pytest
import yaml

from skeleton_core.model import JOINT_INDEX, TRACKED
from skeleton_core.tracker import TRACKERS
from skeleton_eval.clips import toy_clip
from skeleton_eval.sensor_model import SensorModel
from skeleton_eval.sensor_params import (DEFAULT_PARAMS, TRACKER_VARIANTS, VARIANT_YAML,
                                         load_params, tracker_params)

ROOT = Path(__file__).resolve().parents[3]
AZURE = 'azure_kinect_bt'


def test_every_variant_yaml_matches_its_builtin_table():
    for name, variant in TRACKER_VARIANTS.items():
        assert name in TRACKERS
        with open(ROOT / 'config' / VARIANT_YAML[name]) as f:
            assert yaml.safe_load(f) == variant, name
        # the file alone (merged over the defaults) is the variant the tracker's name selects
        assert load_params(ROOT / 'config' / VARIANT_YAML[name]) == tracker_params(name)


def test_variant_selected_by_tracker_name():
    az = tracker_params(AZURE)
    assert az['tracker'] == AZURE and DEFAULT_PARAMS['tracker'] == 'sensor_model'
    # the Azure depth camera's NFOV unbinned mode, not the Kinect v1's 57 x 43 deg, 0.8-4 m
    assert (az['placement']['horizontal_fov_deg'], az['placement']['vertical_fov_deg']) == (75, 65)
    assert (az['placement']['min_range_m'], az['placement']['max_range_m']) == (0.5, 3.86)
    assert az['reporting']['tracking_states'] is False
    assert az['reporting']['unseen'] == 'predict'
    # smaller noise and offsets in every joint group
    for table in (('jitter', 'base_mm'), ('slow_drift', 'sigma_mm'), ('systematic', 'sigma_mm')):
        a, k = az[table[0]][table[1]], DEFAULT_PARAMS[table[0]][table[1]]
        assert all(a[g] < k[g] for g in k), table
    # what is not in the variant stays the base model's (scenarios, failure modes)
    assert az['scenarios'] == DEFAULT_PARAMS['scenarios']
    # trackers without a variant get the base model; an unknown name is refused
    for name in ('', 'sensor_model', 'nite2', 'kinect_v2_sdk'):
        assert tracker_params(name) == load_params(None)
    with pytest.raises(ValueError, match='unknown skeleton tracker'):
        tracker_params('kinect_v3')


# The Azure variant's per-group factors over the Kinect model's tables, and the rounding step of
# each table (mm). These are the documented FALLBACK of config/sensor_model_azure_kinect_bt.yaml
# (our choice, not published ratios: the per-joint Azure / Kinect v2 figures of Albert et al.
# 2020 and Tölgyessy et al. 2021 are not yet read); when they are, these factors change with the
# YAML, each to the cited ratio.
AZURE_FACTORS = {
    ('systematic', 'sigma_mm'): (dict.fromkeys(
        ('torso', 'head', 'shoulder', 'elbow', 'wrist', 'hand', 'hip', 'knee', 'ankle', 'foot'),
        0.7), 1.0),
    ('slow_drift', 'sigma_mm'): (dict.fromkeys(
        ('torso', 'head', 'shoulder', 'elbow', 'wrist', 'hand', 'hip', 'knee', 'ankle', 'foot'),
        0.7), 0.5),
    ('jitter', 'base_mm'): (dict(torso=0.5, head=0.67, shoulder=0.5, elbow=0.6, wrist=0.6,
                                 hand=0.6, hip=0.5, knee=0.6, ankle=0.6, foot=0.6), 0.5),
}


def test_azure_tables_are_the_kinect_tables_times_the_documented_factors():
    az = tracker_params(AZURE)
    for (section, key), (factors, step) in AZURE_FACTORS.items():
        a, k = az[section][key], DEFAULT_PARAMS[section][key]
        assert set(factors) == set(k) == set(a), (section, key)
        for g, f in factors.items():
            # each value is the Kinect value times its factor, rounded to the table's step
            assert abs(a[g] - f * k[g]) <= step / 2 + 1e-9, (section, g, a[g], f * k[g])


def test_azure_stream_reports_every_joint_tracked_and_predicts_the_unseen():
    clip = toy_clip(20.0)
    kin = SensorModel(seed=4).corrupt(clip, 'b', seed=4)
    az = SensorModel(tracker_params(AZURE), seed=4).corrupt(clip, 'b', seed=4)
    assert (az.tracking_state == TRACKED).all()           # no states in the ROS message
    assert (kin.tracking_state != TRACKED).any()          # the Kinect model has them
    # the stream still knows which joints were unseen (for the no-harm mask and the tests)
    assert (~az.clean).any()
    err_k = np.linalg.norm(kin.positions - kin.truth, axis=-1)
    err_a = np.linalg.norm(az.positions - az.truth, axis=-1)
    # where nothing is wrong: the Azure model's noise + offsets are smaller
    assert np.median(err_a[az.clean]) < 0.8 * np.median(err_k[kin.clean])
    # an unseen joint is predicted where the body goes (its frame-to-frame motion follows the
    # truth's: regression slope ~1), not held where it was lost (slope ~0)
    def followed(s):
        both = ~s.clean[1:] & ~s.clean[:-1]
        vr, vt = np.diff(s.positions, axis=0)[both], np.diff(s.truth, axis=0)[both]
        return float((vr * vt).sum() / (vt * vt).sum())
    assert followed(az) > 0.8 and followed(kin) < 0.3, (followed(az), followed(kin))


def test_wider_field_of_view_keeps_raised_hands_in_view():
    # the hands raised above the head at 2.5 m: out of the Kinect v1's 43 deg vertical view
    # (NOT_TRACKED, held), inside the Azure's 65 deg
    clip = toy_clip(10.0)
    pos = clip.positions.copy()
    for j in ('HandLeft', 'HandRight'):
        pos[:, JOINT_INDEX[j], 2] = 2.2
    from dataclasses import replace
    clip = replace(clip, positions=pos)
    kin = SensorModel(seed=1).corrupt(clip, 'clean', seed=1)
    az = SensorModel(tracker_params(AZURE), seed=1).corrupt(clip, 'clean', seed=1)
    hands = [JOINT_INDEX['HandLeft'], JOINT_INDEX['HandRight']]
    assert (~kin.clean[:, hands]).mean() > 0.9
    assert (~az.clean[:, hands]).mean() < 0.1

