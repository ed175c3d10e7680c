"""Fused raw Eq. 18 with a constant front-view weight on the joints both views track (the fusion
elsewhere): is one view systematically better? Usage: const_weight.py SEED CLASS (front + side,
13 dev clips x 100 frames)."""
import sys

import numpy as np

from kinect_experiments.fusion_breakdown import segment_error_cm
from kinect_experiments.fusion_eval import fused_frames, view_poses
from skeleton_core.model import TRACKED
from skeleton_eval.clips import load_clips
from skeleton_eval.sensor_model import SensorModel

seed, sc = int(sys.argv[1]), sys.argv[2]
_, dev, _ = load_clips('auto', seed)
sensor = SensorModel(None, seed=seed)
poses = view_poses(sensor, 2, 'front-side')
W = (0.5, 0.6, 0.7, 0.8, 1.0)
acc = {w: 0.0 for w in W}
base = fz = 0.0
n = 0
for clip in dev:
    views = [sensor.corrupt(clip, sc, seed=seed, max_frames=100, view=p) for p in poses]
    truth = poses[0].apply(views[0].truth)
    a, b = (poses[k].apply(v.positions) for k, v in enumerate(views))
    fused = np.stack([f.positions for f in fused_frames(views, poses)])
    tt = (views[0].tracking_state == TRACKED) & (views[1].tracking_state == TRACKED)
    fz += segment_error_cm(fused, truth).sum()
    base += segment_error_cm(a, truth).sum()
    for w in W:
        acc[w] += segment_error_cm(np.where(tt[..., None], w * a + (1 - w) * b, fused), truth).sum()
    n += segment_error_cm(a, truth).size
print(seed, sc, 'single', round(base / n, 2), 'fused', round(fz / n, 2),
      {w: round(float(v / n), 2) for w, v in acc.items()})
