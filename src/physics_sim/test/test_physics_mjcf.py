"""The generated MJCF: one capsule body per skeleton segment, ball joints, masses from the model,
T-pose joint points at the model's rest positions, collision bits, objects."""
import mujoco
import numpy as np
import pytest

from skeleton_core.model import NUM_SEGMENTS, SEGMENT_CHILDREN, SEGMENTS, JOINT_NAMES, standard_body

from physics_sim.mjcf_body import CharacterParams, standalone_character_xml, joint_anchor
from physics_sim.mjcf_world import CharacterEntry, ObjectSpec, WorldParams, world_xml


def _model(xml):
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    return m, d


def test_character_structure_and_masses():
    body = standard_body(1.8, 80.0)
    m, d = _model(standalone_character_xml(body))
    assert m.nbody == 1 + NUM_SEGMENTS
    types = list(m.jnt_type)
    assert types.count(mujoco.mjtJoint.mjJNT_FREE) == 1
    assert types.count(mujoco.mjtJoint.mjJNT_BALL) == NUM_SEGMENTS - 1
    for k, c in enumerate(SEGMENT_CHILDREN):
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f'u0_seg_{JOINT_NAMES[c]}')
        assert m.body_mass[b] == pytest.approx(body.segment_masses[k], rel=1e-5)
        g = m.body_geomadr[b]
        assert m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE
        assert m.geom_size[g, 0] == pytest.approx(body.segment_radii[k], rel=1e-5)
    assert m.body_mass.sum() == pytest.approx(80.0, rel=1e-4)


def test_tpose_joint_points_match_rest_positions():
    body = standard_body()
    m, d = _model(standalone_character_xml(body))
    rest = body.rest_positions()
    for j in range(20):
        k, local = joint_anchor(body, j)
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f'u0_seg_{JOINT_NAMES[SEGMENT_CHILDREN[k]]}')
        p = d.xpos[b] + d.xmat[b].reshape(3, 3) @ local
        np.testing.assert_allclose(p, rest[j], atol=1e-6)
        np.testing.assert_allclose(d.xquat[b], [1, 0, 0, 0], atol=1e-9)


def test_two_characters_collide_with_each_other_not_themselves():
    body = standard_body()
    xml = world_xml([CharacterEntry('u1_', body, (0, 0, body.root_height), 0),
                     CharacterEntry('u2_', body, (0, 0.3, body.root_height), 1)])
    m, d = _model(xml)
    pairs = set()
    for i in range(d.ncon):
        b1 = m.body_rootid[m.geom_bodyid[d.contact[i].geom1]]
        b2 = m.body_rootid[m.geom_bodyid[d.contact[i].geom2]]
        pairs.add(tuple(sorted((int(b1), int(b2)))))
    roots = sorted(set(int(r) for r in m.body_rootid[1:]))
    assert len(roots) == 2
    assert tuple(roots) in pairs            # overlapping characters touch
    assert all(a != b for a, b in pairs)    # no contact inside one character


def test_objects_and_mocap_targets_compile():
    body = standard_body()
    objs = [ObjectSpec('crate', 'box', (1.0, 0, 0.2), (0.2, 0.2, 0.2), 3.0),
            ObjectSpec('ball', 'ball', (1.0, 1.0, 0.1), (0.1,), 0.5),
            ObjectSpec('mace', 'mace', (0.5, -0.5, 1.0), (0.3, 0.06), 2.0)]
    xml = world_xml([CharacterEntry('u0_', body, (0, 0, body.root_height))], objs,
                    WorldParams(character=CharacterParams(mocap_targets=True)))
    m, d = _model(xml)
    assert m.nmocap == 20
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_EQUALITY, i) for i in range(m.neq)]
    assert 'u0_pin_FootLeft' in names and 'u0_hold_mace_HandRight' in names
    assert sum(n.startswith('u0_track_') for n in names) == 20
    mace = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, 'obj_mace')
    assert m.body_subtreemass[mace] == pytest.approx(2.0)


@pytest.mark.parametrize('kw', [dict(kind='cone'), dict(mass=-1.0), dict(size=(0.1,)),
                                dict(pos=(np.nan, 0, 0))])
def test_bad_objects_refused(kw):
    args = dict(name='x', kind='box', pos=(0, 0, 1), size=(0.1, 0.1, 0.1), mass=1.0)
    args.update(kw)
    with pytest.raises(ValueError):
        ObjectSpec(**args)


def test_pd_actuators_sit_on_the_joint_points_and_segment_axes():
    body = standard_body()
    m, d = _model(standalone_character_xml(body, CharacterParams(pd_actuators=True, pd_kp=1234.0,
                                                                 pd_kv=56.0,
                                                                 pd_force_limit=789.0)))
    assert m.nu == 20 * 3 + NUM_SEGMENTS
    rest = body.rest_positions()
    for j in range(20):
        s = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f'u0_site_{JOINT_NAMES[j]}')
        np.testing.assert_allclose(d.site_xpos[s], rest[j], atol=1e-6)
        for a, axis in enumerate('xyz'):
            u = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f'u0_pd_{JOINT_NAMES[j]}_{axis}')
            # length = the joint point's coordinate along the world axis; gains Ke, Kd; bound
            assert d.actuator_length[u] == pytest.approx(rest[j, a], abs=1e-6)
            assert m.actuator_dyntype[u] == mujoco.mjtDyn.mjDYN_INTEGRATOR
            np.testing.assert_allclose(m.actuator_biasprm[u, :3], [0.0, -1234.0, -56.0])
            np.testing.assert_allclose(m.actuator_forcerange[u], [-789.0, 789.0])
    for k, c in enumerate(SEGMENT_CHILDREN):
        s = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f'u0_axis_{JOINT_NAMES[c]}')
        parent = rest[SEGMENTS[k][0]]
        axis = rest[c] - parent
        np.testing.assert_allclose(d.site_xmat[s].reshape(3, 3)[:, 2], axis / np.linalg.norm(axis),
                                   atol=1e-6)
    # without the option: no actuators and no axis sites; the joint sites (where every controller
    # reads the joint points) and the world origin site
    m0, d0 = _model(standalone_character_xml(body))
    assert m0.nu == 0 and m0.nsite == 1 + 20
    for j in range(20):
        s = mujoco.mj_name2id(m0, mujoco.mjtObj.mjOBJ_SITE, f'u0_site_{JOINT_NAMES[j]}')
        np.testing.assert_allclose(d0.site_xpos[s], rest[j], atol=1e-6)
