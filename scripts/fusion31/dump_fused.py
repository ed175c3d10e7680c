"""Dump the fusion's output (2 sensors x 6 users, classes a/c/d, seeds 5-6) to compare commits."""
import sys
import numpy as np
from skeleton_eval.clips import load_clips
from skeleton_eval.sensor_model import SensorModel
from skeleton_core.conversions import SkeletonFrame
from kinect_experiments import fusion_eval as FE
from pose_reconstruction.fusion import MultiSensorFusion

_, dev, _ = load_clips('auto', 5)
out = {}
for seed in (5, 6):
    sensor = SensorModel(None, seed=seed)
    poses = FE.view_poses(sensor, 2)
    for sc in ('a', 'c', 'd'):
        for ci, clip in enumerate(dev[:3]):
            streams = [sensor.corrupt(clip, sc, seed=seed, max_frames=200, view=p) for p in poses]
            fu = MultiSensorFusion({f'kinect_{k + 1}': p for k, p in enumerate(poses)}, frame_id='world')
            shifts = [(0.0, (u - 2.5) * 1.0, 0.0) for u in range(6)]
            P, R, T = [], [], []
            for i in range(len(streams[0])):
                for k, s in enumerate(streams):
                    inv = poses[k].inverse()
                    d = [inv.apply(np.asarray([sh]))[0] - inv.apply(np.zeros((1, 3)))[0] for sh in shifts]
                    fu.add(f'kinect_{k + 1}', [SkeletonFrame(positions=s.positions[i] + d[u],
                           tracking_state=s.tracking_state[i].copy(), user_id=u + 1,
                           stamp_ns=int(s.stamps_ns[i])) for u in range(6)], int(s.stamps_ns[i]))
                fr, _, _ = fu.fuse()
                fr = sorted(fr, key=lambda f: f.positions[0, 1])
                P.append(np.stack([f.positions for f in fr]))
                R.append(np.stack([f.reliability for f in fr]))
                T.append(np.stack([f.tracking_state for f in fr]))
            key = f'{seed}_{sc}_{ci}'
            m = max(len(x) for x in P)      # the number of tracks varies (class d: jumps)

            def pad(xs, fill, m=m):
                return np.stack([np.concatenate([x, np.full((m - len(x),) + x.shape[1:], fill, x.dtype)])
                                 for x in xs])
            out[key + '_p'], out[key + '_r'], out[key + '_t'] = pad(P, np.nan), pad(R, np.nan), pad(T, 255)
np.savez(sys.argv[1], **out)
print('saved', len(out))
