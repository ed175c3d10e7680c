"""The papers' PD equations on hand-computed cases (Shum & Ho 2012 Eq. 1-2, Shum 2013 Eq. 16-17)."""
import numpy as np
import pytest

from skeleton_core.model import standard_body

from physics_sim.controller import (apply_at_points, ball_qpos, pd_force, pd_twist_torque,
                                    quat_between, segment_quats_from_positions, twist_error)


def _axis_angle(axis, ang):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.concatenate([a * np.sin(ang / 2), [np.cos(ang / 2)]])


def test_pd_force_direction_and_magnitude():
    p_t = np.array([[0.1, 0.0, 0.0], [0.0, 0.0, 0.0]])
    p = np.zeros((2, 3))
    v_t = np.zeros((2, 3))
    v = np.array([[0.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    f = pd_force(p_t, p, v_t, v, ke=100.0, kd=10.0, max_force=1e6)
    np.testing.assert_allclose(f[0], [10.0, 0.0, 0.0])   # Ke * 0.1 along the error
    np.testing.assert_allclose(f[1], [0.0, -20.0, 0.0])  # Kd opposes the velocity


def test_pd_force_clamped_keeps_direction():
    f = pd_force(np.array([[3.0, 4.0, 0.0]]), np.zeros((1, 3)), np.zeros((1, 3)),
                 np.zeros((1, 3)), ke=1000.0, kd=0.0, max_force=50.0)
    assert np.linalg.norm(f[0]) == pytest.approx(50.0)
    np.testing.assert_allclose(f[0] / 50.0, [0.6, 0.8, 0.0])


def test_twist_error_only_counts_rotation_about_the_axis():
    z = np.array([[0.0, 0.0, 1.0]])
    ident = np.array([[0.0, 0.0, 0.0, 1.0]])
    twist = _axis_angle([0, 0, 1], 0.3)[None]
    swing = _axis_angle([1, 0, 0], 0.5)[None]
    assert twist_error(twist, ident, z)[0] == pytest.approx(0.3)
    assert twist_error(swing, ident, z)[0] == pytest.approx(0.0, abs=1e-12)
    assert twist_error(ident, twist, z)[0] == pytest.approx(-0.3)


def test_twist_torque_gains_and_clamp():
    t = pd_twist_torque(np.array([0.2, 1.0]), np.array([0.0, 0.0]), np.array([1.0, 0.0]),
                        np.array([10.0, 10.0]), np.array([0.5, 0.5]), max_torque=5.0)
    np.testing.assert_allclose(t, [10 * 0.2 - 0.5 * 1.0, 5.0])


def test_force_at_point_gives_torque_about_com():
    w = apply_at_points(np.array([[0.0, 0.0, 10.0]]), np.array([[1.0, 0.0, 0.0]]),
                        np.zeros((1, 3)))
    np.testing.assert_allclose(w[0], [0, 0, 10, 0, -10, 0])


def test_rest_pose_gives_identity_orientations_and_ball_quats():
    body = standard_body()
    q = segment_quats_from_positions(body.rest_positions(), body.rest_offsets)
    np.testing.assert_allclose(np.abs(q[:, 3]), 1.0, atol=1e-9)
    np.testing.assert_allclose(ball_qpos(q)[:, 0], 1.0, atol=1e-9)


def test_quat_between_maps_vectors():
    from skeleton_core.geometry import quat_rotate
    a = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]])
    b = np.array([[0, 1.0, 0], [0, 0, -1.0], [0, 0.6, 0.8]])
    q = quat_between(a, b)
    np.testing.assert_allclose(quat_rotate(q, a), b, atol=1e-9)
