"""Fusion cost, the compiled per-track step (new) against the numpy twin (old), alternating in one
process: 2 sensors (front + side), class c, seed 5, 1 / 3 / 6 users; ROUNDS rounds each.
Usage: ab_cost.py [ROUNDS] [FRAMES]. Prints per configuration the median over rounds of the mean
wall and thread-CPU ms per frame and user (Eq. 1-8 included and without it)."""
import sys
import numpy as np
from skeleton_eval.clips import load_clips
from skeleton_eval.sensor_model import SensorModel
from kinect_experiments import fusion_eval as FE
from pose_reconstruction import fusion as F

rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 3
frames = int(sys.argv[2]) if len(sys.argv) > 2 else 200
_, dev, _ = load_clips('auto', 5)
sensor = SensorModel(None, seed=5)
poses = FE.view_poses(sensor, 2)
longest = max(dev, key=lambda c: len(c.positions))
streams = [sensor.corrupt(longest, 'c', seed=5, max_frames=frames, view=p) for p in poses]
orig = F.MultiSensorFusion.__post_init__
mode = {'jit': True}


def post_init(self):
    orig(self)
    self._jit = self._jit and mode['jit']


F.MultiSensorFusion.__post_init__ = post_init
FE.fusion_cost(streams[:], poses, users=1)          # warm-up (compile / cache load)
res = {}
for r in range(rounds):
    for users in (1, 3, 6):
        for name, on in (('old', False), ('new', True)):
            mode['jit'] = on
            c = FE.fusion_cost(streams, poses, users=users)
            res.setdefault((users, name), []).append(c)
print('users version  wall_ms  no_eq8_wall_ms  cpu_ms   (median of', rounds, 'rounds, per frame and user)')


def med(cs, k):
    return float(np.median([c[k] for c in cs]))


for (users, name), cs in sorted(res.items()):
    print(f'{users:5d} {name:7s} {med(cs, "mean_ms"):8.3f} {med(cs, "no_eq8_mean_ms"):15.3f} '
          f'{med(cs, "cpu_mean_ms"):7.3f}')
