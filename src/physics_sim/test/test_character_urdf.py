"""The physics character as a robot: its URDF has the MuJoCo model's bodies and ball joints, and the
URDF with the joint states and the root gives the simulated joint points back."""
import numpy as np

from physics_sim.character_urdf import (CharacterRobots, character_joint_states, character_tree,
                                        character_urdf)
from physics_sim.simulation import Simulation
from skeleton_core import model as m
from skeleton_core.kinematic_tree import forward_kinematics_urdf, parse_urdf
from skeleton_core.tf import matrix_from_quat
from skeleton_data.motions import builtin_clips


def test_urdf_names_are_the_mujoco_model_names():
    sim = Simulation()
    clip = builtin_clips(seed=5)[1]
    sim.step({4: np.asarray(clip.positions[0])})
    model = sim.world_of(4).model
    root, joints = parse_urdf(character_urdf(4, sim.characters[4].body))
    assert root == 'u4_seg_Spine' and model.body(root).id >= 0
    for child in m.SEGMENT_CHILDREN:
        if child == m.SPINE:
            continue
        assert f'u4_seg_{m.JOINT_NAMES[child]}' in joints
        assert model.joint(f'u4_ball_{m.JOINT_NAMES[child]}').id >= 0
        for axis in 'zyx':
            assert any(j['name'] == f'u4_ball_{m.JOINT_NAMES[child]}_{axis}'
                       for j in joints.values())
    for j in m.JOINT_NAMES:   # every joint point is a frame named as its MuJoCo site
        assert f'u4_site_{j}' in joints and model.site(f'u4_site_{j}').id >= 0


def test_urdf_with_joint_states_gives_the_simulated_characters_back():
    sim = Simulation()
    clips = builtin_clips(seed=9)
    robots = CharacterRobots()
    worst = 0.0
    for k in range(0, 60):
        states = sim.step({1: np.asarray(clips[3].positions[k]),
                           2: np.asarray(clips[6].positions[k]) + (2.0, 0.0, 0.0)})
        urdf, names, angles, roots = robots.update(states, sim.characters, np.zeros(3))
        assert (set(urdf) == {1, 2}) == (k == 0)   # made once per character body
        if k % 10:
            continue
        texts = {u: character_urdf(u, sim.characters[u].body) for u in states}
        values = dict(zip(names, angles))
        for (child, t, q), uid in zip(roots, states):
            assert child == f'u{uid}_seg_Spine'
            poses = forward_kinematics_urdf(texts[uid], values)
            r = matrix_from_quat(q)
            fk = np.array([t + r @ poses[f'u{uid}_site_{j}'][1] for j in m.JOINT_NAMES])
            worst = max(worst, np.linalg.norm(fk - states[uid].positions, axis=1).max())
    assert worst < 1e-6   # (to within float rounding: the URDF is the MJCF's geometry)
    # one character left: its URDF is made again only if it comes back
    states = sim.step({1: np.asarray(clips[3].positions[60])})
    sim.remove_character(2)
    states = sim.step({1: np.asarray(clips[3].positions[61])})
    urdf, names, _, roots = robots.update(states, sim.characters, np.zeros(3))
    assert not urdf and [r[0] for r in roots] == ['u1_seg_Spine']
    assert all(n.startswith('u1_') for n in names)


def test_joint_states_of_the_rest_posture_are_zero():
    tree = character_tree(0)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (1, m.NUM_JOINTS, 1))
    root, angles = character_joint_states(tree, q)
    assert np.allclose(root, [[0, 0, 0, 1]]) and np.abs(angles).max() < 1e-12
    assert angles.shape == (1, 3 * (m.NUM_SEGMENTS - 1))
