"""Profile the fusion over a generated 2-sensor x 6-user stream (class c, seed 5, 300 frames)."""
import sys
import cProfile
import pstats
from skeleton_eval.clips import load_clips
from skeleton_eval.sensor_model import SensorModel
from kinect_experiments import fusion_eval as FE

_, dev, _ = load_clips('auto', 5)
sensor = SensorModel(None, seed=5)
poses = FE.view_poses(sensor, 2)
longest = max(dev, key=lambda c: len(c.positions))
streams = [sensor.corrupt(longest, 'c', seed=5, max_frames=300, view=p) for p in poses]
if len(sys.argv) > 1 and sys.argv[1] == 'prof':
    cProfile.run('c = FE.fusion_cost(streams, poses)', '/tmp/fusion3.prof')
    pstats.Stats('/tmp/fusion3.prof').sort_stats('cumtime').print_stats(35)
else:
    for _ in range(int(sys.argv[1]) if len(sys.argv) > 1 else 1):
        c = FE.fusion_cost(streams, poses)
        print(c)
