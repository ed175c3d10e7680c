"""The physics character in a feature world (docs/control.md, docs/physics.md): the world file's
static geometry in the MuJoCo model, and hands gripping a feature the control node engaged."""
from pathlib import Path

import mujoco
import numpy as np
import pytest
import yaml

from skeleton_core.model import (ELBOW_LEFT, ELBOW_RIGHT, HAND_LEFT, HAND_RIGHT, JOINT_NAMES,
                                 SHOULDER_LEFT, SHOULDER_RIGHT, WRIST_LEFT, WRIST_RIGHT,
                                 standard_body)

from physics_sim.controller import Gains
from physics_sim.feature_geometry import load_geometry, parse_geometry
from physics_sim.feature_holds import engaged_hands, grip_changes
from physics_sim.mjcf_world import CharacterEntry, world_xml
from physics_sim.simulation import SimConfig, Simulation

ROOT = Path(__file__).resolve().parents[1]
PLAYGROUND = ROOT / 'src/performance_control/config/worlds/playground.yaml'
BODY = standard_body()
SENSOR_H = 0.8


def _geom(m, name):
    g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name)
    assert g >= 0, name
    return g


def test_builder_adds_the_world_files_geometry():
    doc = yaml.safe_load(PLAYGROUND.read_text())
    feats = load_geometry(str(PLAYGROUND))
    lift = 0.04
    m = mujoco.MjModel.from_xml_string(world_xml(
        [CharacterEntry('u1_', BODY, (0.0, 0.0, 1.0))], features=feats, feature_lift=lift))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    bars = doc['features']['monkey_bars']['geometry']
    for i, b in enumerate(bars):
        g = _geom(m, f'feat_monkey_bars_{i}')
        assert m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE
        assert m.geom_size[g, 0] == pytest.approx(b['radius'])
        a, c = np.array(b['from']), np.array(b['to'])
        np.testing.assert_allclose(d.geom_xpos[g], (a + c) / 2 + [0, 0, lift], atol=1e-6)
        assert m.geom_size[g, 1] == pytest.approx(np.linalg.norm(c - a) / 2)
    rope = doc['features']['rope']['geometry'][0]
    for s in range(rope['segments']):   # a chain of capsule bodies on ball joints, at rest
        g = _geom(m, f'feat_rope_0_seg{s}_geom')
        assert m.geom_size[g, 0] == pytest.approx(rope['radius'])
        assert m.body_mass[m.geom_bodyid[g]] == pytest.approx(rope['segment_mass'])
        j = m.body_jntadr[m.geom_bodyid[g]]
        assert m.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL
        assert m.dof_damping[m.jnt_dofadr[j]] == pytest.approx(rope['joint_damping'])
        mid = np.array(rope['top']) - [0, 0, (s + 0.5) * rope['length'] - lift]
        np.testing.assert_allclose(d.geom_xpos[g], mid, atol=1e-6)
    tr = doc['features']['trampoline']['geometry'][0]
    g = _geom(m, 'feat_trampoline_0')
    np.testing.assert_allclose(m.geom_size[g], tr['half'])
    np.testing.assert_allclose(d.geom_xpos[g], np.array(tr['center']) + [0, 0, lift], atol=1e-6)
    # water (a volume) and the floor plane add no geometry: one floor, no water body
    assert sum(m.geom_type == mujoco.mjtGeom.mjGEOM_PLANE) == 1
    assert mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, 'feat_water') < 0
    # a grip per hand and holdable body (the world for the bars, each rope segment), inactive
    for h in (HAND_LEFT, HAND_RIGHT):
        for b in ['world'] + [f'feat_rope_0_seg{s}' for s in range(rope['segments'])]:
            e = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, f'u1_grip_{JOINT_NAMES[h]}_{b}')
            assert e >= 0 and not m.eq_active0[e]


def test_without_feature_world_the_model_is_unchanged():
    e = [CharacterEntry('u1_', BODY, (0.0, 0.0, 1.0))]
    assert world_xml(e) == world_xml(e, features={}) == world_xml(e, features=None)
    sim = Simulation(SimConfig(body_height=1.75))
    sim.step({1: BODY.rest_positions() - [0, 0, SENSOR_H]})
    assert 'feat_' not in sim.world.xml and 'grip_' not in sim.world.xml


def test_bad_world_geometry_names_file_and_feature():
    with pytest.raises(ValueError, match=r'w\.yaml: feature .bars.: capsule.radius'):
        parse_geometry({'features': {'bars': {'geometry': [
            {'type': 'capsule', 'from': [0, 0, 2], 'to': [1, 0, 2], 'radius': -1}]}}}, 'w.yaml')
    with pytest.raises(FileNotFoundError):
        Simulation(SimConfig(feature_world='/nonexistent/world.yaml'))


def test_grip_changes_rules():
    axes = {'monkey_bars': [(np.array([2.6, -0.5, 2.79]), np.array([2.6, 0.5, 2.79]), 'world')],
            'rope': [(np.array([0.0, 0.0, 3.0]), np.array([0.0, 0.0, 2.6]), 'seg0'),
                     (np.array([0.0, 0.0, 2.6]), np.array([0.1, 0.0, 2.2]), 'seg1')]}
    bar_hand = np.array([2.62, 0.2, 2.84])       # 5.4 cm from the bar's axis
    far_hand = np.array([2.8, 0.2, 2.3])
    grab, rel = grip_changes({HAND_LEFT: 'monkey_bars', HAND_RIGHT: 'monkey_bars'}, {},
                             {HAND_LEFT: bar_hand, HAND_RIGHT: far_hand}, axes, 0.15)
    assert rel == [] and list(grab) == [HAND_LEFT]
    assert grab[HAND_LEFT][:2] == ('monkey_bars', 'world')
    np.testing.assert_allclose(grab[HAND_LEFT][2], [2.6, 0.2, 2.79])   # on the axis
    # the rope: the closest segment, where it is now
    grab, _ = grip_changes({HAND_RIGHT: 'rope'}, {}, {HAND_RIGHT: np.array([0.15, 0.0, 2.4])},
                           axes, 0.15)
    assert grab[HAND_RIGHT][1] == 'seg1'
    np.testing.assert_allclose(grab[HAND_RIGHT][2], [0.0559, 0.0, 2.3765], atol=1e-4)
    # released when no longer engaged, or engaged with another feature
    held = {HAND_LEFT: ('monkey_bars', 'world', np.zeros(3)),
            HAND_RIGHT: ('rope', 'seg0', np.zeros(3))}
    grab, rel = grip_changes({HAND_RIGHT: 'monkey_bars'}, held, {HAND_RIGHT: bar_hand}, axes, 0.15)
    assert sorted(rel) == [HAND_LEFT, HAND_RIGHT] and list(grab) == [HAND_RIGHT]
    # held hands stay as they are; water / unknown features have nothing to hold
    assert grip_changes({HAND_LEFT: 'monkey_bars'}, {HAND_LEFT: held[HAND_LEFT]},
                        {HAND_LEFT: far_hand}, axes, 0.15) == ({}, [])
    assert grip_changes({HAND_LEFT: 'water', HAND_RIGHT: 'nope'}, {},
                        {HAND_LEFT: bar_hand, HAND_RIGHT: bar_hand}, axes, 1.0) == ({}, [])
    assert engaged_hands(['HandLeft', 'FootLeft'], ['rope', 'floor']) == {HAND_LEFT: 'rope'}
    with pytest.raises(ValueError):
        engaged_hands(['HandLeft'], [])


def hanging_pose(bar=(2.6, 0.0, 2.75)):
    """The standard body with both arms straight up, hands on the bar (world, floor z = 0)."""
    p = BODY.rest_positions().copy()
    for sh, el, wr, hd in ((SHOULDER_LEFT, ELBOW_LEFT, WRIST_LEFT, HAND_LEFT),
                           (SHOULDER_RIGHT, ELBOW_RIGHT, WRIST_RIGHT, HAND_RIGHT)):
        for a, b in ((sh, el), (el, wr), (wr, hd)):
            ln = np.linalg.norm(BODY.rest_positions()[b] - BODY.rest_positions()[a])
            p[b] = p[a] + [0.0, 0.0, ln]
    hands = (p[HAND_LEFT] + p[HAND_RIGHT]) / 2
    return p + (np.array(bar) - hands)


def _hang(gains=None, grip=True, seconds=2.0):
    sim = Simulation(SimConfig(body_height=1.75, feature_world=str(PLAYGROUND),
                               gains=gains or Gains()))
    target = hanging_pose() - [0, 0, SENSOR_H]
    sim.step({1: target})
    if grip:
        sim.set_engaged(1, ['HandLeft', 'HandRight'], ['monkey_bars', 'monkey_bars'])
    lift = sim.sensor.lift
    hand_gap, hip_z = [], []
    for _ in range(int(seconds * 30)):
        st = sim.step({1: target})[1]
        hands = st.positions[[HAND_LEFT, HAND_RIGHT]]
        hand_gap.append(np.abs(np.linalg.norm(hands[:, [0, 2]] - [2.6, 2.75 + lift], axis=1)).max())
        hip_z.append(float(st.positions[0, 2]))
    return sim, target, np.array(hand_gap), np.array(hip_z)


def test_engaged_hands_hang_from_the_bar_and_drop_when_released():
    sim, target, gap, hip_z = _hang()
    assert sim.counters['grips'] == 2 and set(sim.grips[1]) == {HAND_LEFT, HAND_RIGHT}
    assert gap.max() < 0.03                      # the hands stay on the bar's axis
    hang_z = hanging_pose()[0, 2] + sim.sensor.lift
    assert np.abs(hip_z - hang_z).max() < 0.05   # the body hangs at the hanging height for 2 s
    assert sim.counters['nan_reset'] == 0
    # released: the control node's character drops to the floor; the physics one follows
    sim.set_engaged(1)
    standing = BODY.rest_positions() + [2.6, 0.0, 0.0] - [0, 0, SENSOR_H]
    for _ in range(45):
        st = sim.step({1: standing})[1]
    assert sim.grips == {}
    assert st.positions[0, 2] < hang_z - 0.5         # standing (hips 0.67 m lower)
    assert np.linalg.norm(st.positions[HAND_LEFT] - [2.6, 0.2, 2.75]) > 0.5


def test_the_grip_carries_the_body():
    """With Eq. 1 too weak to hold the body up (20 joints x 25 N < its weight), only the grip on
    the bar keeps it at the hanging height; without it the body sinks."""
    weak = Gains(max_force=25.0)
    _, _, _, held_z = _hang(weak, grip=True)
    _, _, _, free_z = _hang(weak, grip=False)
    hang_z = hanging_pose()[0, 2]
    assert held_z[-1] > hang_z - 0.25          # the weak arms sag 0.19 m, but it hangs
    assert free_z[-1] < hang_z - 1.0           # on the floor


def test_hanging_on_the_rope_swings_it():
    """Both hands on the rope (a chain of bodies): they stay on it, the physics stays stable, and
    the character swaying forwards and back swings the rope with it."""
    sim = Simulation(SimConfig(body_height=1.75, feature_world=str(PLAYGROUND)))
    rx, ry = yaml.safe_load(PLAYGROUND.read_text())['features']['rope']['geometry'][0]['top'][:2]
    target = hanging_pose(bar=(rx - 0.15, ry, 3.6)) - [0, 0, SENSOR_H]   # the body behind it
    target[HAND_LEFT, :2], target[HAND_RIGHT, :2] = [rx, ry + 0.03], [rx, ry - 0.03]
    target[WRIST_LEFT, :2], target[WRIST_RIGHT, :2] = [rx - 0.05, ry + 0.08], [rx - 0.05,
                                                                               ry - 0.08]
    sim.step({1: target})
    sim.set_engaged(1, ['HandLeft', 'HandRight'], ['rope', 'rope'])
    sim.step({1: target})
    rest = sim.grip_points(1)[HAND_LEFT].copy()
    assert {g[1] for g in sim.grips[1].values()} <= {f'feat_rope_0_seg{s}' for s in range(10)}
    gaps, swing = [], []
    for i in range(60):
        st = sim.step({1: target + [0.3 * np.sin(i / 10), 0, 0]})[1]
        held = sim.grip_points(1)
        gaps += [np.linalg.norm(st.positions[h] - held[h]) for h in (HAND_LEFT, HAND_RIGHT)]
        swing.append(held[HAND_LEFT][0] - rest[0])
    assert max(gaps) < 0.03
    assert max(swing) > 0.15 and min(swing) < -0.15       # the rope swings with the body
    assert sim.counters['nan_reset'] == 0
