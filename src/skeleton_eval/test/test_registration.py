"""Resampling, Kabsch and the lag + rigid registration of a session."""
import numpy as np
import pytest

from skeleton_eval import registration as R
from skeleton_core.model import standard_body


def _rot(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def test_resample_linear_and_nan_outside():
    t = np.arange(5) / 100.0
    v = np.stack([t * 2.0, -t], -1)
    out = R.resample(v, t, np.array([-0.01, 0.005, 0.04, 0.05]))
    np.testing.assert_allclose(out[1], (0.01, -0.005))
    np.testing.assert_allclose(out[2], (0.08, -0.04))
    assert np.isnan(out[0]).all() and np.isnan(out[3]).all()


def test_kabsch_recovers_rotation_and_translation():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(50, 3))
    rot = _rot((0.3, -1.0, 0.5), 2.2)
    t = np.array([3.4, 0.1, -0.05])
    b = a @ rot.T + t
    a[5] = np.nan  # ignored
    r, tt = R.kabsch(a, b)
    np.testing.assert_allclose(r, rot, atol=1e-9)
    np.testing.assert_allclose(tt, t, atol=1e-9)
    assert np.isclose(np.linalg.det(r), 1.0)


def test_kabsch_never_returns_a_reflection():
    rng = np.random.default_rng(2)
    a = rng.normal(size=(20, 3))
    b = a * np.array([1.0, 1.0, -1.0])  # mirror image: best proper rotation, not the mirror
    r, _ = R.kabsch(a, b)
    assert np.isclose(np.linalg.det(r), 1.0)


def _motion(seconds, rate, phase):
    """A moving 20-joint skeleton: rest pose + per-joint sinusoids (m)."""
    t = np.arange(int(seconds * rate)) / rate
    rest = standard_body().rest_positions()
    rng = np.random.default_rng(phase)
    f = rng.uniform(0.3, 1.2, size=(20, 3))
    ph = rng.uniform(0, 2 * np.pi, size=(20, 3))
    amp = rng.uniform(0.02, 0.15, size=(20, 3))
    amp[0] = 0.01
    return rest + amp * np.sin(2 * np.pi * f * t[:, None, None] + ph)


def test_register_session_recovers_transform_and_lags():
    rot = _rot((0, 0, 1), np.pi) @ _rot((1, 0, 0), 0.05)
    trans = np.array([3.42, -0.1, 0.04])
    lags = [0.12, -0.2, 0.05]
    kin, ref = [], []
    for i, lag in enumerate(lags):
        r100 = _motion(4.0, 100.0, i)                      # reference, 100 Hz, 4 s
        tk = np.arange(int(3.0 * 30)) / 30.0 + 0.5         # Kinect clip: 3 s inside it
        k = R.resample(r100, np.arange(len(r100)) / 100.0, tk + lag)
        kin.append(k @ rot.T + trans)
        # the reference recording starts 0.5 s earlier: Kinect t=0 is reference t=0.5+lag
        ref.append(r100)
    reg = R.register_session(kin, ref, max_lag=0.9)
    np.testing.assert_allclose(reg.rotation, rot, atol=1e-3)
    np.testing.assert_allclose(reg.translation, trans, atol=2e-3)
    np.testing.assert_allclose(reg.lags, np.array(lags) + 0.5, atol=0.011)
    assert np.nanmax(reg.residual_per_joint) < 0.005


def test_kabsch_needs_three_points():
    with pytest.raises(ValueError):
        R.kabsch(np.zeros((2, 3)), np.zeros((2, 3)))


def test_split_setups_groups_movements_with_the_same_transform():
    """Four movements: three share the session's transform, one was recorded with the lab origin
    moved by 0.7 m: it gets a setup of its own."""
    rot = _rot((0, 0, 1), np.pi)
    kin, ref, groups = [], [], []
    for m in range(4):
        idx = []
        for rep in range(2):
            r = _motion(2.0, 100.0, 10 * m + rep)
            k = R.resample(r, np.arange(len(r)) / 100.0, np.arange(45) / 30.0 + 0.3)
            trans = np.array([3.4, -0.1, 0.0]) + (np.array([-0.7, 0.1, 0.0]) if m == 2 else 0)
            kin.append(k @ rot.T + trans)
            ref.append(r)
            idx.append(len(kin) - 1)
        groups.append(idx)
    setups = R.split_setups(groups, kin, ref)
    assert sorted(map(sorted, setups)) == [[0, 1, 2, 3, 6, 7], [4, 5]]
    assert len(setups[0]) == 6  # the consensus first
