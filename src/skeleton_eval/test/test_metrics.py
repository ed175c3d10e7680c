"""Accuracy metrics on hand-made cases with hand-computed numbers."""
import numpy as np

from skeleton_eval import metrics as M
from skeleton_core.model import (ELBOW_LEFT, HAND_LEFT, NUM_JOINTS, SEGMENT_OF_JOINT, WRIST_LEFT,
                                 standard_body)

REST = standard_body().rest_positions()


def _seq(n=4):
    return np.repeat(REST[None], n, axis=0)


def test_eq18_and_mpjpe_one_joint_displaced():
    truth = _seq()
    pred = truth.copy()
    pred[:, HAND_LEFT, 0] += 0.03  # 3 cm
    per, tot = M.eq18_error(pred, truth)
    assert np.isnan(per[0])
    assert np.isclose(per[HAND_LEFT], 3.0) and np.isclose(per[WRIST_LEFT], 0.0)
    assert np.isclose(tot, 3.0 / 19)  # mean over 19 parts
    per, tot = M.mpjpe(pred, truth)
    assert np.isclose(per[HAND_LEFT], 3.0) and np.isclose(tot, 3.0 / 20)


def test_eq18_ignores_global_translation_and_counts_children():
    truth = _seq()
    pred = truth + np.array([0.1, -0.2, 0.05])
    assert np.isclose(M.eq18_error(pred, truth)[1], 0.0)
    assert np.isclose(M.mpjpe(pred, truth)[1], np.linalg.norm([10, -20, 5]))
    # moving the wrist by 4 cm changes two parent-relative vectors (wrist and hand)
    pred = truth.copy()
    pred[:, WRIST_LEFT, 2] += 0.04
    per, tot = M.eq18_error(pred, truth)
    assert np.isclose(per[WRIST_LEFT], 4.0) and np.isclose(per[HAND_LEFT], 4.0)
    assert np.isclose(tot, 8.0 / 19)


def test_jitter_constant_acceleration():
    fps = 30.0
    t = np.arange(10) / fps
    pred = _seq(10)
    pred[..., 1] += 0.5 * 2.0 * t[:, None] ** 2  # 2 m/s^2 along y
    per, tot = M.jitter(pred, fps)
    assert np.allclose(per, 2.0) and np.isclose(tot, 2.0)
    assert np.isnan(M.jitter(pred[:2], fps)[1])


def test_bone_length_std_and_error():
    truth = _seq(4)
    pred = truth.copy()
    # forearm 2 cm longer in frames 1 and 3 (move wrist and hand along the bone, +y)
    pred[1::2, WRIST_LEFT, 1] += 0.02
    pred[1::2, HAND_LEFT, 1] += 0.02
    s = SEGMENT_OF_JOINT[WRIST_LEFT]
    per, _ = M.bone_length_std(pred)
    assert np.isclose(per[s], 1.0)  # lengths L, L+2, L, L+2 cm: population std 1 cm
    assert np.isclose(per[SEGMENT_OF_JOINT[HAND_LEFT]], 0.0)
    per, tot = M.bone_length_error(pred, truth)
    assert np.isclose(per[s], 1.0) and np.isclose(tot, 1.0 / 19)


def test_bone_length_step_is_the_frame_to_frame_part():
    s = SEGMENT_OF_JOINT[WRIST_LEFT]
    # lengths L, L+2, L, L+2 cm (noise): steps of 2 cm, RMS 2 / sqrt(2)
    noisy = _seq(4)
    noisy[1::2, WRIST_LEFT, 1] += 0.02
    noisy[1::2, HAND_LEFT, 1] += 0.02
    assert np.isclose(M.bone_length_step(noisy)[0][s], 2.0 / np.sqrt(2))
    # lengths L ... L+6 cm in 1 cm steps (slow change): std 2 cm, frame-to-frame part 0.71 cm
    slow = _seq(7)
    slow[:, WRIST_LEFT, 1] += 0.01 * np.arange(7)
    slow[:, HAND_LEFT, 1] += 0.01 * np.arange(7)
    assert np.isclose(M.bone_length_std(slow)[0][s], 2.0)
    per, tot = M.bone_length_step(slow)
    assert np.isclose(per[s], 1.0 / np.sqrt(2)) and np.isclose(per[SEGMENT_OF_JOINT[HAND_LEFT]], 0)
    assert np.isnan(M.bone_length_step(slow[:1])[1])
    assert 'bone_step_cm' in M.compute_all(slow, slow)


def test_bone_direction_error_right_angle():
    truth = _seq(2)
    pred = truth.copy()
    # turn the forearm (elbow -> wrist, along +y) to point down (-z), same length
    L = np.linalg.norm(REST[WRIST_LEFT] - REST[ELBOW_LEFT])
    pred[:, WRIST_LEFT] = REST[ELBOW_LEFT] + np.array([0, 0, -L])
    pred[:, HAND_LEFT] = pred[:, WRIST_LEFT] + (REST[HAND_LEFT] - REST[WRIST_LEFT])
    per, _ = M.bone_direction_error(pred, truth)
    assert np.isclose(per[SEGMENT_OF_JOINT[WRIST_LEFT]], 90.0)
    assert np.isclose(per[SEGMENT_OF_JOINT[HAND_LEFT]], 0.0)
    assert np.isclose(M.bone_length_error(pred, truth)[0][SEGMENT_OF_JOINT[WRIST_LEFT]], 0.0)


def test_nan_frames_are_skipped():
    truth = _seq(3)
    pred = truth.copy()
    pred[:, HAND_LEFT, 0] += 0.05
    pred[1] = np.nan
    per, tot = M.mpjpe(pred, truth)
    assert np.isclose(per[HAND_LEFT], 5.0) and np.isclose(tot, 5.0 / 20)
    allnan = np.full_like(pred, np.nan)
    per, tot = M.eq18_error(allnan, truth)
    assert np.isnan(tot) and np.all(np.isnan(per))
    out = M.compute_all(pred, truth)
    assert set(out) == set(M.METRICS)
    assert len(out['eq18_cm']['per_joint']) == NUM_JOINTS and len(out['bone_dir_deg']['per_joint']) == 19


def test_length_rigidity_is_per_track_and_weighted_by_frames():
    from skeleton_core.model import standard_body
    rng = np.random.default_rng(0)
    a = np.repeat(standard_body(1.6).rest_positions()[None], 40, 0)
    b = np.repeat(standard_body(1.9).rest_positions()[None], 20, 0)
    # two rigid tracks of different people: 0 each (a pooled std would not be)
    raw_a, raw_b = a + rng.normal(0, 0.01, a.shape), b + rng.normal(0, 0.01, b.shape)
    r = M.length_rigidity([(raw_a, a), (raw_b, b), (raw_b[:2], b[:2])])
    assert r['tracks'] == 2 and r['frames'] == 62 and r['out_nan_frames'] == 0
    assert r['out_std_mean_cm'] < 1e-12 and abs(r['std_reduction_pct'] - 100.0) < 1e-9
    want = (40 * M.bone_length_std(raw_a)[0] + 20 * M.bone_length_std(raw_b)[0]) / 60
    np.testing.assert_allclose(r['raw_std_cm'], want)
    assert r['raw_jitter_ms2'] > 1.0 and r['out_jitter_ms2'] < 1e-9
    bad = b.copy()
    bad[3] = np.nan
    assert M.length_rigidity([(raw_b, bad)])['out_nan_frames'] == 1
