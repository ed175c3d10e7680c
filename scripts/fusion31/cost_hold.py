from skeleton_eval.clips import load_clips
from skeleton_eval.sensor_model import SensorModel
from kinect_experiments import fusion_eval as FE
from pose_reconstruction import fusion as F
_, dev, _ = load_clips('auto', 5)
sensor = SensorModel(None, seed=5)
poses = FE.view_poses(sensor, 2)
longest = max(dev, key=lambda c: len(c.positions))
streams = [sensor.corrupt(longest, 'c', seed=5, max_frames=300, view=p) for p in poses]
res = {True: [], False: []}
for rep in range(3):
    for h in (True, False):
        F.HOLD_RELATIVE = h
        res[h].append(FE.fusion_cost(streams, poses))
for h in (True, False):
    print('hold' if h else 'no hold',
          *(f'{key} {[round(r[key], 3) for r in res[h]]}' for key in ('cpu_mean_ms', 'mean_ms', 'p95_ms')))
