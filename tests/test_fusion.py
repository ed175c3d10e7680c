"""Multi-sensor fusion (pose_reconstruction.fusion): pass-through, reliability
weighting, mirror resolution, association, time alignment. ROS-free, fast."""
import numpy as np
import pytest

from pose_reconstruction.fusion import (FRAME_PERIOD_NS, MultiSensorFusion, facing, fuse_views,
                                        interpolate, mirror_labels)
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import (HAND_LEFT, HAND_RIGHT, HIP_CENTER, INFERRED, MIRROR, NUM_JOINTS,
                                 TRACKED, standard_body)
from skeleton_core.tf import Transform
from skeleton_eval.clips import toy_clip
from skeleton_eval.sensor_corrupter import _Corrupter
from skeleton_eval.sensor_model import SensorModel

FRONT = Transform.from_xyz_ypr(0.0, 0.0, 0.8)                              # at the origin, looking +x
SIDE = Transform.from_xyz_ypr(2.5, -2.5, 0.8, yaw=90.0)               # 90 deg: looking +y
BACK = Transform.from_xyz_ypr(5.0, 0.0, 0.8, yaw=180.0)                    # behind the user
DT = FRAME_PERIOD_NS


def person(x=2.5, y=0.0, yaw=np.pi, raise_left=True) -> np.ndarray:
    """A standing T-pose in world at (x, y) facing ``yaw`` (pi: towards FRONT), left hand raised."""
    p = standard_body().rest_positions()
    p = p - p[HIP_CENTER]
    if raise_left:
        p[HAND_LEFT] += (0.0, 0.0, 0.3)
    c, s = np.cos(yaw), np.sin(yaw)
    p = p @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T
    return p + (x, y, 1.0)


def seen(world: np.ndarray, pose: Transform, uid=1, stamp=0, rel=1.0, back=False) -> SkeletonFrame:
    """What a sensor at ``pose`` reports: its frame; a view of the back swaps left and right."""
    p = pose.inverse().apply(world)
    if back:
        p = p[list(MIRROR)]
    return SkeletonFrame(positions=p, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                         reliability=np.full(NUM_JOINTS, rel, np.float32), user_id=uid,
                         stamp_ns=stamp, frame_id='kinect_link')


def test_one_sensor_passes_through_bit_identical():
    fu = MultiSensorFusion({'kinect_1': SIDE})
    rng = np.random.default_rng(0)
    frames = [seen(person(), SIDE, uid=u) for u in (3, 7)]
    for f in frames:
        f.positions = f.positions + rng.normal(0, 0.01, f.positions.shape)
        f.reliability = np.full(NUM_JOINTS, np.nan, np.float32)
    fu.add('kinect_1', frames, 123)
    out, stamp, fid = fu.fuse()
    assert stamp == 123 and fid == 'kinect_link' and len(out) == 2
    for a, b in zip(out, frames):
        assert a.positions.tobytes() == b.positions.tobytes()
        assert a.tracking_state.tobytes() == b.tracking_state.tobytes()
        assert a.reliability.tobytes() == b.reliability.tobytes() and a.user_id == b.user_id


def test_two_views_fused_by_reliability():
    truth = person()
    a = seen(truth, FRONT, rel=0.9)
    b = seen(truth, SIDE, rel=0.9)
    # the front view gets the right hand wrong (occluded) and says so; the side sees it
    a.positions[HAND_RIGHT] += (0.0, 0.0, -0.4)
    a.reliability[HAND_RIGHT] = 0.1
    fu = MultiSensorFusion({'k1': FRONT, 'k2': SIDE})
    fu.add('k1', [a], 0)
    fu.add('k2', [b], 0)
    out, _, fid = fu.fuse()
    assert fid == 'world' and len(out) == 1
    f = out[0]
    # weights 0.1 / 0.9: the error shrinks to a tenth; elsewhere both agree with the truth
    assert np.linalg.norm(f.positions[HAND_RIGHT] - truth[HAND_RIGHT]) == pytest.approx(0.04, abs=1e-6)
    assert np.allclose(np.delete(f.positions, HAND_RIGHT, 0), np.delete(truth, HAND_RIGHT, 0))
    assert f.reliability[HAND_RIGHT] == pytest.approx(0.9)
    # a joint one view only infers follows the view that tracks it
    a.tracking_state[HAND_RIGHT] = INFERRED
    a.reliability[HAND_RIGHT] = 0.9
    g = fuse_views([a.copy(positions=FRONT.apply(a.positions)), b.copy(positions=SIDE.apply(b.positions))])
    err = np.linalg.norm(g.positions[HAND_RIGHT] - truth[HAND_RIGHT])
    assert err == pytest.approx(0.4 * 0.05 / 1.05, rel=1e-6)
    assert g.tracking_state[HAND_RIGHT] == TRACKED


def test_a_view_of_the_back_is_unmirrored():
    truth = person()                           # faces FRONT, back to BACK
    fu = MultiSensorFusion({'k1': FRONT, 'k2': BACK})
    back = seen(truth, BACK, rel=0.8, back=True)
    # the back view, as the sensor reports it, puts the raised (left) hand on the right
    assert np.linalg.norm(BACK.apply(back.positions)[HAND_RIGHT] - truth[HAND_LEFT]) < 1e-9
    assert facing(BACK.apply(back.positions)) @ facing(truth) < -0.99
    fu.add('k1', [seen(truth, FRONT, rel=0.9)], 0)
    fu.add('k2', [back], 0)
    out, _, _ = fu.fuse()
    assert len(out) == 1 and fu.stats.mirrored == 1
    assert np.allclose(out[0].positions, truth)
    # mirror_labels is an involution
    m = mirror_labels(mirror_labels(back))
    assert np.array_equal(m.positions, back.positions)


def test_association_two_people_stable_ids():
    p1, p2 = person(2.5, 0.8), person(2.5, -0.8, raise_left=False)
    fu = MultiSensorFusion({'k1': FRONT, 'k2': SIDE})
    ids = None
    for k in range(3):
        # the sensors number the people differently, and sensor 2 swaps its numbers at frame 2
        fu.add('k1', [seen(p1, FRONT, uid=1, stamp=k * DT), seen(p2, FRONT, uid=2, stamp=k * DT)], k * DT)
        u = (5, 6) if k < 2 else (6, 5)
        fu.add('k2', [seen(p2, SIDE, uid=u[0], stamp=k * DT), seen(p1, SIDE, uid=u[1], stamp=k * DT)], k * DT)
        out, _, _ = fu.fuse()
        assert len(out) == 2
        by_pos = {round(float(f.positions[HIP_CENTER, 1]), 3): f.user_id for f in out}
        assert set(by_pos) == {0.8, -0.8}
        for f in out:
            truth = p1 if f.positions[HIP_CENTER, 1] > 0 else p2
            assert np.allclose(f.positions, truth)
        ids = ids or by_pos
        assert by_pos == ids                   # a person keeps its fused id
    # a person 2 m away from every track is a new one
    fu.add('k1', [seen(person(4.5, 3.0), FRONT, uid=9, stamp=3 * DT)], 3 * DT)
    fu.add('k2', [], 3 * DT)
    out, _, _ = fu.fuse()
    assert len(out) == 1 and out[0].user_id not in ids.values()


def test_interpolation_to_a_common_stamp_and_late_sensor():
    a0, a1 = person(2.5, 0.0), person(2.7, 0.0)
    f0 = SkeletonFrame(positions=a0, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                       reliability=np.full(NUM_JOINTS, 0.5, np.float32), stamp_ns=0)
    f1 = f0.copy(positions=a1, stamp_ns=DT)
    mid = interpolate(f0, f1, DT // 4)
    assert np.allclose(mid.positions, 0.75 * a0 + 0.25 * a1)
    assert interpolate(f0, f1, 2 * DT) is f1 and interpolate(f0, f1, -5) is f0
    # sensor 2 captures half a frame after sensor 1; the fusion interpolates sensor 1 to its stamp
    fu = MultiSensorFusion({'k1': FRONT, 'k2': SIDE})
    fu.add('k1', [seen(a0, FRONT, stamp=0)], 0)
    fu.add('k1', [seen(a1, FRONT, stamp=DT)], DT)
    half = person(2.6, 0.0)
    fu.add('k2', [seen(half, SIDE, stamp=DT // 2)], DT // 2)
    out, stamp, _ = fu.fuse(DT // 2)
    assert stamp == DT // 2 and np.allclose(out[0].positions, half, atol=1e-6)
    # a sensor silent for more than a frame is left out, not waited for
    fu.add('k1', [seen(person(3.0, 0.0), FRONT, stamp=3 * DT)], 3 * DT)
    out, stamp, _ = fu.fuse()
    assert stamp == 3 * DT and len(out) == 1 and fu.stats.late == 1
    assert np.allclose(out[0].positions, person(3.0, 0.0))


def test_reliability_computed_per_sensor_when_missing():
    truth = person()
    fu = MultiSensorFusion({'k1': FRONT, 'k2': SIDE})
    for k in range(5):
        a, b = seen(truth, FRONT, stamp=k * DT), seen(truth, SIDE, stamp=k * DT)
        a.reliability[:] = np.nan
        b.reliability[:] = np.nan
        fu.add('k1', [a], k * DT)
        fu.add('k2', [b], k * DT)
        out, _, _ = fu.fuse()
    assert np.all(np.isfinite(out[0].reliability)) and np.allclose(out[0].positions, truth)


def test_unknown_sensor_and_no_sensor_are_one_line_errors():
    with pytest.raises(ValueError, match='at least one'):
        MultiSensorFusion({})
    with pytest.raises(KeyError, match='unknown sensor'):
        MultiSensorFusion({'k1': FRONT}).add('k9', [], 0)


def test_sensor_model_views_share_one_object():
    """Class b's table is one object in the room: each view sees it where it stands (before, every
    view drew its own table in front of itself and the side view lost the same legs)."""
    model = SensorModel(seed=0)
    clip = toy_clip(2.0)
    side = Transform.from_xyz_ypr(2.5, -2.5, 0.0, yaw=90.0)
    ref = _Corrupter(model, clip, 'b', 7, Transform.identity())
    view = _Corrupter(model, clip, 'b', 7, side)
    lo, hi = ref.box
    corners = side.apply(np.array([view.box[0], view.box[1]]))
    assert np.allclose(np.sort(corners, axis=0), np.stack([lo, hi]), atol=1e-9)
    # the table stands between the user and the reference sensor: in the side view it is beside
    # the user (its y range, the side sensor's depth, overlaps the user's), not in front
    root = view.truth_all[:, HIP_CENTER]
    assert view.box[0][0] < np.median(root[:, 0]) < view.box[1][0] + 1.0


def test_a_joint_no_view_tracks_is_held_relative_to_its_parent():
    """A hand both sensors lose is reported by each at the place it left the room (the Kinect's
    held INFERRED joint); the fused hand stays where the track last saw it *from its parent* and
    moves with the body (here: the person walks 0.5 m while the hand is lost)."""
    fu = MultiSensorFusion({'k1': FRONT, 'k2': SIDE})
    for i in range(12):
        truth = person(y=0.05 * i)
        a, b = seen(truth, FRONT, stamp=i * DT), seen(truth, SIDE, stamp=i * DT)
        if i >= 2:      # lost by both: each view holds the hand where it last saw it
            for f, pose in ((a, FRONT), (b, SIDE)):
                f.positions[HAND_RIGHT] = pose.inverse().apply(person(y=0.05)[None])[0, HAND_RIGHT]
                f.tracking_state[HAND_RIGHT] = INFERRED
                f.reliability[HAND_RIGHT] = 0.0
        fu.add('k1', [a], i * DT)
        fu.add('k2', [b], i * DT)
        (f,), _, _ = fu.fuse()
    assert f.tracking_state[HAND_RIGHT] == INFERRED and f.reliability[HAND_RIGHT] == 0.0
    assert np.linalg.norm(f.positions[HAND_RIGHT] - truth[HAND_RIGHT]) < 1e-6
    # the views' held hand is 0.5 m behind
    assert np.linalg.norm(person(y=0.05)[HAND_RIGHT] - truth[HAND_RIGHT]) == pytest.approx(0.5)


def test_evaluation_layouts_place_the_two_sensors_90_deg_apart():
    """evaluate --sensors 2: front-side = the front sensor itself + one on the user's side;
    diagonal = both 2.5 m from the user, 90 deg apart, 45 deg either side of the front, facing
    the user; an unknown layout is a one-line error."""
    from kinect_experiments.fusion_eval import view_poses
    sensor = SensorModel(None, seed=0)
    d = sensor.params['placement']['distance_m']
    user = np.array([d, sensor.params['placement']['lateral_offset_m'], 0.0])
    fs = view_poses(sensor, 2, 'front-side')
    assert fs[0].is_identity()
    for poses, off in ((fs, (0.0, 90.0)), (view_poses(sensor, 2, 'diagonal'), (45.0, 45.0))):
        dirs = []
        for pose, o in zip(poses, off):
            to_user = user - pose.translation
            assert np.linalg.norm(to_user) == pytest.approx(d)
            x = pose.apply(np.array([[1.0, 0.0, 0.0]]))[0] - pose.translation
            assert np.dot(x, to_user) / d == pytest.approx(1.0)      # it faces the user
            dirs.append(to_user / d)
            # the angle from the user's front (the user faces the front sensor, -x)
            ang = np.degrees(np.arccos(np.clip(dirs[-1] @ [1.0, 0.0, 0.0], -1, 1)))
            assert ang == pytest.approx(o)
        assert np.degrees(np.arccos(np.clip(dirs[0] @ dirs[1], -1, 1))) == pytest.approx(90.0)
    with pytest.raises(ValueError, match='unknown layout'):
        view_poses(sensor, 2, 'ring')


def test_limbs_a_view_swapped_are_swapped_back_before_the_mean():
    """A sensor that swaps the user's left and right arms (a confident failure, TRACKED): its
    Eq. 1-8 plausibility flags the swap and keeps the arms' reliability (the reconstruction swaps
    them back); the fusion swaps them back too, so the fused left hand is the left hand, not the
    mean of one view's left and the other's right."""
    from skeleton_core.model import LIMB_JOINTS
    arms_l, arms_r = list(LIMB_JOINTS['left_arm']), list(LIMB_JOINTS['right_arm'])
    fu = MultiSensorFusion({'k1': FRONT, 'k2': SIDE})
    for i in range(20):
        truth = person(y=0.01 * i)
        views = [seen(truth, FRONT, stamp=i * DT), seen(truth, SIDE, stamp=i * DT)]
        for v in views:
            v.reliability = np.full(NUM_JOINTS, np.nan, np.float32)    # the fusion computes Eq. 1-8
        if i == 19:
            p = views[0].positions
            p[arms_l + arms_r] = p[arms_r + arms_l]
        fu.add('k1', [views[0]], i * DT)
        fu.add('k2', [views[1]], i * DT)
        (f,), _, _ = fu.fuse()
    assert fu.stats.unswapped == 1
    assert np.linalg.norm(f.positions[HAND_LEFT] - truth[HAND_LEFT]) < 1e-6
    assert np.linalg.norm(truth[HAND_LEFT] - truth[HAND_RIGHT]) > 1.0


@pytest.mark.parametrize('layout,scenario', [('front-side', 'c'), ('diagonal', 'd')])
def test_compiled_fusion_agrees_with_numpy(layout, scenario):
    """The compiled per-track step (fusion_kernels.fuse_track: mirror, weighted mean, hold,
    facing) and the numpy twin give the same fused skeletons on sensor-model views of 3 users
    (2 sensors, occlusion (c) or confident failures (d), Eq. 1-8 per sensor): the same tracks,
    states, reliabilities and mirror decisions, positions equal to float rounding (the twin's
    facing is float32 arithmetic, the kernel's float64). A third sensor behind the user sees the
    back: its left and right are mirrored."""
    from skeleton_core import jit
    if not jit.enabled():
        pytest.skip('numba off: the numpy twin is the only path')
    from kinect_experiments.fusion_eval import view_poses
    sensor = SensorModel(None, seed=7)
    poses = view_poses(sensor, 2, layout)
    d = sensor.params['placement']['distance_m']
    poses.append(Transform.from_xyz_ypr(2 * d, sensor.params['placement']['lateral_offset_m'],
                                        0.0, yaw=180.0))
    streams = [sensor.corrupt(toy_clip(), scenario, seed=7, max_frames=150, view=p) for p in poses]
    fus = {}
    for compiled in (True, False):
        fu = MultiSensorFusion({f'k{k}': p for k, p in enumerate(poses)})
        fu._jit = compiled
        fus[compiled] = fu
    shifts = [(0.0, y, 0.0) for y in (-1.0, 0.0, 1.0)]
    held = 0
    for i in range(len(streams[0])):
        for fu in fus.values():
            for k, s in enumerate(streams):
                inv = poses[k].inverse()
                d = [inv.apply(np.asarray([sh]))[0] - inv.apply(np.zeros((1, 3)))[0] for sh in shifts]
                fu.add(f'k{k}', [SkeletonFrame(positions=s.positions[i] + d[u],
                                               tracking_state=s.tracking_state[i].copy(),
                                               user_id=u + 1, stamp_ns=int(s.stamps_ns[i]))
                                 for u in range(len(shifts))], int(s.stamps_ns[i]))
        a, _, _ = fus[True].fuse()
        b, _, _ = fus[False].fuse()
        assert [f.user_id for f in a] == [f.user_id for f in b]
        for fa, fb in zip(a, b):
            assert np.array_equal(fa.tracking_state, fb.tracking_state)
            assert fa.reliability.tobytes() == fb.reliability.tobytes()
            np.testing.assert_allclose(fa.positions, fb.positions, rtol=0, atol=1e-12)
            held += int((fa.tracking_state != TRACKED).sum())
    assert fus[True].stats.mirrored == fus[False].stats.mirrored > 0
    assert held > 0                      # the streams exercise the hold (step 7)
