"""Two Azure Kinect body trackers (the sensor model's ``azure_kinect_bt`` variant: every joint
reported TRACKED, unseen joints predicted), front + side: the extrinsic calibration from the
skeletons recovers the side sensor (<= 3 cm, <= 2 deg, the clock offset), and the fused raw
skeleton is closer to the truth than either camera alone. ROS-free. The seeds were not tuned on
(nothing in the calibration or the fusion was changed for this tracker)."""
import numpy as np
import pytest

from kinect_experiments.fusion_eval import fused_frames, in_reference, view_poses
from skeleton_core.tf import Transform
from skeleton_data.motions import builtin_clips
from skeleton_eval.extrinsics import calibrate, synthetic_tracks
from skeleton_eval.metrics import eq18_error, mpjpe
from skeleton_eval.sensor_model import SensorModel
from skeleton_eval.sensor_params import tracker_params

AZURE = tracker_params('azure_kinect_bt')
SIDE = Transform.from_xyz_ypr(2.5, 2.5, 0.0, yaw=-90.0)   # calibrate_extrinsics --synthetic's view


@pytest.mark.parametrize('seed', [1, 2])
def test_two_azure_sensors_calibrated_from_the_skeletons(seed):
    a, b, _ = synthetic_tracks(SIDE, seed=seed, scenario='a', clock_offset_s=0.31, phase_s=0.012,
                               sensor_params=AZURE)
    # no joint states, as in the ROS driver's message
    assert (a.tracking_state == 2).all() and (b.tracking_state == 2).all()
    c = calibrate(a, b, seed=seed)
    d, ang = c.transform.distance(SIDE)
    assert d <= 0.03 and ang <= 2.0, (d, ang, c.transform)
    assert abs(c.time_offset_s - 0.31) < 0.011


def test_two_azure_sensors_fused_raw_beats_either_alone():
    sensor = SensorModel(AZURE, seed=5)
    poses = view_poses(sensor, 2, 'front-side')
    err = {'front': [], 'side': [], 'fused': []}
    for clip in builtin_clips(seed=5, duration=8.0)[:3]:
        for scenario in ('a', 'b'):
            views = [sensor.corrupt(clip, scenario, seed=5, view=p) for p in poses]
            truth = views[0].truth
            fused = np.stack([f.positions for f in fused_frames(views, poses)])
            side = in_reference(views[1], poses[1])
            assert np.allclose(side.truth, truth, atol=1e-9)
            for key, pos in (('front', views[0].positions), ('side', side.positions),
                             ('fused', fused)):
                err[key].append((eq18_error(pos, truth)[1], mpjpe(pos, truth)[1]))
    mean = {k: np.mean(v, axis=0) for k, v in err.items()}
    for k in ('front', 'side'):   # Eq. 18 and MPJPE: the fused raw below either camera alone
        assert mean['fused'][0] < 0.95 * mean[k][0], mean
        assert mean['fused'][1] < mean[k][1], mean


def test_left_right_swaps_of_a_stateless_stream_are_undone():
    """Walking round the loop, the view of the back is reported with left and right swapped
    (TRACKED: no states); ``unmirrored`` labels them as the truth again. A stream with states
    (the Kinect model) is returned as it is."""
    from skeleton_core.model import MIRROR
    from skeleton_eval.extrinsics import unmirrored
    a, _, truth = synthetic_tracks(SIDE, seed=2, scenario='a', sensor_params=AZURE)

    def swapped(pos):
        d = np.linalg.norm(pos - truth, axis=-1).mean(axis=1)
        m = np.linalg.norm(pos[:, list(MIRROR)] - truth, axis=-1).mean(axis=1)
        return m < d
    assert swapped(a.positions).mean() > 0.1      # the back views: swapped
    assert swapped(unmirrored(a).positions).mean() < 0.02
    k, _, _ = synthetic_tracks(SIDE, seed=2, scenario='a')
    assert unmirrored(k) is k
