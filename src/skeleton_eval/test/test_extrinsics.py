"""Extrinsic calibration from skeletons (skeleton_eval.extrinsics): the rigid fit against gross
outliers, the trackers' per-joint offsets carried in the body frame (the mechanism the fit
models), and the whole calibration recovering a known placement and clock offset of a side sensor
from the sensor model's two views of one person walking."""
import numpy as np
import pytest

from skeleton_core.model import NUM_JOINTS, TRACKED
from skeleton_core.tf import Transform
from skeleton_eval.extrinsics import (CalibrationError, Track, body_frame_fit, calibrate, kabsch,
                                      robust_fit, synthetic_tracks)

SIDE = Transform.from_xyz_ypr(2.5, 2.5, 0.0, -90, 0, 0)   # front + side at 90 degrees


def test_robust_fit_ignores_gross_outliers():
    rng = np.random.default_rng(0)
    b = rng.uniform(-1, 1, (400, 3))
    true = Transform.from_xyz_ypr(0.4, -1.2, 0.3, 70, 5, -3)
    a = true.apply(b) + rng.normal(0, 0.005, b.shape)
    bad = rng.choice(400, 100, replace=False)                 # a quarter latched elsewhere
    a[bad] += rng.uniform(0.3, 1.0, (100, 3))
    d, ang = kabsch(a, b).distance(true)
    assert d > 0.05                                            # plain Kabsch is pulled off
    t, inl = robust_fit(a, b, np.ones(400), np.arange(400), rng)
    d, ang = t.distance(true)
    assert d < 0.005 and ang < 0.3
    assert not inl[bad].any()


def test_body_frame_offsets_are_separated_from_the_placement():
    """Two trackers whose joint centres differ by a constant offset per joint in the body frame:
    walking round (the heading covers every direction) the fit finds the rotation and the
    horizontal placement exactly; a plain fit is pulled by the offsets' mean."""
    rng = np.random.default_rng(1)
    frames, joints = 300, NUM_JOINTS
    heading = np.linspace(0, 4 * np.pi, frames)
    body = rng.uniform(-0.3, 0.3, (joints, 3)) + [0, 0, 0.9]
    centre = np.stack([np.cos(heading / 2) * 1.2 + 2.5, np.sin(heading / 2) * 1.2, 0 * heading], 1)
    c, s = np.cos(heading), np.sin(heading)
    rot = np.zeros((frames, 3, 3))
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = c, -s, s, c, 1
    a = np.einsum('fij,kj->fki', rot, body) + centre[:, None]       # A's joints (frames, 20, 3)
    offsets = rng.normal(0, 0.03, (joints, 3)) + [0.02, 0.0, 0.01]   # B's tracker, body frame
    b_world = a - np.einsum('fij,kj->fki', rot, offsets)
    true = Transform.from_xyz_ypr(2.5, 2.5, 0.2, -90, 0, 0)
    b = true.inverse().apply(b_world)
    f, j = np.meshgrid(np.arange(frames), np.arange(joints), indexing='ij')
    pa, pb = a.reshape(-1, 3), b.reshape(-1, 3)
    w = np.ones(len(pa))
    plain = kabsch(pa, pb, w)
    assert plain.distance(true)[0] > 0.01
    t, inl, r = body_frame_fit(pa, pb, w, j.ravel(), heading[f.ravel()], plain,
                               np.ones(len(pa), bool))
    # the rotation and the horizontal placement exactly; a vertical offset turns with no
    # heading, so the trackers' mean vertical difference stays in the height (a stated limit)
    assert t.distance(true)[1] < 0.01
    np.testing.assert_allclose(t.translation[:2], true.translation[:2], atol=1e-4)
    assert abs(t.translation[2] - true.translation[2]) <= abs(offsets[:, 2].mean()) + 1e-4
    assert r.max() < 1e-4


def test_calibration_recovers_a_side_sensor_and_its_clock_offset():
    """The sensor model (scenario a: noise, offsets, self-occlusion, false positives) seen from
    the front and from the side, the side sensor's clock 0.31 s ahead and capturing 12 ms later
    in the motion: <= 3 cm, <= 2 deg, the offset within a third of a frame."""
    a, b, _ = synthetic_tracks(SIDE, seed=1, scenario='a', clock_offset_s=0.31, phase_s=0.012)
    c = calibrate(a, b, seed=1)
    d, ang = c.transform.distance(SIDE)
    assert d <= 0.03 and ang <= 2.0, c.transform
    assert abs(c.time_offset_s - 0.31) < 0.011
    assert c.inliers > 0.5 * c.pairs


def test_unrelated_tracks_are_refused_with_a_reason():
    rng = np.random.default_rng(2)
    n = 60
    stamps = np.arange(n) * 33_333_333
    a = Track(stamps, rng.normal(size=(n, NUM_JOINTS, 3)), np.full((n, NUM_JOINTS), TRACKED))
    b = Track(stamps + 10**12, rng.normal(size=(n, NUM_JOINTS, 3)),
              np.full((n, NUM_JOINTS), TRACKED))
    with pytest.raises(CalibrationError, match='overlap|same time'):
        calibrate(a, b)
