"""Invariants of the skeleton model (the single source of truth for joints and body)."""
import numpy as np
import pytest

from skeleton_core import model as m


def test_tree_rooted_at_hip_center_and_parents_precede_children():
    assert m.JOINT_NAMES[m.ROOT] == 'HipCenter'
    assert m.PARENTS[m.ROOT] == -1
    assert [j for j in range(m.NUM_JOINTS) if m.PARENTS[j] < 0] == [m.ROOT]
    for j in range(1, m.NUM_JOINTS):
        assert 0 <= m.PARENTS[j] < j
    assert m.NUM_JOINTS == 20 and m.NUM_SEGMENTS == 19
    # every joint reaches the root
    for j in range(m.NUM_JOINTS):
        k, steps = j, 0
        while m.PARENTS[k] >= 0:
            k, steps = m.PARENTS[k], steps + 1
        assert k == m.ROOT and steps < m.NUM_JOINTS


def test_kinect_v1_joint_order():
    assert m.JOINT_NAMES[:4] == ('HipCenter', 'Spine', 'ShoulderCenter', 'Head')
    assert m.JOINT_NAMES[7] == 'HandLeft' and m.JOINT_NAMES[19] == 'FootRight'


def test_segment_lengths_positive_and_symmetric():
    body = m.standard_body()
    assert np.all(body.segment_lengths > 0)
    for k, (p, c) in enumerate(m.SEGMENTS):
        mk = m.SEGMENT_OF_JOINT[m.MIRROR[c]]
        assert body.segment_lengths[k] == pytest.approx(body.segment_lengths[mk])
        assert body.segment_masses[k] == pytest.approx(body.segment_masses[mk])
    assert body.segment_masses.sum() == pytest.approx(body.mass)


def test_rest_pose_stands_on_floor_at_standard_height():
    body = m.standard_body()
    p = body.rest_positions()
    assert p[:, 2].min() == pytest.approx(0.0, abs=1e-9)          # feet on the floor
    assert 0.90 * body.height < p[m.HEAD, 2] < body.height       # head joint below the top of the head
    assert np.allclose(m.segment_lengths(p), body.segment_lengths)
    assert p[m.HAND_LEFT, 1] > 0 > p[m.HAND_RIGHT, 1]            # REP-103: y left
    assert p[m.FOOT_LEFT, 0] > p[m.ANKLE_LEFT, 0]                # feet point forward (+x)


def test_scaling_is_proportional_and_validated():
    a, b = m.standard_body(1.75), m.standard_body(1.50)
    assert np.allclose(b.segment_lengths / a.segment_lengths, 1.50 / 1.75)
    assert m.estimate_height(b.rest_positions()) == pytest.approx(1.50)
    with pytest.raises(ValueError):
        m.standard_body(float('nan'))
    with pytest.raises(ValueError):
        m.standard_body(0.1)


def test_nite_mapping_complete():
    assert len(m.NITE_JOINT_NAMES) == 15 == len(m.NITE_TO_KINECT) == len(m.NITE_TF_NAMES)
    assert len(set(m.NITE_TO_KINECT)) == 15
    assert sorted(set(m.NITE_TO_KINECT) | set(m.NITE_MISSING)) == list(range(20))
    assert len(m.NITE_MISSING) == 5
    assert m.NITE_TO_KINECT[m.NITE_JOINT_NAMES.index('JOINT_HEAD')] == m.HEAD


def test_forward_kinematics_inverts_parent_relative():
    p = m.standard_body().rest_positions() + np.random.default_rng(0).normal(0, 0.05, (20, 3))
    rel = m.parent_relative(p)
    assert np.allclose(m.forward_kinematics(rel, p[m.ROOT]), p)
    assert sorted(m.subtree(m.SHOULDER_LEFT)) == [4, 5, 6, 7]


def test_mirror_is_an_involution():
    assert all(m.MIRROR[m.MIRROR[j]] == j for j in range(m.NUM_JOINTS))
    assert m.MIRROR[m.HIP_CENTER] == m.HIP_CENTER
