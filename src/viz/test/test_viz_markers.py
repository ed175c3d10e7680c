"""viz.markers: marker geometry for RViz (pure Python, no rclpy)."""
import numpy as np
import pytest

from skeleton_core.conversions import SkeletonFrame
from skeleton_core.geometry import quat_rotate
from skeleton_core.model import (ELBOW_LEFT, HAND_RIGHT, HEAD, INFERRED, NOT_TRACKED, NUM_JOINTS,
                                 NUM_SEGMENTS, SEGMENT_OF_JOINT, SEGMENTS, WRIST_LEFT,
                                 standard_body)
from viz import markers as mk


def _frame(uid=1, shift=(2.5, 0.0, 0.0), reliability=None, ts=None, frame_id='kinect_link'):
    p = standard_body().rest_positions() + np.array(shift)
    return SkeletonFrame(positions=p,
                         tracking_state=np.full(NUM_JOINTS, 2, np.uint8) if ts is None else ts,
                         reliability=(np.full(NUM_JOINTS, np.nan, np.float32)
                                      if reliability is None else reliability),
                         user_id=uid, stamp_ns=123456789, frame_id=frame_id)


@pytest.mark.parametrize('d', [(1, 0, 0), (0, 1, 0), (0, 0, 1), (0, 0, -1), (1, -2, 0.5),
                               (-0.3, 0.1, -0.9), (1e-7, 0, -1)])
def test_quat_z_to_aligns_cylinder_axis_with_direction(d):
    q = np.array(mk.quat_z_to(np.array(d, float)))
    assert np.isclose(np.linalg.norm(q), 1.0)
    z = quat_rotate(q, np.array([0.0, 0.0, 1.0]))
    assert np.allclose(z, np.array(d) / np.linalg.norm(d), atol=1e-6)


def test_capsules_use_segment_lengths_orientations_and_standard_radii():
    f = _frame()
    specs = mk.capsule_markers(f, mk.Style(character_height=1.75))
    assert len(specs) == 3 * NUM_SEGMENTS
    assert len({s.id for s in specs}) == len(specs)
    radii = standard_body().segment_radii
    p = f.positions
    for k, (a, b) in enumerate(SEGMENTS):
        cyl, cap_a, cap_b = specs[3 * k: 3 * k + 3]
        assert (cyl.type, cap_a.type, cap_b.type) == (mk.CYLINDER, mk.SPHERE, mk.SPHERE)
        assert np.allclose(cyl.position, 0.5 * (p[a] + p[b]))
        assert np.isclose(cyl.scale[2], np.linalg.norm(p[b] - p[a]))
        assert np.allclose(cyl.scale[:2], 2 * radii[k])
        axis = quat_rotate(np.array(cyl.orientation), np.array([0.0, 0.0, 1.0]))
        assert np.allclose(axis, (p[b] - p[a]) / np.linalg.norm(p[b] - p[a]), atol=1e-9)
        assert np.allclose(cap_a.position, p[a]) and np.allclose(cap_b.position, p[b])
        assert np.allclose(cap_b.scale, 2 * radii[k])
    assert all(s.ns == 'character/user_1' and s.frame_id == 'kinect_link' for s in specs)


def test_capsule_radii_follow_estimated_character_height():
    body = standard_body(1.5)
    f = _frame()
    f.positions = body.rest_positions()
    specs = mk.capsule_markers(f, mk.Style(character_height=0.0))
    assert np.isclose(specs[0].scale[0], 2 * body.segment_radii[0], rtol=1e-6)


def test_reliability_square_side_proportional_to_one_minus_reliability():
    r = np.linspace(0.0, 1.0, NUM_JOINTS).astype(np.float32)
    r[HEAD] = np.nan
    style = mk.Style(reliability_square_max=0.2, reliability_square_min=0.001)
    specs, none = mk.reliability_markers(_frame(reliability=r), style)
    by_id = {s.id: s for s in specs}
    assert HEAD in none and HEAD not in by_id          # unknown reliability: no square
    assert NUM_JOINTS - 1 in none                      # reliability 1: no square
    for j, s in by_id.items():
        assert s.type == mk.CUBE and s.ns == 'reliability/user_1'
        assert np.isclose(s.scale[1], 0.2 * (1 - r[j]), atol=1e-6)
        assert s.scale[1] == s.scale[2] and s.scale[0] < 0.01  # flat square facing the sensor
        assert s.color[:3] == (1.0, 0.0, 0.0)
    # sides strictly decrease as reliability grows
    sides = [by_id[j].scale[1] for j in sorted(by_id)]
    assert all(a > b for a, b in zip(sides, sides[1:]))


def test_raw_layer_hides_not_tracked_and_dims_inferred():
    ts = np.full(NUM_JOINTS, 2, np.uint8)
    ts[HAND_RIGHT] = NOT_TRACKED
    ts[WRIST_LEFT] = INFERRED
    style = mk.Style(inferred_alpha=0.3)
    joints, bones = mk.skeleton_markers(_frame(ts=ts), 'raw', style.raw_joint_color,
                                        style.raw_bone_color, style)
    assert joints.type == mk.SPHERE_LIST and bones.type == mk.LINE_LIST
    assert len(joints.points) == NUM_JOINTS - 1
    assert len(bones.points) == 2 * (NUM_SEGMENTS - 1)  # the WristRight-HandRight bone is gone
    alphas = joints.colors[:, 3]
    assert np.isclose(alphas.min(), 0.3) and np.sum(np.isclose(alphas, 0.3)) == 1
    assert np.allclose(joints.colors[0, :3], style.raw_joint_color[:3])  # purple
    assert np.allclose(bones.colors[0, :3], style.raw_bone_color[:3])   # yellow
    # the two bones touching the inferred wrist are dimmed
    dim = np.isclose(bones.colors[:, 3], 0.3)
    assert dim.sum() == 4
    grey = mk.Style(not_tracked='grey')
    joints, bones = mk.skeleton_markers(_frame(ts=ts), 'raw', grey.raw_joint_color,
                                        grey.raw_bone_color, grey)
    assert len(joints.points) == NUM_JOINTS
    assert np.allclose(joints.colors[HAND_RIGHT], grey.not_tracked_color)


def test_scene_namespaces_hidden_layers_and_deletes():
    scene = mk.SceneState(mk.Style())
    r = np.full(NUM_JOINTS, 1.0, np.float32)
    r[ELBOW_LEFT] = 0.2
    scene.update('raw', [_frame(1), _frame(2, shift=(3, 1, 0))], 0.0)
    scene.update('reliability', [_frame(1, reliability=r)], 0.0)
    scene.update('reconstructed', [_frame(1)], 0.0)
    scene.update('character', [_frame(1)], 0.0)
    specs = scene.build(0.1)
    nss = {s.ns for s in specs}
    assert nss == {'raw/user_1', 'raw/user_2', 'reliability/user_1', 'reconstructed/user_1',
                   'character/user_1'}
    assert [s.id for s in specs if s.ns == 'reliability/user_1'] == [ELBOW_LEFT]
    assert sum(s.ns == 'character/user_1' for s in specs) == 3 * NUM_SEGMENTS
    assert all(s.action == mk.ADD for s in specs)
    # nothing changed: nothing to send; a style change rebuilds every layer
    assert scene.build(0.15) == []
    scene.invalidate()
    assert {s.ns for s in scene.build(0.15)} == nss

    # user 2 disappears, the raw layer is hidden: their markers come back once as DELETE
    scene.update('raw', [_frame(1)], 0.2)
    scene.enabled['raw'] = False
    specs = scene.build(0.3)
    deletes = {(s.ns, s.id) for s in specs if s.action == mk.DELETE}
    assert deletes == {('raw/user_1', 0), ('raw/user_1', 1), ('raw/user_2', 0), ('raw/user_2', 1)}
    assert not any(s.ns.startswith('raw/') and s.action == mk.ADD for s in specs)
    scene.update('raw', [_frame(1)], 0.35)
    specs = scene.build(0.4)
    assert not any(s.ns.startswith('raw/') for s in specs)
    assert not scene.has_stale(0.4)

    # a layer that stops updating goes stale and is deleted
    scene.update('reconstructed', [_frame(1)], 0.4)
    assert not scene.has_stale(0.5)
    scene.build(0.5)
    assert scene.has_stale(5.0)
    specs = scene.build(5.0)
    assert specs and all(s.action == mk.DELETE for s in specs)
    assert scene.shown_namespaces() == []


def test_scene_fills_empty_frame_id_and_applies_offsets():
    scene = mk.SceneState(mk.Style(offsets={'character': (0.0, 1.0, 0.0)}),
                          default_frame_id='world')
    scene.update('character', [_frame(1, frame_id='')], 0.0)
    specs = scene.build(0.0)
    assert all(s.frame_id == 'world' for s in specs)
    f = _frame(1)
    assert np.allclose(specs[1].position, f.positions[SEGMENTS[0][0]] + (0, 1, 0))
    assert SEGMENT_OF_JOINT[SEGMENTS[0][1]] == 0
