"""The hybrid PD controller of Shum & Ho 2012 (Sec. 6, Eq. 1-2) and Shum et al. 2013 (Eq. 16-17),
as plain numpy (no MuJoCo), so the equations can be tested by hand.

* Positional control (Eq. 1/16): for every joint ``F = Ke (p_t - p) + Kd (p'_t - p')``, the same
  gains for all joints, the force magnitude clamped to ``max_force``. It is applied as an external
  force at the joint point.
* Rotational control (Eq. 2/17): a torque about the segment's own axis only,
  ``T = Ke_i (theta_t - theta) + Kd_i (theta'_t - theta')``, per-segment gains, magnitude clamped to
  ``max_torque``. ``theta_t - theta`` is the twist (about the current segment axis) of the rotation
  from the current to the target segment orientation.

These functions are what the controllers (:mod:`physics_sim.controllers`) apply: ``explicit_pd``
calls :func:`point_wrenches` (Eq. 1 at every joint point as a wrench on its body, compiled with
numba where available, :func:`pd_force` + :func:`apply_at_points` otherwise) at every step, and
every controller takes Eq. 2 from :func:`twist_angle` and :func:`pd_twist_torque`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from skeleton_core import jit
from skeleton_core.geometry import quat_conjugate, quat_multiply, swing_twist
from skeleton_core.params import param


@dataclass
class Gains:
    """Controller gains and limits (the paper hand-tunes one Ke/Kd pair for all joints)."""

    ke: float = param(4000.0, 'Ke of Eq. 1 (N/m), shared by all joints', range=(0.0, 1e6),
                      name='kp')
    kd: float = param(100.0, 'Kd of Eq. 1 (N s/m), shared by all joints', range=(0.0, 1e4))
    max_force: float = param(800.0, 'bound on |F| of Eq. 1 (N)', range=(0.0, 1e5), public=False)
    twist_ke: float = param(400.0, 'Eq. 2 elasticity per unit axial inertia (1/s^2): Ke_i = '
                            'twist_kp * I_i (I_i = axial inertia + armature)', range=(0.0, 1e5),
                            name='twist_kp', public=False)
    twist_kd: float = param(40.0, 'Eq. 2 damping per unit axial inertia (1/s): Kd_i = twist_kd '
                            '* I_i', range=(0.0, 1e4), public=False)
    max_torque: float = param(50.0, 'bound on |T| of Eq. 2 (N m)', range=(0.0, 1e4), public=False)

    def validate(self) -> None:
        for name in ('ke', 'kd', 'max_force', 'twist_ke', 'twist_kd', 'max_torque'):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise ValueError(f'gain {name} must be finite and >= 0, got {v!r}')


def clamp_norm(v: np.ndarray, limit: float) -> np.ndarray:
    """Scale rows of ``v`` (..., 3) down so their norm is at most ``limit``."""
    v = np.asarray(v, float)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    scale = np.where(n > limit, limit / np.maximum(n, 1e-300), 1.0)
    return v * scale


def pd_force(p_target, p, v_target, v, ke: float, kd: float, max_force: float) -> np.ndarray:
    """Eq. 1: ``F = Ke (p_t - p) + Kd (v_t - v)`` per joint, |F| <= max_force. Shapes (N, 3)."""
    f = ke * (np.asarray(p_target, float) - p) + kd * (np.asarray(v_target, float) - v)
    return clamp_norm(f, max_force)


def twist_error(q_target, q_current, axis) -> np.ndarray:
    """Angle (rad, (-pi, pi]) about ``axis`` (N, 3) of the twist part of ``q_t * q^-1``."""
    rel = quat_multiply(q_target, quat_conjugate(q_current))
    rel = rel * np.where(rel[..., 3:4] < 0, -1.0, 1.0)  # shortest way round
    _, ang = swing_twist(rel, axis)
    return ang


def pd_twist_torque(angle_err, rate_target, rate, ke_i, kd_i, max_torque: float) -> np.ndarray:
    """Eq. 2 (scalar per segment): ``T = Ke_i dtheta + Kd_i (theta'_t - theta')`` clamped."""
    t = np.asarray(ke_i) * angle_err + np.asarray(kd_i) * (np.asarray(rate_target) - rate)
    return np.clip(t, -max_torque, max_torque)


def twist_drive(angle_err, rate_target, twist_ke: float, twist_kd: float, inertia) -> np.ndarray:
    """Eq. 2 without the measured rate: ``Ke_i dtheta + Kd_i theta'_t`` with ``Ke_i, Kd_i`` = gain
    per unit inertia times ``inertia`` -- the drive of a twist actuator, which subtracts
    ``Kd_i theta'`` and applies the bound at every step itself (``actuator_pd``)."""
    return (twist_ke * angle_err + twist_kd * rate_target) * inertia


def twist_angle(q_current, axis_forms, q_target) -> np.ndarray:
    """Eq. 2's error ``theta_t - theta`` (rad, shortest way round) of every segment from its current
    and target orientations (N, 4, w x y z; the target need not be unit) in one bilinear form:
    with ``rel = conj(q) * q_t``, its w part is ``q . q_t`` and its vector part along the
    segment's body-frame axis ``u`` is ``q^T M_u q_t`` (``axis_forms`` (N, 4, 4), from
    :func:`twist_forms`); the twist of ``q_t * conj(q)`` about the world axis ``R u`` is the same
    angle (:func:`twist_error` computes it the long way)."""
    rw = np.einsum('ij,ij->i', q_current, q_target)
    proj = np.einsum('ni,nij,nj->n', q_current, axis_forms, q_target)
    return 2.0 * np.arctan2(proj * np.copysign(1.0, rw), np.abs(rw))


def twist_forms(axes_local: np.ndarray) -> np.ndarray:
    """The (N, 4, 4) matrices ``M_u`` of :func:`twist_angle` for body-frame unit axes (N, 3):
    ``u . vec(conj(q) * q_t) = q^T M_u q_t`` (w x y z): M[0, 1:] = u, M[1:, 0] = -u,
    M[1:, 1:] = [u]x."""
    u = np.asarray(axes_local, float).reshape(-1, 3)
    m4 = np.zeros((len(u), 4, 4))
    m4[:, 0, 1:], m4[:, 1:, 0] = u, -u
    m4[:, 1, 2], m4[:, 1, 3] = -u[:, 2], u[:, 1]
    m4[:, 2, 1], m4[:, 2, 3] = u[:, 2], -u[:, 0]
    m4[:, 3, 1], m4[:, 3, 2] = -u[:, 1], u[:, 0]
    return m4


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (N, 3) arrays (np.cross is slow for small arrays)."""
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def apply_at_points(forces, points, com) -> np.ndarray:
    """Wrench (6,) per body at its centre of mass for forces (N, 3) applied at points (N, 3):
    MuJoCo's ``xfrc_applied`` layout [force, torque]."""
    forces = np.asarray(forces, float).reshape(-1, 3)
    arm = np.asarray(points, float).reshape(-1, 3) - com
    return np.concatenate([forces, cross_rows(arm, forces)], axis=1)


def point_velocity(cvel: np.ndarray, points: np.ndarray, root_com: np.ndarray) -> np.ndarray:
    """World linear velocity (N, 3) of points fixed on bodies with MuJoCo's com-based velocities
    ``cvel`` (N, 6: angular, linear at the subtree centre of mass ``root_com``)."""
    return cvel[:, 3:] + cross_rows(cvel[:, :3], points - root_com)


# ---------------------------------------------------------------------------------------------
# explicit_pd's step: Eq. 1 at every joint point, as wrenches on the bodies (numba / numpy twins)
# ---------------------------------------------------------------------------------------------
def _explicit_pd_numpy(xfrc, site_xpos, js, cvel, subtree_com, xipos, jb, jroot, p0, dp, v,
                       share, jchar, ke, kd, max_force, ub, sum_rows):
    sj = share[jchar][:, None]
    p_t, v_t = p0 + sj * dp, v * (sj < 1.0)
    pts = site_xpos[js]
    vel = point_velocity(cvel[jb], pts, subtree_com[jroot])
    with np.errstate(over='ignore', invalid='ignore', divide='ignore'):
        f = pd_force(p_t, pts, v_t, vel, ke, kd, max_force)
    xfrc[ub] += sum_rows @ apply_at_points(f, pts, xipos[jb])  # several joints share a body


def _explicit_pd_kernel(xfrc, site_xpos, js, cvel, subtree_com, xipos, jb, jroot, p0, dp, v,
                        share, jchar, ke, kd, max_force, ub, sum_rows):
    for n in range(js.shape[0]):
        s = share[jchar[n]]
        moving = 1.0 if s < 1.0 else 0.0
        site, b, r = js[n], jb[n], jroot[n]
        px, py, pz = site_xpos[site, 0], site_xpos[site, 1], site_xpos[site, 2]
        # point velocity: v_com + w x (p - subtree com)
        ax, ay, az = px - subtree_com[r, 0], py - subtree_com[r, 1], pz - subtree_com[r, 2]
        wx, wy, wz = cvel[b, 0], cvel[b, 1], cvel[b, 2]
        vx = cvel[b, 3] + (wy * az - wz * ay)
        vy = cvel[b, 4] + (wz * ax - wx * az)
        vz = cvel[b, 5] + (wx * ay - wy * ax)
        # Eq. 1
        fx = ke * (p0[n, 0] + s * dp[n, 0] - px) + kd * (v[n, 0] * moving - vx)
        fy = ke * (p0[n, 1] + s * dp[n, 1] - py) + kd * (v[n, 1] * moving - vy)
        fz = ke * (p0[n, 2] + s * dp[n, 2] - pz) + kd * (v[n, 2] * moving - vz)
        nrm = np.sqrt(fx * fx + fy * fy + fz * fz)
        if nrm > max_force:
            k = max_force / nrm
            fx, fy, fz = fx * k, fy * k, fz * k
        # as a wrench at the body's centre of mass
        cx, cy, cz = px - xipos[b, 0], py - xipos[b, 1], pz - xipos[b, 2]
        xfrc[b, 0] += fx
        xfrc[b, 1] += fy
        xfrc[b, 2] += fz
        xfrc[b, 3] += cy * fz - cz * fy
        xfrc[b, 4] += cz * fx - cx * fz
        xfrc[b, 5] += cx * fy - cy * fx


# explicit_pd_wrenches(xfrc, site_xpos, js, cvel, subtree_com, xipos, jb, jroot, p0, dp, v, share,
#                      jchar, ke, kd, max_force, ub, sum_rows):
# adds Eq. 1's force at every joint point, as a wrench on its body, to ``xfrc`` (MuJoCo's
# xfrc_applied). The targets are interpolated first: p_t = p0 + s dp, p'_t = v while s < 1 (0 after),
# s = share[jchar] per joint; the joint points are the sites ``js`` of ``site_xpos``, on bodies ``jb``
# whose kinematic roots are ``jroot``; ``ub`` / ``sum_rows`` (the distinct bodies and the rows that
# sum joints onto them) serve the numpy twin. Compiled by numba when available (skeleton_core.jit),
# else pd_force + apply_at_points in numpy: both give the same numbers (tests/test_physics_controller).
_explicit_pd_numba = jit.njit(_explicit_pd_kernel)
explicit_pd_wrenches = jit.pick(_explicit_pd_numba, _explicit_pd_numpy)



# ---------------------------------------------------------------------------------------------
# Eq. 2 torques of every segment about its axis between joint points (numba / numpy twins)
# ---------------------------------------------------------------------------------------------
def _twist_numpy(out, xquat, sb, tw_m, q0, dq, share, schar, pts, sc, sp, w, cvel, ke_i, kd_i,
                 max_torque):
    ss = share[schar]
    q_t = q0 + ss[:, None] * dq
    err = twist_angle(xquat[sb], tw_m, q_t)
    axes = pts[sc] - pts[sp]
    axes /= np.maximum(np.sqrt(np.einsum('ij,ij->i', axes, axes)), 1e-9)[:, None]
    rate_t = np.einsum('ij,ij->i', w, axes) * (ss < 1.0)
    rate = np.einsum('ij,ij->i', cvel[sb, :3], axes)
    out[:] = pd_twist_torque(err, rate_t, rate, ke_i, kd_i, max_torque)[:, None] * axes


def _twist_kernel(out, xquat, sb, tw_m, q0, dq, share, schar, pts, sc, sp, w, cvel, ke_i, kd_i,
                  max_torque):
    qt = np.empty(4)
    for n in range(sb.shape[0]):
        s = share[schar[n]]
        b = sb[n]
        for i in range(4):
            qt[i] = q0[n, i] + s * dq[n, i]
        rw = 0.0
        proj = 0.0
        for i in range(4):
            rw += xquat[b, i] * qt[i]
            row = 0.0
            for j in range(4):
                row += tw_m[n, i, j] * qt[j]
            proj += xquat[b, i] * row
        err = 2.0 * np.arctan2(proj * np.copysign(1.0, rw), abs(rw))
        c, p = sc[n], sp[n]
        ax, ay, az = pts[c, 0] - pts[p, 0], pts[c, 1] - pts[p, 1], pts[c, 2] - pts[p, 2]
        nrm = max(np.sqrt(ax * ax + ay * ay + az * az), 1e-9)
        ax, ay, az = ax / nrm, ay / nrm, az / nrm
        rate_t = (w[n, 0] * ax + w[n, 1] * ay + w[n, 2] * az) * (1.0 if s < 1.0 else 0.0)
        rate = cvel[b, 0] * ax + cvel[b, 1] * ay + cvel[b, 2] * az
        tau = ke_i[n] * err + kd_i[n] * (rate_t - rate)
        tau = min(max(tau, -max_torque), max_torque)
        out[n, 0] = tau * ax
        out[n, 1] = tau * ay
        out[n, 2] = tau * az


# twist_torques(out, xquat, sb, tw_m, q0, dq, share, schar, pts, sc, sp, w, cvel, ke_i, kd_i,
#               max_torque):
# writes Eq. 2's torque vector (N, 3) of every segment into ``out``: the target orientation
# q0 + s dq (w x y z, s = share[schar] per segment) against the body quaternion ``xquat[sb]``
# (:func:`twist_angle` with the forms ``tw_m``), about the unit axis from joint point ``pts[sp]``
# to ``pts[sc]``, the target twist rate ``w . axis`` while s < 1, the measured ``cvel[sb, :3] .
# axis``, per-segment gains ``ke_i``, ``kd_i``, bounded by ``max_torque``
# (:func:`pd_twist_torque`). One compiled loop instead of a dozen numpy calls on 19 rows a
# character, every few physics steps; the numpy twin computes the same numbers
# (tests/test_physics_controller).
_twist_numba = jit.njit(_twist_kernel)
twist_torques = jit.pick(_twist_numba, _twist_numpy)


# ---------------------------------------------------------------------------------------------
# body wrenches as generalized forces: what MuJoCo does with xfrc_applied, over the dof chains
# ---------------------------------------------------------------------------------------------
def _wrench_qfrc_kernel(qfrc, wr, bodies, dofadr, dofnum, body_parent, dof_parent, rootid, cdof,
                        xipos, subtree_com):
    qfrc[:] = 0.0
    for k in range(bodies.shape[0]):
        b = bodies[k]
        fx, fy, fz = wr[b, 0], wr[b, 1], wr[b, 2]
        tx, ty, tz = wr[b, 3], wr[b, 4], wr[b, 5]
        if fx == 0.0 and fy == 0.0 and fz == 0.0 and tx == 0.0 and ty == 0.0 and tz == 0.0:
            continue
        r = rootid[b]
        ox, oy, oz = (xipos[b, 0] - subtree_com[r, 0], xipos[b, 1] - subtree_com[r, 1],
                      xipos[b, 2] - subtree_com[r, 2])
        mx, my, mz = tx + oy * fz - oz * fy, ty + oz * fx - ox * fz, tz + ox * fy - oy * fx
        while b > 0 and dofnum[b] == 0:
            b = body_parent[b]
        if b == 0:
            continue
        i = dofadr[b] + dofnum[b] - 1
        while i >= 0:
            qfrc[i] += (cdof[i, 3] * fx + cdof[i, 4] * fy + cdof[i, 5] * fz
                        + cdof[i, 0] * mx + cdof[i, 1] * my + cdof[i, 2] * mz)
            i = dof_parent[i]


# wrench_qfrc(qfrc, wr, bodies, dofadr, dofnum, body_parent, dof_parent, rootid, cdof, xipos,
#             subtree_com): sets ``qfrc`` (nv,) to the generalized forces of the wrenches ``wr``
# (nbody, 6: force, torque at the body's centre of mass ``xipos``, xfrc_applied's layout) on
# ``bodies``: J^T [F; T] over each body's dof chain from MuJoCo's ``cdof`` (com-based motion
# subspaces about the ``subtree_com`` of the body's root), which is what MuJoCo computes from
# xfrc_applied (mj_applyFT) with two dense 3 x nv Jacobians a body: 114 bodies and nv 360 at six
# characters were 30 us of every step. Compiled only: without numba explicit_pd writes
# xfrc_applied (tests/test_physics_controller compares the two).
wrench_qfrc = jit.njit(_wrench_qfrc_kernel)


# ---------------------------------------------------------------------------------------------
# explicit_pd's whole control of one physics step in one compiled call
# ---------------------------------------------------------------------------------------------
def _explicit_pd_step_kernel(qfrc, wr, site_xpos, js, cvel, subtree_com, xipos, jb, jroot, p0, dp,
                             v, share, jchar, ke, kd, max_force, sb, twist, bodies, dofadr,
                             dofnum, body_parent, dof_parent, rootid, cdof):
    wr[:] = 0.0
    _explicit_pd_numba(wr, site_xpos, js, cvel, subtree_com, xipos, jb, jroot, p0, dp, v, share,
                       jchar, ke, kd, max_force, bodies, wr)
    for k in range(sb.shape[0]):
        b = sb[k]
        wr[b, 3] += twist[k, 0]
        wr[b, 4] += twist[k, 1]
        wr[b, 5] += twist[k, 2]
    wrench_qfrc(qfrc, wr, bodies, dofadr, dofnum, body_parent, dof_parent, rootid, cdof, xipos,
                subtree_com)


# explicit_pd_step(qfrc, wr, site_xpos, js, cvel, subtree_com, xipos, jb, jroot, p0, dp, v, share,
#                  jchar, ke, kd, max_force, sb, twist, bodies, dofadr, dofnum, body_parent,
#                  dof_parent, rootid, cdof): what explicit_pd does at every physics step, in the
# same order and with the same additions as its separate calls -- ``wr`` zeroed, Eq. 1's wrenches
# added (:func:`explicit_pd_wrenches`), the Eq. 2 torques ``twist`` (len(sb), 3) added to the
# segment bodies ``sb``' torque rows, and ``qfrc`` set to their generalized forces
# (:func:`wrench_qfrc`): one dispatch instead of two plus three numpy calls (each of which costs
# more than its arithmetic on 6 characters). Compiled only (explicit_pd without numba writes
# xfrc_applied); tests/test_physics_controller checks it gives the separate calls' bits.
explicit_pd_step = jit.njit(_explicit_pd_step_kernel)


__all__ = ['Gains', 'clamp_norm', 'pd_force', 'twist_error', 'pd_twist_torque', 'twist_drive',
           'twist_angle', 'twist_forms', 'cross_rows', 'apply_at_points', 'point_velocity',
           'explicit_pd_wrenches', 'twist_torques', 'wrench_qfrc', 'explicit_pd_step']
