"""The papers' PD equations on hand-computed cases (Shum & Ho 2012 Eq. 1-2, Shum 2013 Eq. 16-17)."""
import numpy as np
import pytest

from skeleton_core.model import standard_body

from physics_sim.controller import apply_at_points, pd_force, pd_twist_torque, twist_error
from physics_sim.posture import ball_qpos, quat_between, segment_quats_from_positions


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


def _two_characters(seconds: float):
    """Two explicit_pd characters 2 m apart in one world, simulated for ``seconds``."""
    from physics_sim.simulation import SimConfig, Simulation
    sim = Simulation(SimConfig(controller='explicit_pd', body_height=1.75))
    base = standard_body().rest_positions() + np.array([2.5, 0.0, -0.8])
    for uid, dy in ((1, -1.0), (2, 1.0)):
        sim.set_target(uid, base + [0.0, dy, 0.0])
    sim.advance(seconds)
    return sim


def test_explicit_pd_kernel_numba_and_numpy_agree():
    """explicit_pd's per-step Eq. 1 (compiled by numba) gives the numpy formulation's wrenches
    (pd_force + apply_at_points, summed per body) on a real MuJoCo state with random targets,
    clamped and unclamped forces, moving and held targets."""
    pytest.importorskip('numba')
    from physics_sim import controller as ctl
    sim = _two_characters(0.05)
    w = sim.worlds[0]
    d, ix = w.data, w.ix
    rng = np.random.default_rng(0)
    n = len(ix.jb)
    p0 = w.joint_points() + rng.normal(0.0, 0.1, (n, 3))
    dp, v = rng.normal(0.0, 0.05, (n, 3)), rng.normal(0.0, 1.0, (n, 3))
    share = np.array([0.3, 1.0])       # one character's target moving, the other's held
    out = {}
    for name, fn in (('numba', ctl._explicit_pd_numba), ('numpy', ctl._explicit_pd_numpy)):
        xfrc = np.zeros_like(d.xfrc_applied)
        fn(xfrc, d.site_xpos, ix.js, d.cvel, d.subtree_com, d.xipos, ix.jb, ix.jroot, p0, dp, v,
           share, ix.jchar, 4000.0, 100.0, 300.0, ix.ub, ix.sum_rows)
        out[name] = xfrc
    assert np.abs(out['numpy']).max() > 100.0
    np.testing.assert_allclose(out['numba'], out['numpy'], rtol=1e-12, atol=1e-9)
    # the numpy twin is Eq. 1 at the joint points, as wrenches at the bodies' centres of mass
    pts = d.site_xpos[ix.js]
    sj = share[ix.jchar][:, None]
    vel = ctl.point_velocity(d.cvel[ix.jb], pts, d.subtree_com[ix.jroot])
    f = pd_force(p0 + sj * dp, pts, v * (sj < 1.0), vel, 4000.0, 100.0, 300.0)
    assert np.linalg.norm(f, axis=1).max() <= 300.0 + 1e-9
    ref = np.zeros_like(d.xfrc_applied)
    np.add.at(ref, ix.jb, apply_at_points(f, pts, d.xipos[ix.jb]))
    np.testing.assert_allclose(out['numpy'], ref, rtol=1e-12, atol=1e-9)


def test_twist_kernel_numba_and_numpy_agree():
    """Eq. 2 about the axes between joint points (compiled by numba) gives the numpy
    formulation's torques (twist_angle + pd_twist_torque) on a real MuJoCo state with random
    target orientations and rates, bounded and unbounded torques, moving and held targets; the
    numpy twin is what World.twist_torques computes the long way (axis sites, the actuators'
    path)."""
    pytest.importorskip('numba')
    from physics_sim import controller as ctl
    sim = _two_characters(0.05)
    w = sim.worlds[0]
    d, ix = w.data, w.ix
    rng = np.random.default_rng(1)
    n = len(ix.sb)
    q0 = d.xquat[ix.sb] + rng.normal(0.0, 0.3, (n, 4))
    dq, wt = rng.normal(0.0, 0.05, (n, 4)), rng.normal(0.0, 3.0, (n, 3))
    d.cvel[:] = rng.normal(0.0, 2.0, d.cvel.shape)
    share = np.array([0.3, 1.0])       # one character's target moving, the other's held
    pts = w.joint_points()
    ke_i, kd_i = 400.0 * ix.tw_i, 40.0 * ix.tw_i
    out = {}
    for name, fn in (('numba', ctl._twist_numba), ('numpy', ctl._twist_numpy)):
        out[name] = np.zeros((n, 3))
        fn(out[name], d.xquat, ix.sb, ix.tw_m, q0, dq, share, ix.schar, pts, ix.sc, ix.sp, wt,
           d.cvel, ke_i, kd_i, 2.0)
    tau = np.linalg.norm(out['numpy'], axis=1)
    assert (tau > 1.999).sum() > 5 and (tau < 1.99).sum() > 5   # bounded and not
    np.testing.assert_allclose(out['numba'], out['numpy'], rtol=1e-12, atol=1e-12)
    # the numpy twin is Eq. 2: twist error and rates about the joint-point axis, bounded
    axes = pts[ix.sc] - pts[ix.sp]
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    ss = share[ix.schar]
    err = ctl.twist_angle(d.xquat[ix.sb], ix.tw_m, q0 + ss[:, None] * dq)
    rate_t = np.sum(wt * axes, axis=1) * (ss < 1.0)
    rate = np.sum(d.cvel[ix.sb, :3] * axes, axis=1)
    want = np.clip(ke_i * err + kd_i * (rate_t - rate), -2.0, 2.0)[:, None] * axes
    np.testing.assert_allclose(out['numpy'], want, rtol=1e-9, atol=1e-12)


def test_wrench_qfrc_is_what_mujoco_makes_of_xfrc_applied():
    """explicit_pd's wrenches handed to MuJoCo as generalized forces (compiled, over each body's
    dof chain) are MuJoCo's own from the same wrenches as xfrc_applied: mj_applyFT at every body's
    centre of mass, and the same accelerations from mj_forward."""
    pytest.importorskip('numba')
    import mujoco
    from physics_sim import controller as ctl
    from physics_sim.simulation import SimConfig, Simulation
    sim = Simulation(SimConfig(controller='explicit_pd', body_height=1.75))
    base = standard_body().rest_positions() + np.array([2.5, 0.0, -0.8])
    for uid, dy in ((1, -0.4), (2, 0.4)):
        sim.set_target(uid, base + [0.0, dy, 0.0])
    sim.advance(0.1)
    m, d, ix = sim.model, sim.data, sim.worlds[0].ix
    mujoco.mj_forward(m, d)   # cdof, xipos of the current qpos (the controller: after mj_step1)
    rng = np.random.default_rng(2)
    wr = np.zeros_like(d.xfrc_applied)
    bodies = np.union1d(ix.jb, ix.sb).astype(np.int64)
    wr[bodies] = rng.normal(0.0, 50.0, (len(bodies), 6))
    wr[bodies[3]] = 0.0                  # a body without a wrench
    qfrc = np.full(m.nv, np.nan)         # every entry written
    ctl.wrench_qfrc(qfrc, wr, bodies, m.body_dofadr, m.body_dofnum, m.body_parentid,
                    m.dof_parentid, m.body_rootid, d.cdof, d.xipos, d.subtree_com)
    ref = np.zeros(m.nv)
    for b in bodies:
        mujoco.mj_applyFT(m, d, wr[b, :3].copy(), wr[b, 3:].copy(), d.xipos[b].copy(), int(b), ref)
    assert np.abs(ref).max() > 10.0
    np.testing.assert_allclose(qfrc, ref, rtol=1e-10, atol=1e-9)
    d.qfrc_applied[:] = qfrc
    d.xfrc_applied[:] = 0.0
    mujoco.mj_forward(m, d)
    via_qfrc = d.qacc.copy()
    d.qfrc_applied[:] = 0.0
    d.xfrc_applied[:] = wr
    mujoco.mj_forward(m, d)
    np.testing.assert_allclose(via_qfrc, d.qacc, rtol=1e-8, atol=1e-6)


def test_explicit_pd_step_is_the_separate_calls_bit_for_bit():
    """explicit_pd's one compiled call per step (Eq. 1, the Eq. 2 torques on the segment bodies,
    the generalized forces) gives exactly the bits of the separate calls it replaced: Eq. 1 into
    zeroed wrenches, the torques added to the segment rows, wrench_qfrc -- on a real state with
    random targets, torques and a stale wrench buffer."""
    pytest.importorskip('numba')
    from physics_sim import controller as ctl
    sim = _two_characters(0.05)
    w = sim.worlds[0]
    m, d, ix = w.model, w.data, w.ix
    rng = np.random.default_rng(3)
    n = len(ix.jb)
    p0 = w.joint_points() + rng.normal(0.0, 0.1, (n, 3))
    dp, v = rng.normal(0.0, 0.05, (n, 3)), rng.normal(0.0, 1.0, (n, 3))
    share = np.array([0.3, 1.0])
    twist = rng.normal(0.0, 5.0, (len(ix.sb), 3))
    bodies = np.union1d(ix.jb, ix.sb).astype(np.int64)
    ref_wr = np.zeros_like(d.xfrc_applied)
    ctl.explicit_pd_wrenches(ref_wr, d.site_xpos, ix.js, d.cvel, d.subtree_com, d.xipos, ix.jb,
                             ix.jroot, p0, dp, v, share, ix.jchar, 4000.0, 100.0, 300.0, ix.ub,
                             ix.sum_rows)
    ref_wr[ix.sb, 3:] += twist
    ref = np.zeros(m.nv)
    ctl.wrench_qfrc(ref, ref_wr, bodies, m.body_dofadr, m.body_dofnum, m.body_parentid,
                    m.dof_parentid, m.body_rootid, d.cdof, d.xipos, d.subtree_com)
    wr = rng.normal(0.0, 9.0, d.xfrc_applied.shape)   # last step's: zeroed by the call
    qfrc = np.full(m.nv, np.nan)
    ctl.explicit_pd_step(qfrc, wr, d.site_xpos, ix.js, d.cvel, d.subtree_com, d.xipos, ix.jb,
                         ix.jroot, p0, dp, v, share, ix.jchar, 4000.0, 100.0, 300.0, ix.sb, twist,
                         bodies, m.body_dofadr, m.body_dofnum, m.body_parentid, m.dof_parentid,
                         m.body_rootid, d.cdof)
    assert np.abs(ref).max() > 10.0
    assert np.array_equal(wr, ref_wr) and np.array_equal(qfrc, ref)


def test_explicit_pd_push_acts_for_its_duration_only():
    """With the compiled step, xfrc_applied holds only the pushes: set while a push lasts,
    cleared at the first step after it ended."""
    from skeleton_core import jit
    if not jit.enabled():
        pytest.skip('without numba explicit_pd writes its own wrenches to xfrc_applied')
    from physics_sim.simulation import SimConfig, Simulation
    sim = Simulation(SimConfig(controller='explicit_pd', body_height=1.75))
    sim.set_target(1, standard_body().rest_positions() + np.array([2.5, 0.0, -0.8]))
    sim.advance(0.1)
    w = sim.worlds[0]
    spine = w.chars[0].seg_body[sim.segment_index('Spine')]
    sim.apply_push(1, 'Spine', (200.0, 0.0, 0.0), 0.05)
    sim.advance(1 / 30)
    assert w.data.xfrc_applied[spine, 0] == 200.0
    sim.advance(0.1)
    assert not w.data.xfrc_applied.any()


def test_explicit_pd_slow_control_from_the_sites_is_bit_identical():
    """Eq. 2 and the foot pins computed from MuJoCo's site arrays (the compiled step's path) give
    exactly the states of the path through World.targets_at / joint_points / twist_torques, with
    feet pinned and released along the way (three characters side by side, stepping)."""
    from skeleton_core import jit
    if not jit.enabled():
        pytest.skip('the site path is the compiled step\'s')
    from physics_sim.simulation import SimConfig, Simulation
    sims = [Simulation(SimConfig(controller='explicit_pd', body_height=1.75)) for _ in range(2)]
    base = standard_body().rest_positions() + np.array([2.5, 0.0, -0.8])
    for k in range(40):
        for sim in sims:
            for uid in (1, 2, 3):
                p = base + [0.0, 0.8 * (uid - 2), 0.0]
                p = p + 0.04 * np.sin(0.3 * k + uid + np.arange(20)[:, None])
                p[[14, 15, 18, 19], 2] += 0.12 * max(0.0, np.sin(0.25 * k + uid))  # steps
                sim.set_target(uid, p, None, k * 33_333_333)
            ctl = sim.worlds[0].controller
            assert (ctl._sc_site is not None) == (k == 0 or sim is sims[0])
            if sim is sims[1]:
                ctl._sc_site = None           # the generic path (no joint sites)
            sim.advance(1 / 30)
    assert sims[0].counters['pins'] > 3 and sims[0].counters == sims[1].counters
    a, b = sims[0].states(), sims[1].states()
    for uid in a:
        assert np.array_equal(a[uid].positions, b[uid].positions)
        assert np.array_equal(a[uid].orientations, b[uid].orientations)


def test_segment_quats_numba_and_python_agree():
    """Target orientations from joint positions (one call per target frame and character):
    the numba kernel gives the scalar Python's quaternions on random postures, on a degenerate
    one (a zero-length segment, a segment pointing against its rest direction) and with two
    bodies alternating (the per-body cache)."""
    pytest.importorskip('numba')
    from physics_sim import posture
    bodies = (standard_body(), standard_body(1.6))
    rng = np.random.default_rng(4)
    for i in range(40):
        body = bodies[i % 2]
        p = body.rest_positions() + rng.normal(0.0, 0.15, (20, 3))
        if i == 7:
            p[7] = p[6]                      # HandLeft on WristLeft: zero length
            p[5] = p[4] - (p[5] - p[4])      # ElbowLeft turned back
        a = posture._segment_quats_compiled(p, body.rest_offsets)
        b = posture._segment_quats_python(p, body.rest_offsets)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1.0, atol=1e-12)
