"""CMU import (one small clip from ../shared) and the clip split / mirroring (synthetic clips)."""
import numpy as np
import pytest

from skeleton_data.bvh import load_bvh
from skeleton_core.geometry import facing_yaw, quat_rotate
from skeleton_data.mocap import (CMU_TO_KINECT, CMU_UNIT, BVH_TO_REP103, MotionClip,
                                 load_cmu_clip, load_cmu_clips, mirror_clip, rest_directions,
                                 split_clips)
from skeleton_core.model import (HIP_LEFT, HIP_RIGHT, JOINT_NAMES, PARENTS, ROOT, segment_lengths,
                                 standard_body)


@pytest.fixture(scope='module')
def walk(shared_dir):
    return load_cmu_clip(shared_dir / 'mocap' / 'cmu' / '08_01.bvh')


def test_mapping_covers_every_kinect_joint():
    assert set(CMU_TO_KINECT) == set(JOINT_NAMES)
    for name, pts in CMU_TO_KINECT.items():
        assert sum(w for _, w in pts) == pytest.approx(1.0), name
    assert np.linalg.det(BVH_TO_REP103) == pytest.approx(1.0)  # a rotation, not a mirror


def test_tpose_dropped_and_units(walk, shared_dir):
    bvh = load_bvh(shared_dir / 'mocap' / 'cmu' / '08_01.bvh')
    assert len(walk) == bvh.num_frames - 1
    assert walk.fps == pytest.approx(30.0, rel=1e-4)
    assert walk.motion_class == 'locomotion'
    # first clip frame is BVH frame 1 (frame 0 is the synthetic T-pose)
    pos, _, _ = bvh.forward_kinematics(bvh.motion[1:2], scale=CMU_UNIT)
    hips = BVH_TO_REP103 @ pos[0, bvh.index('Hips')]
    np.testing.assert_allclose(walk.positions[0, ROOT], hips, atol=1e-9)


def test_walk_hip_height_speed_and_axes(walk):
    p = walk.positions
    assert 0.87 <= np.median(p[:, ROOT, 2]) <= 1.0
    speed = np.linalg.norm(p[-1, ROOT, :2] - p[0, ROOT, :2]) / ((len(walk) - 1) / walk.fps)
    assert 1.2 <= speed <= 1.8
    # REP-103: left hip on +y of the right one when facing +x, walking forward along the facing
    heading = np.arctan2(*(p[-1, ROOT, :2] - p[0, ROOT, :2])[::-1])
    yaw = np.median(facing_yaw(p))
    assert abs(np.angle(np.exp(1j * (heading - yaw)))) < np.radians(20)
    assert np.all(p[:, :, 2] > -0.02)  # floor at z = 0
    assert np.min(p[:, [15, 19], 2]) < 0.03  # toes touch it


def test_orientations_follow_segments(walk):
    d = walk.positions[:, 1:] - walk.positions[:, list(PARENTS[1:])]
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    pred = quat_rotate(walk.orientations[:, 1:], rest_directions()[1:])
    np.testing.assert_allclose(pred, d, atol=1e-9)
    # the head segment's twist follows the CMU Head bone: its facing (x axis) stays forward-ish
    head_fwd = quat_rotate(walk.orientations[:, 3], np.array([1.0, 0, 0]))
    pelvis_fwd = quat_rotate(walk.orientations[:, 0], np.array([1.0, 0, 0]))
    assert np.all(np.sum(head_fwd[:, :2] * pelvis_fwd[:, :2], -1) > 0.7)
    np.testing.assert_allclose(np.linalg.norm(walk.orientations, axis=-1), 1.0, atol=1e-9)


def test_bad_file_skipped_and_reported(tmp_path, shared_dir):
    src = (shared_dir / 'mocap' / 'cmu' / '09_02.bvh').read_text()
    (tmp_path / '09_02.bvh').write_text(src)
    (tmp_path / 'broken.bvh').write_text(src[: len(src) // 2])
    skipped = []
    clips = load_cmu_clips(tmp_path, None, skipped=skipped)
    assert [c.name for c in clips] == ['09_02']
    assert skipped and skipped[0][0] == 'broken.bvh' and 'truncated MOTION' in skipped[0][1]


def _clip(name, cls, n):
    p = np.tile(standard_body().rest_positions(), (n, 1, 1))
    p[:, :, 0] += np.arange(n)[:, None] * 0.01
    q = np.zeros((n, 20, 4))
    q[..., 3] = 1
    return MotionClip(name, cls, 30.0, p, q, 'test')


def test_split_whole_clips_and_tail():
    clips = [_clip(f'w{i}', 'locomotion', 10) for i in range(10)] + [_clip('box', 'boxing', 100)]
    db, dev = split_clips(clips, 0.3)
    dev_names = [c.name for c in dev]
    assert dev_names == ['w1', 'w5', 'w8', 'box:dev']
    assert len(db) == 8 and db[-1].name == 'box:db'
    box_db, box_dev = db[-1], dev[-1]
    assert len(box_db) == 70 and len(box_dev) == 30
    np.testing.assert_array_equal(box_dev.positions[0], clips[-1].positions[70])
    assert split_clips(clips, 0.3)[1][0].name == 'w1'  # deterministic


def test_mirror_clip(walk):
    m = mirror_clip(walk)
    np.testing.assert_allclose(m.positions[:, HIP_LEFT, 1], -walk.positions[:, HIP_RIGHT, 1])
    np.testing.assert_allclose(segment_lengths(m.positions), segment_lengths(walk.positions)[:, [
        s for s in (0, 1, 2, 7, 8, 9, 10, 3, 4, 5, 6, 15, 16, 17, 18, 11, 12, 13, 14)]], atol=1e-12)
    d = m.positions[:, 1:] - m.positions[:, list(PARENTS[1:])]
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    pred = quat_rotate(m.orientations[:, 1:], rest_directions()[1:])
    assert np.degrees(np.arccos(np.clip(np.sum(d * pred, -1), -1, 1)))[:, 3:].max() < 1.0
    back = mirror_clip(m)
    np.testing.assert_allclose(back.positions, walk.positions)
