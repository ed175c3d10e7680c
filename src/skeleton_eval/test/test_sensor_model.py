"""Kinect v1 sensor model: placement, calibrated noise statistics, event rates, live == offline."""
from pathlib import Path

import numpy as np
import pytest
import yaml

from skeleton_eval.clips import toy_clip
from skeleton_core.model import (FOOT_LEFT, FOOT_RIGHT, HAND_LEFT, HAND_RIGHT, HIP_CENTER, INFERRED,
                                 NOT_TRACKED, TRACKED)
from skeleton_core.model import SEGMENT_NAMES, SEGMENTS
from skeleton_eval.sensor_params import DEFAULT_PARAMS, JOINT_GROUP, SCENARIOS, load_params
from skeleton_eval.sensor_model import SensorModel
from skeleton_eval.sensor_statistics import statistics
from skeleton_eval.sensor_stream import LOOP_BLEND_FRAMES

ROOT = Path(__file__).resolve().parents[3]


def test_yaml_matches_builtin_defaults():
    with open(ROOT / 'config' / 'sensor_model.yaml') as f:
        data = yaml.safe_load(f)
    assert data == DEFAULT_PARAMS
    assert load_params(ROOT / 'config' / 'sensor_model.yaml') == DEFAULT_PARAMS
    assert set(SCENARIOS) <= set(DEFAULT_PARAMS['scenarios'])


def test_placement_in_sensor_frame():
    m = SensorModel(seed=0)
    s = m.corrupt(toy_clip(3.0), 'clean')
    assert s.positions.shape == s.truth.shape == (90, 20, 3)
    assert s.tracking_state.dtype == np.uint8 and s.stamps_ns.dtype == np.int64
    assert np.allclose(np.diff(s.stamps_ns), 1e9 / 30, atol=1)
    root = s.truth[:, HIP_CENTER]
    assert np.allclose(root[:, 0], 2.5, atol=0.05) and np.allclose(root[:, 1], 0.0, atol=0.05)
    feet = s.truth[:, [FOOT_LEFT, FOOT_RIGHT], 2]
    assert abs(feet.min() + 0.8) < 0.03  # floor at -sensor height
    # facing the sensor: the body's left hand is on the sensor's right (-y)
    assert np.all(s.truth[:, HAND_LEFT, 1] < s.truth[:, HAND_RIGHT, 1])
    # resampled from 120 Hz
    clip = toy_clip(3.0, fps=120.0)
    assert len(m.corrupt(clip, 'clean')) == 90


def test_noise_statistics_match_the_yaml():
    m = SensorModel(seed=3)
    streams = [m.corrupt(toy_clip(20.0, name=f'toy{i}'), 'clean') for i in range(3)]
    st = statistics(streams)
    expected = m.expected_jitter_mm(st['mean_depth_m'])
    got = np.array(st['jitter_mm'])
    assert np.all(np.abs(got / expected - 1) < 0.2), (got, expected)
    # every segment length varies frame to frame, by about the joint errors combined
    bl = np.array(st['bone_length_std_mm'])
    assert np.all(bl > 5.0) and np.all(bl < 60.0)
    # vertical segments (trunk, thighs, shanks) are perpendicular to the depth axis: their length
    # std is the lateral error of both ends combined, sqrt(base^2 + slow^2) per joint (YAML values)
    p = m.params
    lat = {g: np.hypot(p['jitter']['base_mm'][g], p['slow_drift']['sigma_mm'][g])
           for g in p['jitter']['base_mm']}
    for child in ('Spine', 'ShoulderCenter', 'Head', 'KneeLeft', 'AnkleRight'):
        k = SEGMENT_NAMES.index(next(n for n in SEGMENT_NAMES if n.endswith('-' + child)))
        a, b = SEGMENTS[k]
        want = np.hypot(lat[JOINT_GROUP[a]], lat[JOINT_GROUP[b]])
        assert abs(bl[k] / want - 1) < 0.2, (child, bl[k], want)
    # no event in the clean scenario
    assert all(s.events == [] for s in streams)
    assert np.all(np.concatenate([s.tracking_state for s in streams]) == TRACKED)


def _rate_check(events, kind, cause, rate_per_min, frames, fps=30.0):
    onsets = [e for e in events if e['type'] == kind and e['cause'] == cause]
    busy = sum(e['duration'] for e in events if e['type'] == kind)
    free_min = max(frames - busy, 1) / fps / 60.0
    expected = rate_per_min * free_min
    assert abs(len(onsets) - expected) < 3.5 * np.sqrt(expected) + 1, (len(onsets), expected)
    return len(onsets)


@pytest.mark.parametrize('scenario', ['a', 'b', 'c'])
def test_events_happen_at_the_configured_rates(scenario):
    # rates scaled up 10x so a short stream has enough events; the ratio between classes is kept
    p = DEFAULT_PARAMS['scenarios'][scenario]
    over = {'scenarios': {scenario: {'occlusion_per_min': 10 * p['occlusion_per_min'],
                                     'false_positive_per_min': 10 * p['false_positive_per_min'],
                                     'turn_per_min': 0.0}}}
    m = SensorModel(over, seed=1)
    s = m.corrupt(toy_clip(60.0), scenario)
    n_occ = _rate_check(s.events, 'occlusion', 'random', 10 * p['occlusion_per_min'], len(s))
    assert n_occ > 10
    # false positives (random onsets; one episode per candidate joint at a time)
    fp = [e for e in s.events if e['type'] == 'false_positive' and e['cause'] == 'random']
    expected = 10 * p['false_positive_per_min'] * len(s) / 30.0 / 60.0
    assert abs(len(fp) - expected) < 3.5 * np.sqrt(expected) + 1, (len(fp), expected)
    # during a random occlusion episode the limb is INFERRED or NOT_TRACKED (unless a false
    # positive latched one of its joints, which the SDK reports TRACKED)
    latched = np.zeros(s.tracking_state.shape, bool)
    for e in s.events:
        if e['type'] == 'false_positive':
            latched[e['frame']:e['frame'] + e['duration'], e['joints']] = True
    for e in [e for e in s.events if e['type'] == 'occlusion']:
        f = e['frame'] + 1
        if f < len(s):
            j = [k for k in e['joints'] if not latched[f, k]]
            assert np.all(s.tracking_state[f, j] != TRACKED)


def test_more_occlusion_with_objects():
    m = SensorModel(seed=2)
    clip = toy_clip(30.0)
    st = statistics([m.corrupt(clip, sc) for sc in ('a', 'b', 'c')])['scenarios']
    assert st['a']['occluded_fraction'] < st['b']['occluded_fraction']
    assert st['a']['occluded_fraction'] < st['c']['occluded_fraction']


def test_false_positive_latches_and_vibrates():
    over = {'scenarios': {'a': {'false_positive_per_min': 30.0, 'occlusion_per_min': 0.0,
                                'turn_per_min': 0.0, 'self_occlusion': False}}}
    s = SensorModel(over, seed=4).corrupt(toy_clip(20.0), 'a')
    fps = [e for e in s.events if e['type'] == 'false_positive' and e['duration'] >= 6]
    assert fps
    angles = []
    for e in fps:
        j = e['joints'][0]
        seg = slice(e['frame'], e['frame'] + e['duration'])
        assert np.all(s.tracking_state[seg, j] == TRACKED)  # the SDK still says TRACKED
        err = np.linalg.norm(s.positions[seg, j] - s.truth[seg, j], axis=1)
        assert err.mean() > 0.05
        d = np.diff(s.positions[seg, j], axis=0)
        cos = (d[1:] * d[:-1]).sum(1) / np.linalg.norm(d[1:], axis=1) / np.linalg.norm(d[:-1], axis=1)
        angles += np.degrees(np.arccos(np.clip(cos, -1, 1))).tolist()
    assert np.mean(angles) > 90.0  # vibration (Shum 2013 Eq. 3-4)


def test_turning_away_swaps_left_and_right():
    over = {'turn': {'peak_deg': [175.0, 175.0], 'duration_s': [4.0, 4.0]},
            'scenarios': {'a': {'turn_per_min': 6.0, 'occlusion_per_min': 0.0,
                                'false_positive_per_min': 0.0}}}
    s = SensorModel(over, seed=5).corrupt(toy_clip(30.0), 'a')
    mirrors = [e for e in s.events if e['type'] == 'mirror']
    turns = [e for e in s.events if e['type'] == 'turn']
    assert turns and mirrors
    t = turns[0]
    mid = t['frame'] + t['duration'] // 2
    # the reported left hand is where the true right hand is
    assert np.linalg.norm(s.positions[mid, HAND_LEFT] - s.truth[mid, HAND_RIGHT]) < 0.15
    assert np.any(s.tracking_state[mid] == INFERRED)  # the far side is inferred


def test_live_stream_equals_offline():
    m = SensorModel(seed=7)
    clip = toy_clip(4.0)
    s = m.corrupt(clip, 'c')
    once = list(m.stream(clip, 'c', loop=False))
    assert len(once) == len(s)
    for i, (p, st, tr) in enumerate(once):
        assert np.array_equal(p, s.positions[i]) and np.array_equal(st, s.tracking_state[i])
        assert np.array_equal(tr, s.truth[i])
    # looping: the same until the clip's last LOOP_BLEND_FRAMES, which turn into its first
    # posture (sensor_stream.loop_blend)
    gen = m.stream(clip, 'c', loop=True)
    for i in range(len(s)):
        p, st, tr = next(gen)
        if i < len(s) - LOOP_BLEND_FRAMES:
            assert np.array_equal(tr, s.truth[i]) and np.array_equal(p, s.positions[i])
    p, st, tr = next(gen)  # loops
    assert p.shape == (20, 3) and st.dtype == np.uint8
    assert np.array_equal(m.corrupt(clip, 'c').positions, s.positions)  # seeded
    assert not np.array_equal(SensorModel(seed=8).corrupt(clip, 'c').positions, s.positions)
    assert set(np.unique(s.tracking_state)) <= {NOT_TRACKED, INFERRED, TRACKED}


def test_unknown_scenario_is_rejected():
    with pytest.raises(ValueError):
        SensorModel().corrupt(toy_clip(1.0), 'z')


def test_turn_episodes_at_the_configured_rate():
    m = SensorModel({'scenarios': {'a': {'turn_per_min': 6.0, 'occlusion_per_min': 0.0,
                                         'false_positive_per_min': 0.0}}}, seed=6)
    s = m.corrupt(toy_clip(90.0), 'a')
    n = _rate_check(s.events, 'turn', 'random', 6.0, len(s))
    assert n >= 2
    # turning changes the truth itself (the user turns), about the root
    t = [e for e in s.events if e['type'] == 'turn'][0]
    mid = t['frame'] + t['duration'] // 2
    assert np.allclose(s.truth[mid, HIP_CENTER], m.place(toy_clip(90.0))[mid, HIP_CENTER])


def test_class_e_small_persistent_tracked_errors():
    """Class e: TRACKED joints 5-15 cm off for seconds, the parent pulled partway, marked not
    clean; the other classes draw no random number for it (their streams are unchanged)."""
    m = SensorModel({'scenarios': {'e': {'turn_per_min': 0.0, 'occlusion_per_min': 0.0,
                                         'false_positive_per_min': 0.0}}}, seed=2)
    s = m.corrupt(toy_clip(60.0), 'e')
    ev = [e for e in s.events if e['type'] == 'tracked_error']
    # 8 per minute while none is active, each 1-5 s (~3 s): about 6 in a minute
    assert 3 <= len(ev) <= 12, len(ev)
    ref = SensorModel({'tracked_error': {'enabled': False},
                       'scenarios': {'e': {'turn_per_min': 0.0, 'occlusion_per_min': 0.0,
                                           'false_positive_per_min': 0.0}}}, seed=2)
    assert {e['cause'] for e in ev} <= {'rest', 'drift'}
    checked = False
    for e in ev:
        j, par = e['joints']
        assert 0.05 <= e['offset_m'] <= 0.15 and 0.3 <= e['neighbour_fraction'] <= 0.7
        mid = e['frame'] + e['duration'] // 2
        if mid >= len(s) or e['duration'] < 32 or s.tracking_state[mid, j] != TRACKED:
            continue   # short, or the joint self-occluded meanwhile (INFERRED)
        checked = True
        assert not s.clean[mid, j]
        assert not s.clean[mid, par]
        # the joint's error (beyond the ordinary noise: the 15 frames around mid, averaged)
        # is of the configured size, the parent's a fraction of it
        w = slice(mid - 7, mid + 8)
        err = np.linalg.norm((s.positions[w, j] - s.truth[w, j]).mean(0))
        assert 0.02 < err < 0.25, err
    assert checked
    # without class e's rate, nothing changes in the other classes
    for sc in ('a', 'd'):
        a = SensorModel(seed=0).corrupt(toy_clip(20.0), sc)
        b = SensorModel({'tracked_error': {'enabled': False}}, seed=0).corrupt(toy_clip(20.0), sc)
        assert np.array_equal(a.positions, b.positions)
    # and disabling it in class e leaves the stream without such errors
    s0 = ref.corrupt(toy_clip(60.0), 'e')
    assert not [e for e in s0.events if e['type'] == 'tracked_error']
