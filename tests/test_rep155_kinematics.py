"""The skeleton as a robot (skeleton_core.kinematic_tree, skeleton_core.rep155): the URDF is a tree
with REP-155's names, joint angles solved from positions give the positions back by forward
kinematics of the URDF, the hinges bend the right way, bodies come and go."""
import math

import numpy as np
import pytest

from skeleton_core import model as m
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.kinematic_tree import (euler_zyx, forward_kinematics_urdf, from_euler_zyx,
                                          parse_urdf, quat_from_matrices)
from skeleton_core.rep155 import BodyTracker, JOINT_FRAMES, human_tree, joint_frames
from skeleton_core.tf import matrix_from_quat
from skeleton_data.motions import builtin_clips


def _urdf_positions(urdf, tree, angles, root_pos, root_rot, lengths):
    """World joint positions by FK of the URDF text (a generic URDF reader, not the tree), the
    segment lengths on the stretch joints."""
    values = dict(zip(tree.joint_names + tree.stretch_names,
                      np.concatenate([angles, tree.stretch_of(lengths)])))
    poses = forward_kinematics_urdf(urdf, values)
    return np.array([root_pos + root_rot @ poses[f][1] for f in joint_frames(tree)])


def _clip_fk_error(x, tree, frames_step=1):
    x = x[::frames_step]
    lengths = np.median(m.segment_lengths(x), axis=0)
    w, a, _ = tree.solve(x)
    fk = tree.joint_positions(lengths, x[:, m.ROOT], w, a)
    return np.linalg.norm(fk - x, axis=-1).max()


def test_urdf_is_a_tree_with_rep155_names():
    tree = human_tree('u3')
    urdf = tree.urdf(m.standard_body().segment_lengths, 'human_u3')
    root, joints = parse_urdf(urdf)
    assert root == 'body_u3'
    names = {j['name'] for j in joints.values()}
    for frame in ('head_u3', 'l_shoulder_u3', 'r_elbow_u3', 'l_wrist_u3', 'l_hand_u3',
                  'r_hip_u3', 'l_knee_u3', 'r_ankle_u3', 'torso_u3', 'waist_u3'):
        assert frame in joints, frame
    for joint in ('l_y_shoulder_u3', 'l_p_shoulder_u3', 'l_r_shoulder_u3', 'l_elbow_u3',
                  'r_knee_u3', 'y_waist_u3', 'r_y_hip_u3'):
        assert joint in names, joint
    assert set(tree.joint_names) == {j['name'] for j in joints.values() if j['type'] == 'revolute'}
    # ball joints: 3 revolutes each, hinges (elbows, knees): one
    assert len(tree.joint_names) == 3 * 15 + 4
    assert JOINT_FRAMES[m.HEAD] == 'head' and JOINT_FRAMES[m.HAND_LEFT] == 'l_hand'
    assert len(set(JOINT_FRAMES)) == m.NUM_JOINTS


def test_rest_posture_is_zero_angles_and_urdf_fk_gives_it_back():
    body = m.standard_body(1.62)
    x = body.rest_positions()[None]
    tree = human_tree('a')
    w, a, _ = tree.solve(x)
    assert np.abs(a).max() < 1e-9
    urdf = tree.urdf(body.segment_lengths, 'h')
    p = _urdf_positions(urdf, tree, a[0], x[0, m.ROOT], w[0], body.segment_lengths)
    assert np.abs(p - x[0]).max() < 1e-6   # (the URDF holds 6 digits)


@pytest.mark.parametrize('clip', builtin_clips(seed=7), ids=lambda c: c.name)
def test_fk_of_solved_angles_reproduces_builtin_motions(clip):
    tree = human_tree('b')
    x = np.asarray(clip.positions, float)
    assert _clip_fk_error(x, tree) < 1e-6
    # and through the URDF text, on a few frames
    urdf = tree.urdf(np.median(m.segment_lengths(x), axis=0), 'h')
    w, a, _ = tree.solve(x[::45])
    for i, xi in enumerate(x[::45]):
        p = _urdf_positions(urdf, tree, a[i], xi[m.ROOT], w[i], m.segment_lengths(xi))
        assert np.linalg.norm(p - xi, axis=-1).max() < 1e-6


def test_fk_of_solved_angles_reproduces_cmu_clips(shared_dir):
    from skeleton_data.mocap import load_cmu_clip
    tree = human_tree('c')
    for name in ('08_01.bvh', '09_02.bvh', '13_29.bvh', '86_02.bvh'):
        path = shared_dir / 'mocap' / 'cmu' / name
        if not path.exists():
            continue
        x = np.asarray(load_cmu_clip(path).positions, float)
        # CMU imports have constant bone lengths: FK with the median lengths is exact to 1 cm
        assert _clip_fk_error(x, tree, 3) < 0.01, name


def test_lengths_off_by_millimetres_cost_only_millimetres():
    """Positions whose segments differ from the URDF's lengths by up to 2 mm come back within
    the summed length errors along the chain (< 1 cm at the hands and feet)."""
    rng = np.random.default_rng(1)
    clip = builtin_clips(seed=3)[3]
    x = np.asarray(clip.positions, float)
    tree = human_tree('d')
    lengths = m.segment_lengths(x[0])
    off = lengths + rng.uniform(-0.002, 0.002, lengths.shape)
    w, a, _ = tree.solve(x)
    fk = tree.joint_positions(off, x[:, m.ROOT], w, a)
    assert np.linalg.norm(fk - x, axis=-1).max() < 0.01


def test_hinges_bend_forward_and_the_body_frame_faces_forward():
    body = m.standard_body()
    x = body.rest_positions().copy()
    # left forearm bent 90 degrees forward (+x): positive flexion, elbow axis -z in T-pose
    e, w = x[m.ELBOW_LEFT], x[m.WRIST_LEFT]
    lf = np.linalg.norm(w - e)
    shift = np.array([lf, -lf, 0.0])
    for j in (m.WRIST_LEFT, m.HAND_LEFT):
        x[j] = x[j] + shift * (1.0 if j == m.WRIST_LEFT else 1.0)
    x[m.HAND_LEFT] = x[m.WRIST_LEFT] + np.array([np.linalg.norm(
        body.rest_offsets[m.HAND_LEFT]), 0.0, 0.0])
    tree = human_tree('e')
    wr, a, _ = tree.solve(x[None])
    angle = dict(zip(tree.joint_names, a[0]))
    assert angle['l_elbow_e'] == pytest.approx(math.pi / 2, abs=1e-6)
    assert np.allclose(wr[0], np.eye(3), atol=1e-9)  # facing +x, z up
    # a body turned 90 degrees left: body frame x is world +y
    rz = from_euler_zyx(np.array([math.pi / 2, 0.0, 0.0]))
    wr, _, _ = tree.solve((x @ rz.T)[None])
    assert np.allclose(wr[0][:, 0], [0.0, 1.0, 0.0], atol=1e-9)


def test_rotation_helpers_round_trip():
    rng = np.random.default_rng(0)
    a = rng.uniform([-3, -1.5, -3], [3, 1.5, 3], (50, 3))
    r = from_euler_zyx(a)
    assert np.allclose(euler_zyx(r), a, atol=1e-9)
    q = quat_from_matrices(r)
    for qi, ri in zip(q, r):
        assert np.allclose(matrix_from_quat(qi), ri, atol=1e-9)


def _frame(uid, x):
    return SkeletonFrame(positions=x, tracking_state=np.full(m.NUM_JOINTS, m.TRACKED, np.uint8),
                         user_id=uid)


def test_tracker_bodies_come_and_go_and_urdf_is_made_again_only_on_change():
    clip = builtin_clips(seed=2)[0]
    x = np.asarray(clip.positions, float)
    tr = BodyTracker(window=10, length_tolerance=0.005, min_urdf_period=0.0, openni=True)
    out = tr.update([_frame(1, x[0]), _frame(4, x[0] + 1.0)], 0, 'kinect_link', 0.0)
    assert out.tracked == ['u1', 'u4'] and set(out.urdf) == {'u1', 'u4'} and not out.left
    assert ('kinect_link', 'body_u1') in out.tf_pairs and ('kinect_link', 'left_hand_4') in out.tf_pairs
    assert len(out.tf_pairs) == len(out.tf_translations) == len(out.tf_rotations)
    i = out.tf_pairs.index(('kinect_link', 'left_hand_4'))
    assert np.allclose(out.tf_translations[i], x[0, m.WRIST_LEFT] + 1.0)
    out = tr.update([_frame(1, x[1]), _frame(4, x[1] + 1.0)], 1, 'kinect_link', 0.1)
    assert not out.urdf   # same lengths: the latched URDF stands
    # user 4 grows by 5 %: a new URDF once the median over the window moved
    grown = [tr.update([_frame(1, x[k]), _frame(4, x[0, 0] + 1.05 * (x[k] - x[0, 0]) + 1.0)],
                       k, 'kinect_link', 0.1 * k).urdf for k in range(2, 14)]
    assert any('u4' in g for g in grown) and not any('u1' in g for g in grown)
    out = tr.update([_frame(1, x[20])], 20, 'kinect_link', 2.0)
    assert out.tracked == ['u1'] and out.left == ['u4']
    assert not any('_4' in c or 'u4' in c for _, c in out.tf_pairs)
    # a malformed (NaN) skeleton is not a body
    bad = x[21].copy()
    bad[3] = np.nan
    out = tr.update([_frame(1, x[21]), _frame(5, bad)], 21, 'kinect_link', 2.1)
    assert out.tracked == ['u1']


def test_joint_states_with_stretch_give_positions_of_varying_lengths_back():
    """Segment lengths that move frame to frame (a reconstruction that is not yet rigid) come back
    exactly, whichever URDF the consumer has: each segment's prismatic ``<link>_length`` joint
    carries its length in the frame."""
    rng = np.random.default_rng(4)
    x = np.asarray(builtin_clips(seed=6)[4].positions, float)[:40]
    rel = m.parent_relative(x)
    rel[:, 1:] *= 1.0 + rng.uniform(-0.03, 0.03, (len(x), m.NUM_JOINTS - 1, 1))
    x = m.forward_kinematics(rel, x[:, m.ROOT])
    tr = BodyTracker(window=10, min_urdf_period=0.0)
    urdf, urdfs = None, set()
    for k, xk in enumerate(x):
        out = tr.update([_frame(7, xk)], k, 'kinect_link', float(k))
        urdf = urdf or out.urdf.get('u7')   # the first one: joint states do not depend on it
        urdfs.update(out.urdf.values())
        values = dict(zip(out.joint_names['u7'], out.angles['u7']))
        assert len(values) == 49 + 19
        i = out.tf_pairs.index(('kinect_link', 'body_u7'))
        root_t, root_r = out.tf_translations[i], matrix_from_quat(out.tf_rotations[i])
        poses = forward_kinematics_urdf(urdf, values)
        p = np.array([root_t + root_r @ poses[f'{f}_u7'][1] for f in JOINT_FRAMES])
        assert np.linalg.norm(p - xk, axis=1).max() < 1e-6
        # and the transforms on TF chain up to the same positions
        if k % 13 == 0:
            parent = {c: (pp, t, q) for (pp, c), t, q in zip(
                out.tf_pairs, out.tf_translations, out.tf_rotations)}

            def world(frame, parent=parent):
                r, t = np.eye(3), np.zeros(3)
                while frame != 'kinect_link':
                    pp, tt, qq = parent[frame]
                    r, t = matrix_from_quat(qq) @ r, matrix_from_quat(qq) @ t + tt
                    frame = pp
                return t
            q = np.array([world(f'{f}_u7') for f in JOINT_FRAMES])
            assert np.linalg.norm(q - xk, axis=1).max() < 1e-6
    assert len(urdfs) > 1   # the lengths moved: the URDF was made again on the way


def test_tf_encoder_bytes_are_the_tfmessage_rclpy_reads():
    pytest.importorskip('rclpy')
    from rclpy.serialization import deserialize_message
    from tf2_msgs.msg import TFMessage

    from skeleton_core.rep155 import TfEncoder
    rng = np.random.default_rng(3)
    enc = TfEncoder()
    for n_users in (1, 3, 2):   # the layout is made again when the frames change
        clip = builtin_clips(seed=n_users)[0]
        out = BodyTracker(openni=True).update(
            [_frame(u + 1, np.asarray(clip.positions[u])) for u in range(n_users)],
            1_700_000_000_123_456_789, 'kinect_link', 0.0)
        t = out.tf_translations + rng.normal(0, 1e-3, out.tf_translations.shape)
        msg = deserialize_message(enc.encode(out.tf_pairs, out.stamp_ns, t, out.tf_rotations),
                                  TFMessage)
        assert [(m.header.frame_id, m.child_frame_id) for m in msg.transforms] == out.tf_pairs
        assert {(m.header.stamp.sec, m.header.stamp.nanosec) for m in msg.transforms} == \
            {(1_700_000_000, 123_456_789)}
        got = np.array([[m.transform.translation.x, m.transform.translation.y,
                         m.transform.translation.z, m.transform.rotation.x, m.transform.rotation.y,
                         m.transform.rotation.z, m.transform.rotation.w] for m in msg.transforms])
        assert np.array_equal(got, np.concatenate([t, out.tf_rotations], axis=1))
