"""Calibration measurements and the real-data evaluation on small synthetic 'recordings'."""
import numpy as np
import pytest

from skeleton_eval import calibration as C
from skeleton_data import uiprmd as U
from skeleton_eval import paired as P
from skeleton_core.model import HAND_LEFT, NUM_JOINTS, TRACKED, standard_body


def _moving(n=120, seed=0):
    rest = standard_body().rest_positions()
    t = np.arange(n) / 30.0
    sway = 0.05 * np.sin(2 * np.pi * 0.5 * t)[:, None, None] * np.array([1.0, 0.5, 0.0])
    return rest[None] + sway + np.array([2.5, 0.0, 0.0])


def test_hf_jitter_of_white_noise_matches_the_filter_theory():
    from scipy.signal import savgol_coeffs
    rng = np.random.default_rng(0)
    sigma = 0.004
    p = _moving(1500) + rng.normal(0, sigma, size=(1500, NUM_JOINTS, 3))
    m = C.measure([p])
    h0 = savgol_coeffs(C.SG_WINDOW, C.SG_ORDER)[C.SG_WINDOW // 2]
    want = sigma * np.sqrt(1 - h0) * 1e3  # the smoother is a projection: residual var = (1-h0) s^2
    np.testing.assert_allclose(m['hf_jitter_mm'], want, rtol=0.05)
    assert m['hf_jitter_depth_mm'] == pytest.approx(m['hf_jitter_lateral_mm'], rel=0.1)


def test_rigid_motion_has_no_bone_length_variation_and_offsets_are_exact():
    p = _moving()
    off = np.array([0.01, -0.02, 0.02])
    m = C.measure([p], [p - off], ['s'])
    assert np.nanmax(m['bone_length_std_mm']) < 1e-6
    np.testing.assert_allclose(m['offset_mm'], np.linalg.norm(off) / np.sqrt(3) * 1e3)
    assert np.nanmax(m['random_error_mm']) < 1e-6


def _clip(name, positions):
    st = np.full(NUM_JOINTS, TRACKED, np.uint8)
    return P.RealClip(kinect=U.KinectClip(U.parse_name(name + '_positions.txt.gz'), positions, st,
                                          np.zeros((len(positions), 22, 3))))


def test_tracking_failures_flags_stretched_frames():
    good = [_clip(f'm01_s01_e0{i}', _moving()) for i in range(1, 4)]
    bad = _moving()
    bad[10:40, 13] += np.array([0.0, 0.0, -0.3])   # knee pulled 30 cm: thigh/shank off
    fail = _clip('m03_s01_e01', bad)
    res = C.tracking_failures(good + [fail])
    assert res['m01']['failed_fraction'] == 0.0
    assert res['m03_s01']['failed_fraction'] == pytest.approx(30 / 120)


def test_added_latency():
    from skeleton_eval.real_eval import added_latency_ms
    p = _moving(200)
    p[:, :, 1] += 0.1 * np.sin(np.arange(200) / 5.0)[:, None]
    delayed = np.concatenate([np.repeat(p[:1], 3, 0), p[:-3]])
    assert added_latency_ms(delayed, p) == pytest.approx(100.0, abs=5.0)
    assert added_latency_ms(p, p) == pytest.approx(0.0, abs=1e-9)


def test_evaluate_real_scores_raw_against_the_reference():
    from skeleton_eval.real_eval import evaluate_real, to_markdown
    rng = np.random.default_rng(3)
    clips = []
    for i in range(1, 3):
        ref = _moving(60, i)
        c = _clip(f'm07_s02_e0{i}', ref + rng.normal(0, 0.01, size=ref.shape))
        c.reference = ref
        clips.append(c)
    clips.append(_clip('m03_s01_e01', _moving(60)))  # no reference: reference-free row
    res = evaluate_real('synthetic', methods=['raw', 'one_euro'], clips=clips)
    raw = res['results']['raw']
    # MPJPE of N(0, 1 cm) per axis: mean of a chi(3) * 1 cm = 1.60 cm
    assert raw['m07']['metrics']['mpjpe_cm']['overall'] == pytest.approx(1.596, rel=0.08)
    assert raw['overall']['clips'] == 2
    assert np.isnan(raw['m03_s01']['metrics']['mpjpe_cm']['overall'])
    assert np.isfinite(raw['m03_s01']['metrics']['jitter_ms2']['overall'])
    # hands are not recorded: never scored
    assert np.isnan(raw['m07']['metrics']['mpjpe_cm']['per_joint'][HAND_LEFT])
    assert res['results']['one_euro']['m07']['metrics']['jitter_ms2']['overall'] < \
        raw['m07']['metrics']['jitter_ms2']['overall']
    md = to_markdown(res)
    assert '| raw |' in md and 'm03_s01' in md
