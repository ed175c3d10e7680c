"""The simulated character: settling on a static target, foot pins, pushes, bad targets, several
characters, held objects, conflicting virtual joints, dodging, frames."""
import mujoco
import numpy as np
import pytest

from skeleton_core.model import (ANKLE_LEFT, FOOT_LEFT, HAND_LEFT, HAND_RIGHT, HIP_LEFT, KNEE_LEFT,
                                 standard_body, segment_lengths)

from physics_sim.controller import Gains
from physics_sim.mjcf_world import ObjectSpec
from physics_sim.simulation import SensorPose, SimConfig, Simulation

BODY = standard_body()
SENSOR = SensorPose(0.8, 0.0)


def tpose_sensor(shift=(2.5, 0.0, 0.0)):
    """The standard T-pose, feet on the floor, as the sensor (0.8 m high) sees it."""
    return BODY.rest_positions() + np.array(shift) - np.array([0.0, 0.0, 0.8])


def run(sim, target, seconds, uid=1):
    st = None
    for _ in range(int(round(seconds * 30))):
        st = sim.step({uid: target})[uid]
    return st


@pytest.mark.parametrize('controller', ['actuator_pd', 'explicit_pd', 'mocap_constraints'])
def test_static_tpose_settles(controller):
    sim = Simulation(SimConfig(controller=controller, body_height=1.75))
    st = run(sim, tpose_sensor(), 1.0)
    err = np.linalg.norm(st.positions - st.target_world, axis=1)
    assert err.mean() < 0.03 and err.max() < 0.05
    np.testing.assert_allclose(segment_lengths(st.positions), BODY.segment_lengths, atol=1e-6)
    # reported back in the sensor frame, next to the input
    assert np.abs(st.positions_sensor - tpose_sensor()).max() < 0.05
    # settled: nearly at rest
    root_v = sim.data.qvel[sim.characters[1].root_dadr:sim.characters[1].root_dadr + 3]
    assert np.linalg.norm(root_v) < 0.05
    assert sim.counters['nan_reset'] == 0


def test_point_velocity_formula_matches_mujoco():
    sim = Simulation(SimConfig(body_height=1.75))
    run(sim, tpose_sensor(), 0.1)
    sim.apply_push(1, 'ElbowLeft', (0.0, 50.0, 80.0), 0.05)
    sim.advance(0.03)
    m, d = sim.model, sim.data
    ch = sim.characters[1]
    pts = ch.joint_points(d)
    for j in (HAND_LEFT, KNEE_LEFT):
        b = ch.joint_body[j]
        cv = d.cvel[b]
        v = cv[3:] + np.cross(cv[:3], pts[j] - d.subtree_com[m.body_rootid[b]])
        res = np.zeros(6)
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, b, res, 0)
        v_ref = res[3:] + np.cross(res[:3], pts[j] - d.xipos[b])  # object-centred = COM
        np.testing.assert_allclose(v, v_ref, atol=1e-9)


def test_feet_pinned_when_standing_released_when_lifted():
    sim = Simulation(SimConfig(body_height=1.75))
    st = run(sim, tpose_sensor(), 0.3)
    assert st.pinned == {'FootLeft': True, 'FootRight': True}
    lifted = tpose_sensor()
    # hip flexed 60 degrees, shank vertical: the foot comes ~0.2 m off the floor
    thigh = np.linalg.norm(BODY.rest_offsets[KNEE_LEFT])
    lifted[KNEE_LEFT] = lifted[HIP_LEFT] + thigh * np.array([np.sin(1.05), 0.0, -np.cos(1.05)])
    lifted[ANKLE_LEFT] = lifted[KNEE_LEFT] + BODY.rest_offsets[ANKLE_LEFT]
    lifted[FOOT_LEFT] = lifted[ANKLE_LEFT] + BODY.rest_offsets[FOOT_LEFT]
    st = run(sim, lifted, 0.6)
    assert st.pinned == {'FootLeft': False, 'FootRight': True}
    assert st.positions[FOOT_LEFT, 2] > 0.15
    st = run(sim, tpose_sensor(), 1.0)
    assert st.pinned == {'FootLeft': True, 'FootRight': True}


def test_push_changes_velocities_and_pinned_foot_holds():
    sim = Simulation(SimConfig(body_height=1.75))
    run(sim, tpose_sensor(), 0.3)
    ch = sim.characters[1]
    foot0 = ch.joint_points(sim.data)[FOOT_LEFT].copy()
    v0 = sim.data.qvel[ch.dofs].copy()
    sim.apply_push(1, 'ShoulderCenter', (400.0, 0.0, 0.0), 0.1)
    sim.advance(0.1)
    v1 = sim.data.qvel[ch.dofs]
    assert sim.data.qvel[ch.root_dadr] > 0.1        # pushed forward
    assert np.abs(v1 - v0).max() > 0.3
    assert np.linalg.norm(ch.joint_points(sim.data)[FOOT_LEFT] - foot0) < 0.01
    with pytest.raises(ValueError):
        sim.apply_push(1, 'Nose', (1, 0, 0), 0.1)
    with pytest.raises(ValueError):
        sim.apply_push(7, 'Spine', (1, 0, 0), 0.1)


@pytest.mark.parametrize('bad', [np.full((20, 3), np.nan), np.zeros((19, 3)), np.zeros(60),
                                 'garbage'])
def test_bad_targets_refused_without_changing_the_simulation(bad):
    sim = Simulation(SimConfig(body_height=1.75))
    run(sim, tpose_sensor(), 0.1)
    qpos, t = sim.data.qpos.copy(), sim.time
    target_before = sim.characters[1].cur.positions.copy()
    with pytest.raises(ValueError):
        sim.step({1: tpose_sensor(), 2: bad})
    assert sim.time == t and 2 not in sim.characters
    np.testing.assert_array_equal(sim.data.qpos, qpos)
    np.testing.assert_array_equal(sim.characters[1].cur.positions, target_before)
    assert sim.counters['refused_target'] == 1


def test_several_characters_spawn_and_leave():
    sim = Simulation(SimConfig(body_height=1.75))
    for _ in range(15):
        states = sim.step({1: tpose_sensor((2.5, -1.2, 0.0)), 2: tpose_sensor((2.5, 1.2, 0.0))})
    assert set(states) == {1, 2}
    p1_before = states[1].positions.copy()
    sim.remove_character(2)
    states = sim.step({1: tpose_sensor((2.5, -1.2, 0.0))})
    assert set(states) == {1}
    assert np.abs(states[1].positions - p1_before).max() < 0.02  # state kept across rebuild


def test_held_mace_follows_the_hand():
    sim = Simulation(SimConfig(body_height=1.75),
                     objects=[ObjectSpec('mace', 'mace', (1.0, 1.0, 0.5), (0.3, 0.06), 2.0)])
    run(sim, tpose_sensor(), 0.1)
    sim.hold(1, 'mace', 'right')
    run(sim, tpose_sensor(), 0.5)
    grip = sim.data.xpos[sim.obj_id('mace')] + \
        sim.data.xmat[sim.obj_id('mace')].reshape(3, 3) @ np.array([0, 0, -0.3])
    hand = sim.characters[1].joint_points(sim.data)[HAND_RIGHT]
    assert np.linalg.norm(grip - hand) < 0.01
    held_z = sim.data.xpos[sim.obj_id('mace')][2]
    sim.release('mace')
    run(sim, tpose_sensor(), 0.5)
    assert sim.data.xpos[sim.obj_id('mace')][2] < held_z - 0.2  # no longer held: it drops


def test_conflicting_virtual_joints_stay_finite_and_are_reported():
    sim = Simulation(SimConfig(body_height=1.75))
    run(sim, tpose_sensor(), 0.2)
    # feet pinned 3 m apart: impossible for 0.9 m legs
    sim.pin(1, 'FootLeft', (0.0, 1.5, 0.04))
    sim.pin(1, 'FootRight', (0.0, -1.5, 0.04))
    st = run(sim, tpose_sensor(), 0.5)
    assert np.all(np.isfinite(st.positions))
    assert sim.counters['constraint_conflict'] > 0
    assert sim.counters['virtual_joint_released'] > 0
    np.testing.assert_allclose(segment_lengths(st.positions), BODY.segment_lengths, atol=1e-4)


def test_dodge_raises_forearms_to_the_head():
    heights = {}
    for dodge in (False, True):
        sim = Simulation(SimConfig(body_height=1.75, dodge=dodge))
        run(sim, tpose_sensor(), 0.2)
        sim.throw_at(1, speed=8.0, distance=3.0)
        best = np.inf
        for _ in range(12):
            st = sim.step({1: tpose_sensor()})[1]
            head = st.positions[3]
            best = min(best, np.linalg.norm(st.positions[HAND_LEFT] - head),
                       np.linalg.norm(st.positions[HAND_RIGHT] - head))
        heights[dodge] = best
    assert heights[True] < 0.35 and heights[False] > 0.6  # hands raised to ~0.26 m of the head


def test_sensor_pose_round_trip_and_pitch():
    s = SensorPose(0.8, np.deg2rad(10.0), 0.03)
    p = np.random.default_rng(0).normal(size=(20, 3))
    np.testing.assert_allclose(s.to_sensor(s.to_world(p)), p, atol=1e-12)
    fwd = s.to_world(np.array([[1.0, 0.0, 0.0]]))[0]
    assert fwd[2] < 0.8 + 0.03  # tilted down: a point straight ahead is below the sensor


def test_physics_method_processes_frames_and_registers():
    from skeleton_core.conversions import SkeletonFrame
    from physics_sim.methods import PhysicsMethod, register
    m = PhysicsMethod(config=SimConfig(body_height=1.75))
    out = None
    for i in range(20):
        f = SkeletonFrame(positions=tpose_sensor(), tracking_state=np.full(20, 2, np.uint8),
                          user_id=3, stamp_ns=1_000_000_000 + i * 33_333_333, frame_id='kinect_depth')
        out = m.process(f)
    assert out.user_id == 3 and out.frame_id == 'kinect_depth' and out.stamp_ns == f.stamp_ns
    assert np.abs(out.positions - tpose_sensor()).max() < 0.05
    bad = f.copy(positions=np.full((20, 3), np.nan))
    assert m.process(bad) is None                       # refused, no crash
    lost = f.copy(tracking_state=np.where(np.arange(20) == 7, 0, 2).astype(np.uint8))
    lost.positions[7] = 0.0                             # an untracked joint's garbage
    out = m.process(lost)
    assert np.linalg.norm(out.positions[7] - tpose_sensor()[7]) < 0.1
    m.reset()
    assert not m.sim.characters
    registry = pytest.importorskip('skeleton_eval.registry')
    assert register()
    assert {'physics', 'physics_raw'} <= set(registry.available_methods())
    raw = registry.make_method('physics_raw')
    assert raw.name == 'physics_raw' and raw.process(f) is not None


def test_twist_torque_turns_a_segment_about_its_axis():
    """Eq. 2: a target twisted about the forearm axis turns the simulated forearm that way;
    with the per-segment gain scaled to 0 it does not."""
    from skeleton_core.model import SEGMENT_OF_JOINT, SEGMENTS, WRIST_LEFT
    from physics_sim.posture import segment_quats_from_positions
    k = SEGMENT_OF_JOINT[WRIST_LEFT]
    twists = {}
    for scale in (1.0, 0.0):
        ts = np.ones(19)
        ts[k] = scale
        sim = Simulation(SimConfig(body_height=1.75, twist_scale=ts))
        p = tpose_sensor()
        q = segment_quats_from_positions(BODY.rest_positions(), BODY.rest_offsets)
        half = 0.4  # rad about the forearm axis (+y in the T-pose)
        ori = np.tile([0.0, 0.0, 0.0, 1.0], (20, 1))
        ori[[c for _, c in SEGMENTS]] = q
        sim.step({1: (p, ori)})                      # spawn untwisted
        ori[WRIST_LEFT] = [0.0, np.sin(half / 2), 0.0, np.cos(half / 2)]
        for _ in range(30):
            sim.step({1: (p, ori)})
        qs = sim.characters[1].segment_quats(sim.data)[k]
        twists[scale] = 2 * np.arctan2(qs[1], qs[3])
    assert twists[1.0] > 0.2 and abs(twists[0.0]) < 0.05


def _point_velocities(m, d, ch, pts):
    """World velocities (20, 3) of the joint points, from MuJoCo's own body velocities."""
    out = np.zeros((20, 3))
    res = np.zeros(6)
    for j in range(20):
        b = ch.joint_body[j]
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, b, res, 0)
        out[j] = res[3:] + np.cross(res[:3], pts[j] - d.xipos[b])
    return out


def test_actuator_pd_applies_eq1_and_eq2_at_every_step():
    """actuator_pd's actuators produce Ke (p_t - p) + Kd (p'_t - p') at each joint point, bounded
    per axis by max_force, and Eq. 2's damping about each segment axis, bounded by max_torque."""
    sim = Simulation(SimConfig(controller='actuator_pd', body_height=1.75,
                               gains=Gains(ke=3000.0, kd=80.0, max_force=150.0)))
    run(sim, tpose_sensor(), 0.2)
    sim.apply_push(1, 'ElbowLeft', (0.0, 80.0, 60.0), 0.05)
    sim.advance(0.03)                       # joints moving
    m, d = sim.model, sim.data
    ch = sim.characters[1]
    g = sim.config.gains
    rng = np.random.default_rng(3)
    pts = ch.joint_points(d)
    p_t = pts + rng.normal(0.0, 0.05, (20, 3))
    v_t = rng.normal(0.0, 0.5, (20, 3))
    d.act[sim.world.controller.act_adr] = p_t + g.kd / g.ke * v_t      # what the simulation sets
    tw_ctrl = rng.normal(0.0, 20.0, 19)
    d.ctrl[ch.twist_actuator_ids] = tw_ctrl
    mujoco.mj_forward(m, d)
    pts = ch.joint_points(d)
    f = g.ke * (p_t - pts) + g.kd * (v_t - _point_velocities(m, d, ch, pts))
    assert np.abs(f).max() > g.max_force    # some components are bounded ...
    assert np.abs(f).min() < g.max_force    # ... and some are not
    np.testing.assert_allclose(d.actuator_force[ch.actuator_ids],
                               np.clip(f, -g.max_force, g.max_force), rtol=1e-6, atol=1e-6)
    # twist actuators: ctrl - Kd_i * (angular velocity about the segment axis)
    axes = ch.segment_axes(pts)
    rate = np.sum(d.cvel[ch.seg_body, :3] * axes, axis=1)
    tau = tw_ctrl - g.twist_kd * ch.twist_inertia * rate
    np.testing.assert_allclose(d.actuator_force[ch.twist_actuator_ids],
                               np.clip(tau, -g.max_torque, g.max_torque), rtol=1e-6, atol=1e-6)


def test_actuator_pd_tracks_like_the_explicit_reference():
    """Same control law, evaluated in C: the settled and the moving character agree with
    explicit_pd's to a few millimetres."""
    target = tpose_sensor()
    states = {}
    for ctrl in ('explicit_pd', 'actuator_pd'):
        sim = Simulation(SimConfig(controller=ctrl, body_height=1.75, integrator='euler'))
        run(sim, target, 1.0)
        moving = target.copy()
        out = []
        for i in range(30):  # raise the left forearm and hand over one second
            moving[[6, 7], 2] = target[[6, 7], 2] + 0.3 * (i + 1) / 30
            out.append(sim.step({1: moving})[1].positions)
        states[ctrl] = np.array(out)
    diff = np.linalg.norm(states['explicit_pd'] - states['actuator_pd'], axis=-1)
    assert diff.mean() < 0.005 and diff.max() < 0.02


def test_gains_changed_at_run_time_reach_the_actuators():
    sim = Simulation(SimConfig(controller='actuator_pd', body_height=1.75))
    run(sim, tpose_sensor(), 0.1)
    sim.config.gains.ke = 6000.0
    sim.config.gains.max_force = 500.0
    run(sim, tpose_sensor(), 0.1)
    ids = sim.characters[1].actuator_ids.ravel()
    np.testing.assert_allclose(sim.model.actuator_gainprm[ids, 0], 6000.0)
    np.testing.assert_allclose(sim.model.actuator_biasprm[ids, 1], -6000.0)
    np.testing.assert_allclose(sim.model.actuator_forcerange[ids], [[-500.0, 500.0]] * len(ids))


def test_implicit_damping_keeps_stiff_gains_stable():
    """Ke 1e5 N/m, Kd 2000 N s/m at 2 ms: the explicit scheme diverges (the simulation resets
    itself and counts it); the same actuators integrated with implicitfast stay on target."""
    stiff = dict(ke=1e5, kd=2000.0, max_force=1e9)
    for integrator, stable in (('euler', False), ('implicitfast', True)):
        sim = Simulation(SimConfig(controller='actuator_pd', integrator=integrator,
                                   body_height=1.75, gains=Gains(**stiff)))
        st = run(sim, tpose_sensor(), 0.5)
        assert (sim.counters['nan_reset'] == 0) == stable, integrator
        if stable:
            err = np.linalg.norm(st.positions - st.target_world, axis=1)
            assert err.max() < 0.02


def _walk_targets(n=45):
    """The first frames of the built-in walk, sensor frame (a moving target with foot contacts)."""
    from skeleton_data.motions import builtin_clips
    clip = next(c for c in builtin_clips(0) if c.name == 'builtin_walk')
    return clip.positions[:n] + np.array([2.5, 0.0, -0.8])


@pytest.mark.parametrize('controller', ['actuator_pd', 'explicit_pd', 'mocap_constraints'])
def test_joint_points_from_the_joint_sites_are_the_anchors(controller):
    """The joint sites MuJoCo computes every step sit exactly on the joint anchors (not on the
    MJCF's 6-digit copy), for every controller."""
    sim = Simulation(SimConfig(controller=controller, body_height=1.75))
    for p in _walk_targets(10):
        sim.step({1: p})
    ch = sim.characters[1]
    assert sim.world.ix.js is not None
    np.testing.assert_allclose(sim.world.joint_points(), ch.joint_points(sim.data), rtol=0, atol=1e-12)
    st = sim.states()[1]
    np.testing.assert_allclose(st.positions, ch.joint_points(sim.data), rtol=0, atol=1e-12)
    np.testing.assert_allclose(st.orientations[1:], sim.state(1).orientations[1:], atol=0)


@pytest.mark.parametrize('controller', ['actuator_pd', 'mocap_constraints'])
def test_twist_error_is_the_reference_twist_angle(controller):
    """Eq. 2's error computed as one bilinear form in the body frame equals the twist (about the
    current segment axis) of q_target * q_current^-1 from controller.twist_error."""
    from physics_sim.controller import twist_error
    g = Gains(twist_kd=0.0)    # ctrl = Ke_i * error only
    sim = Simulation(SimConfig(controller=controller, body_height=1.75, gains=g))
    rng = np.random.default_rng(5)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (20, 1))
    for p in _walk_targets(12):
        # orientations given: random twists/swings (up to ~0.6 rad) away from the simulated ones
        q[1:] = rng.normal(0.0, 0.3, (19, 4)) + [0.0, 0.0, 0.0, 1.0]
        sim.step({1: (p, q / np.linalg.norm(q, axis=1, keepdims=True))})
    w = sim.world
    w.pack_targets()
    t = sim.time + 0.01
    pts = sim.world.joint_points()
    tau = w.twist_torques(t, w.tg, pts, damped=(controller != 'actuator_pd'))
    ch = sim.characters[1]
    q0, q1 = ch.prev.seg_quats, ch.cur.seg_quats
    q1 = q1 * np.sign(np.sum(q0 * q1, axis=1))[:, None]
    s = min(max((t - ch.cur.sim_time) / ch.period, 0.0), 1.0)
    q_t = (1 - s) * q0 + s * q1
    q_t /= np.linalg.norm(q_t, axis=1, keepdims=True)
    axes = ch.segment_axes(ch.joint_points(sim.data))
    ref = g.twist_ke * w.ix.tw_i * twist_error(q_t, ch.segment_quats(sim.data), axes)
    if controller == 'actuator_pd':
        assert np.abs(ref).max() > 0.05 * g.twist_ke * w.ix.tw_i.max()   # not all ~0
        np.testing.assert_allclose(tau, ref, rtol=1e-5, atol=1e-9)
    else:   # the damped torque vector: |tau| = min(|ref - Kd_i rate|, max) along the axis; Kd_i = 0
        ref = np.clip(ref, -g.max_torque, g.max_torque)
        np.testing.assert_allclose(tau, ref[:, None] * axes, rtol=1e-5, atol=1e-9)


def test_solver_choice_gives_the_same_motion():
    """pgs and newton solve the same constraints (contacts, foot pins): the walking character
    agrees to a fraction of a millimetre; an unknown solver is refused; auto picks newton for
    every controller (two to three times cheaper than pgs once characters touch:
    ``python -m physics_sim.step_cost --spacing 0.8 --solver pgs``)."""
    out = {}
    for solver in ('pgs', 'newton'):
        sim = Simulation(SimConfig(body_height=1.75, solver=solver))
        out[solver] = np.array([sim.step({1: p})[1].positions for p in _walk_targets()])
        assert sim.counters['pins'] > 0 and sim.counters['nan_reset'] == 0
    assert np.abs(out['pgs'] - out['newton']).max() < 2e-4
    with pytest.raises(ValueError):
        SimConfig(solver='dantzig').validate()
    solvers = {c: Simulation(SimConfig(controller=c, body_height=1.75)).model.opt.solver
               for c in ('actuator_pd', 'explicit_pd', 'mocap_constraints')}
    assert set(solvers.values()) == {mujoco.mjtSolver.mjSOL_NEWTON}


def test_newton_needs_a_quarter_of_the_pgs_sweeps_once_characters_touch():
    """Two characters side by side, 0.8 m apart, their arms swinging into each other: newton
    takes fewer constraint-solver sweeps in total than pgs (iterations, not seconds: the
    machine's load does not move them), with the same contacts."""
    from skeleton_core.model import NUM_JOINTS, standard_body
    rest = standard_body().rest_positions() - np.array([0.0, 0.0, 0.8])
    sway = np.arange(NUM_JOINTS)[:, None] * 0.3
    iters, contacts = {}, {}
    for solver in ('pgs', 'newton'):
        sim = Simulation(SimConfig(solver=solver, controller='explicit_pd'))
        iters[solver] = contacts[solver] = 0
        for k in range(60):
            for u in range(2):
                pos = rest + np.array([0.0, 0.8 * u, 0.0]) + 0.05 * np.sin(0.2 * k + u + sway)
                pos[[7, 11], 2] += 0.2 * np.sin(0.1 * k + u)
                sim.set_target(u + 1, pos, None, k * 33_333_333)
            sim.advance(1 / 30)
            (w,) = sim.worlds
            iters[solver] += int(w.data.solver_niter[0])
            contacts[solver] += int(w.data.ncon)
    assert abs(contacts['pgs'] - contacts['newton']) <= 0.1 * contacts['pgs']
    assert contacts['newton'] > 60 * 4          # they touch: several contacts every frame
    assert iters['newton'] * 4 < iters['pgs'], iters


def test_explicit_joint_damping_only_where_it_is_stable():
    """Euler integrates the joint damping explicitly (MuJoCo's eulerdamp off) unless asked not to
    or unless the armature is too small for it; the motion matches the implicit one closely."""
    flag = int(mujoco.mjtDisableBit.mjDSBL_EULERDAMP)
    sims = {}
    for name, kw, explicit in (('default', {}, True),
                               ('asked', dict(implicit_joint_damping=True), False),
                               ('light', dict(joint_armature=0.005), False),
                               ('implicitfast', dict(integrator='implicitfast'), True)):
        sim = Simulation(SimConfig(body_height=1.75, **kw))
        assert bool(sim.model.opt.disableflags & flag) == explicit, name
        sims[name] = sim
    a = np.array([sims['default'].step({1: p})[1].positions for p in _walk_targets(30)])
    b = np.array([sims['asked'].step({1: p})[1].positions for p in _walk_targets(30)])
    assert np.abs(a - b).max() < 2e-3
    assert sims['default'].counters['nan_reset'] == 0


def test_pin_forces_match_the_constraint_rows():
    """Each pinned foot's force is the norm of its connect rows in MuJoCo's constraint arrays;
    asked only for pins above a bound no row can reach, all are 0 (nothing strained)."""
    sim = Simulation(SimConfig(body_height=1.75))
    run(sim, tpose_sensor(), 1.0)
    d = sim.data
    assert any(p.active for _, _, p in sim.world.pins.feet)
    rows = np.flatnonzero(d.efc_type[:d.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY)
    ref = []
    for _, j, pin in sim.world.pins.feet:
        sel = rows[d.efc_id[rows] == sim.world.chars[0].pin_eq[j]]
        ref.append(np.linalg.norm(d.efc_force[sel]) if pin.active else 0.0)
    f = sim.world.pins.forces()
    assert max(ref) > 10.0    # a standing character leans on its pins
    np.testing.assert_allclose(f, ref, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sim.world.pins.forces(below=0.5 * max(ref)), ref, rtol=1e-12, atol=1e-12)
    assert not sim.world.pins.forces(below=10.0 * max(ref)).any()


def test_bench_rtf_reports_every_run():
    """bench_physics's interleaved real-time factors: one wall and one CPU figure per variant and
    number of characters, positive and finite (no timing is asserted)."""
    from physics_sim import bench
    r = bench.rtf(True, variants=['actuator_pd', 'explicit_pd'], counts=(1, 2), chunk=6)
    assert sorted(r) == sorted(f'{v}_{n}char{s}' for v in ('actuator_pd', 'explicit_pd')
                               for n in (1, 2) for s in ('', '_cpu'))
    assert all(np.isfinite(x) and x > 0 for x in r.values())


def test_bench_solver_option_sets_every_run(monkeypatch):
    """bench_physics --solver pgs: every run's MuJoCo model on PGS (the default auto: newton); an
    unknown solver is refused with a usage error."""
    from physics_sim import bench

    def model_solver():
        sim = Simulation(bench.config('actuator_pd'))
        sim.step({0: tpose_sensor()})
        return sim.world_of(0).model.opt.solver

    assert model_solver() == mujoco.mjtSolver.mjSOL_NEWTON
    monkeypatch.setattr(bench, 'SOLVER', 'pgs')
    assert model_solver() == mujoco.mjtSolver.mjSOL_PGS
    with pytest.raises(SystemExit) as e:
        bench.main(['--solver', 'simplex', '--rtf-only'])
    assert e.value.code == 2


def test_auto_controller_switches_with_the_number_of_characters():
    """controller 'auto': actuator_pd for few characters, explicit_pd from auto_explicit_from on
    (decided when the world is recompiled for a character coming or going); the characters keep
    tracking across the switch."""
    sim = Simulation(SimConfig(controller='auto', auto_explicit_from=3, body_height=1.75,
                               world_split='shared'))
    ys = (-2.4, -0.8, 0.8, 2.4)

    def targets(uids):
        return {u: tpose_sensor((2.5, ys[u - 1], 0.0)) for u in uids}

    def tracking(states):
        return max(np.linalg.norm(s.positions - s.target_world, axis=1).mean()
                   for s in states.values())

    for _ in range(20):
        states = sim.step(targets((1, 2)))
    assert sim.controller == 'actuator_pd' and sim.model.nu > 0
    assert tracking(states) < 0.03
    for _ in range(20):
        states = sim.step(targets((1, 2, 3)))
    assert sim.controller == 'explicit_pd' and sim.model.nu == 0
    assert tracking(states) < 0.03
    sim.remove_character(3)
    for _ in range(20):
        states = sim.step(targets((1, 2)))
    assert sim.controller == 'actuator_pd' and sim.model.nu > 0
    assert tracking(states) < 0.03 and sim.counters['nan_reset'] == 0
    with pytest.raises(ValueError):
        SimConfig(controller='auto', auto_explicit_from=0).validate()
