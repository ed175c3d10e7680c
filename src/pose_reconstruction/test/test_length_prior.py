"""The length prior (pose_reconstruction.length_prior) against hand-computed cases, and the
database's length ratios it reads."""
import numpy as np
import pytest

from pose_reconstruction.length_prior import LengthPrior, LengthPriorConfig
from pose_reconstruction.reconstructor import Reconstructor
from skeleton_core.model import (NUM_SEGMENTS, SEGMENT_CHILD_INDEX, SEGMENT_PARENT_INDEX,
                                 estimate_height)
from skeleton_data.database import build_database, length_ratios
from skeleton_data.mocap import MotionClip
from skeleton_data.motions import builtin_clips


def _prior(online=False, sigma=0.03, min_segments=6):
    cfg = LengthPriorConfig(length_offset_sigma=sigma, length_offset_online=online,
                            length_offset_min_segments=min_segments)
    # every segment 0.2 of the height with a 5 % spread across people; no shared left/right
    return LengthPrior(cfg, np.full(NUM_SEGMENTS, 0.2), np.full(NUM_SEGMENTS, 0.01),
                       symmetric=False)


def test_fuse_matches_the_hand_computed_inverse_variance_combination():
    # 18 segments observed at 0.36 m, one at 0.40 m; equal ratios and spreads, so the weighted
    # size fit is the plain mean: h = mean(L) / 0.2 = 1.810526 m, prior 0.362105 m.
    # var_obs = 2 * 0.03^2 = 1.8e-3; var_prior = (0.362105 * 0.05)^2 + 0.2^2 var_h with
    # var_h = (1.8e-3 + 3.278e-4) / (19 * 0.04) = 2.7997e-3 -> 4.3979e-4;
    # prior weight 1.8e-3 / (1.8e-3 + 4.3979e-4) = 0.80365:
    # 0.40 -> 0.19635 * 0.40 + 0.80365 * 0.362105 = 0.369546
    p = _prior()
    L = np.full(NUM_SEGMENTS, 0.36)
    L[4] = 0.40
    out = p.fuse(L, np.full(NUM_SEGMENTS, 15))
    assert p.height == pytest.approx(1.810526, abs=1e-6)
    assert out[4] == pytest.approx(0.369546, abs=1e-6)
    assert out[0] == pytest.approx(0.361692, abs=1e-6)


def test_unobserved_segment_takes_the_prior_and_few_observations_change_nothing():
    p = _prior()
    L = np.full(NUM_SEGMENTS, 0.36)
    counts = np.full(NUM_SEGMENTS, 15)
    L[7], counts[7] = 0.25, 0  # a fallback length, never observed
    out = p.fuse(L, counts)
    h = 0.36 / 0.2  # fitted to the 18 observed segments only
    assert out[7] == pytest.approx(0.2 * h, abs=1e-9)
    few = np.zeros(NUM_SEGMENTS, int)
    few[:5] = 15  # fewer than length_offset_min_segments (6)
    assert np.array_equal(p.fuse(L, few), L)


def test_offset_scale_is_measured_from_left_right_differences():
    # mirrored pairs observed 4 cm apart (left +2 cm, right -2 cm): var(L_l - L_r) = 4 sigma^2
    # -> sigma = 0.04 / 2 = 2 cm, whatever length_offset_sigma says; the shared (symmetric)
    # lengths are equal on both sides
    from pose_reconstruction.length_prior import _MIRROR_SEG, _MIRRORED
    L = np.full(NUM_SEGMENTS, 0.36)
    left = _MIRRORED & (np.arange(NUM_SEGMENTS) < _MIRROR_SEG)
    L[left] += 0.02
    L[_MIRROR_SEG[left]] -= 0.02
    counts = np.full(NUM_SEGMENTS, 15)
    p = _prior(online=True, sigma=0.05)
    p.fuse(L, counts)
    assert p.offset_sigma == pytest.approx(0.02, abs=1e-12)
    sym = LengthPrior(LengthPriorConfig(length_offset_sigma=0.05), np.full(NUM_SEGMENTS, 0.2),
                      np.full(NUM_SEGMENTS, 0.01), symmetric=True)
    out = sym.fuse(L, counts)
    assert np.allclose(out, out[_MIRROR_SEG])
    assert np.allclose(out, 0.36)  # the shared lengths agree with the prior: nothing moves
    off = _prior(online=False, sigma=0.05)
    off.fuse(L, counts)
    assert off.offset_sigma == pytest.approx(0.05)


def test_segment_far_outside_the_prior_keeps_its_observed_length():
    # a sensor that places a joint elsewhere on one segment (20 cm longer): more than 3 standard
    # deviations off, so that segment keeps its observation and the others fit the size alone
    p = _prior()
    L = np.full(NUM_SEGMENTS, 0.36)
    L[0] = 0.56
    out = p.fuse(L, np.full(NUM_SEGMENTS, 15))
    assert out[0] == 0.56
    assert p.outliers[0] and p.outliers.sum() == 1
    assert p.height == pytest.approx(1.8, abs=1e-9)
    assert np.allclose(out[1:], 0.36)


def test_length_ratios_are_scale_free_and_reach_the_reconstructor():
    clip = builtin_clips()[0]
    big = MotionClip('big', clip.motion_class, clip.fps, clip.positions * 1.2,
                     clip.orientations, 'test')
    mean, std = length_ratios([clip, big])
    p = np.asarray(clip.positions, float)
    ln = np.median(np.linalg.norm(p[:, SEGMENT_CHILD_INDEX] - p[:, SEGMENT_PARENT_INDEX],
                                  axis=-1), axis=0)
    h = np.median([estimate_height(x) for x in p[::30]])
    assert np.allclose(mean, ln / h, rtol=1e-6)
    assert np.all(std < 1e-6)
    db, _ = build_database([clip, big], progress=False)
    assert np.allclose(db.meta['length_ratio_mean'], ln / h, rtol=1e-6)
    on = Reconstructor(db, method='C')
    assert on.segment_output.length_prior is not None
    off = Reconstructor(db, method='C', length_prior=False)
    assert off.segment_output.length_prior is None
    assert Reconstructor(db.positions, method='C').segment_output.length_prior is None


def test_the_fusion_runs_again_only_when_an_observation_arrives():
    clip = builtin_clips()[0]
    db, _ = build_database([clip], progress=False)
    out = Reconstructor(db, method='C').segment_output
    calls = []
    prior = out.length_prior
    out.length_prior = lambda L, n, *a: calls.append(n.copy()) or prior(L, n, *a)
    p = np.asarray(clip.positions[0], float)
    seen = np.full(p.shape[0], 1.0)
    seen[SEGMENT_CHILD_INDEX[-1]] = 0.0  # one segment never observed: lengths never freeze
    first = out.lengths(p, seen)
    assert len(calls) == 1
    first[:] = -1.0  # the caller's copy: the cache keeps its own
    again = out.lengths(p, np.zeros_like(seen))  # nothing reliable: nothing new observed
    assert len(calls) == 1 and np.all(again > 0)
    out.lengths(p, seen)  # new observations: fused again
    assert len(calls) == 2


def _two_subject_references():
    """Two subjects' (T, 20, 3) reference sequences: a standard body scaled by 1.0 / 1.1 with the
    hip segments 1.5x as wide as the database's body, the hands missing (NaN)."""
    from skeleton_core.model import HAND_LEFT, HAND_RIGHT, HIP_LEFT, HIP_RIGHT, ROOT
    p = np.asarray(builtin_clips()[0].positions[:40], float).copy()
    for hip in (HIP_LEFT, HIP_RIGHT):
        p[:, hip] = p[:, ROOT] + 1.5 * (p[:, hip] - p[:, ROOT])
    p[:, [HAND_LEFT, HAND_RIGHT]] = np.nan
    return [p, 1.1 * p, p], ['s01', 's02', 's01']


def test_a_correction_carries_its_references_proportions():
    from pose_reconstruction import correction as C
    refs, groups = _two_subject_references()
    out = C.reference_proportions(refs, groups)
    p = refs[0]
    L = np.median(np.linalg.norm(p[:, SEGMENT_CHILD_INDEX] - p[:, SEGMENT_PARENT_INDEX],
                                 axis=-1), axis=0)
    have = np.isfinite(L)
    assert out['reference_length_groups'] == 2
    mean = np.array([np.nan if v is None else v for v in out['reference_length_ratio_mean']])
    assert np.array_equal(np.isfinite(mean), have)  # the hands: None
    assert np.allclose(mean[have], L[have] / L[have].sum(), rtol=1e-9)  # scale-free
    std = np.array([np.nan if v is None else v for v in out['reference_length_ratio_std']])
    assert np.all(std[have] < 1e-9)
    assert C.reference_proportions(refs[:1], groups[:1]) == {'reference_length_groups': 1}
    # fit() stores them with the correction (the meta a Reconstructor reads)
    full = [np.where(np.isnan(r), 0.0, r) for r in refs]  # fit needs complete frames
    corr = C.fit(full, full, 'kinect_v2_sdk', groups=groups, posture=False)
    assert corr.meta['reference_length_groups'] == 2
    a = np.array(corr.meta['reference_length_ratio_mean'], float)[have]
    assert np.allclose(a / a.sum(), mean[have], rtol=1e-9)  # the same proportions


def test_the_prior_takes_the_corrections_layout_not_the_databases():
    """With a correction applied, lengths measured in the correction's reference layout (here
    hips 1.5x the database body's) stay as measured; the database's proportions pulled them."""
    from pose_reconstruction import correction as C
    from skeleton_core.model import NUM_JOINTS, SEGMENT_NAMES
    refs, groups = _two_subject_references()
    layout = C.reference_proportions(refs, groups)
    db, _ = build_database(builtin_clips()[:2], progress=False)
    corr = C.SensorCorrection('kinect_v2_sdk', np.zeros((NUM_JOINTS, 3)),
                              np.zeros((C.NUM_FEATURES, 3 * NUM_JOINTS)),
                              np.zeros(C.NUM_FEATURES), meta=dict(layout))
    cfg = dict(method='C', length_offset_online=False, length_offset_sigma=0.03)
    with_corr = Reconstructor(db, correction=corr, input_tracker='kinect_v2_sdk', **cfg)
    plain = Reconstructor(db, **cfg)
    p = refs[1][0]
    L = np.linalg.norm(p[SEGMENT_CHILD_INDEX] - p[SEGMENT_PARENT_INDEX], axis=-1)
    seen = np.isfinite(L)
    L = np.where(seen, L, 0.0)
    n = np.where(seen, 15, 0)
    hips = [i for i, s in enumerate(SEGMENT_NAMES) if s in ('HipCenter-HipLeft',
                                                            'HipCenter-HipRight')]
    ours = with_corr.length_prior.fuse(L, n)
    theirs = plain.length_prior.fuse(L, n)
    assert np.allclose(ours[seen], L[seen], atol=1e-6)  # the layout's proportions: as measured
    assert np.all(theirs[hips] < L[hips] - 0.005)  # the database's: pulled > 5 mm shorter
    # the hands, which the reference lacks, keep the database's proportion (rescaled)
    mean = with_corr.length_prior.mean
    assert np.all(np.isfinite(mean)) and np.all(mean > 0)
    # two subjects of the same proportions (spread 0): the spread is the database bodies'
    assert np.allclose(with_corr.length_prior.rel_var, plain.length_prior.rel_var)
    # a correction without proportions (built before they were stored): the database's
    bare = C.SensorCorrection('kinect_v2_sdk', np.zeros((NUM_JOINTS, 3)),
                              np.zeros((C.NUM_FEATURES, 3 * NUM_JOINTS)),
                              np.zeros(C.NUM_FEATURES))
    old = Reconstructor(db, correction=bare, input_tracker='kinect_v2_sdk', **cfg)
    assert np.allclose(old.length_prior.mean, plain.length_prior.mean)
