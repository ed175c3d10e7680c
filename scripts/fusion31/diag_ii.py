"""Fused raw against single raw (Eq. 18, cm), with and without fusion step 7, per sensor-model
variant: diag_ii.py SEED CLASSES LAYOUT [PARAMS.yaml ...]"""
import sys

import numpy as np

from kinect_experiments import fusion_eval as FE
from pose_reconstruction import fusion as F
from skeleton_core.model import SEGMENT_PARENT_INDEX
from skeleton_core.tf import Transform
from skeleton_eval.clips import load_clips
from skeleton_eval.sensor_model import SensorModel

seed, scs, layout = int(sys.argv[1]), sys.argv[2].split(','), sys.argv[3]
CH, PA = np.arange(1, 20), np.asarray(SEGMENT_PARENT_INDEX)


def segerr(p, t):
    return np.linalg.norm((p[:, CH] - p[:, PA]) - (t[:, CH] - t[:, PA]), axis=-1) * 100


_, dev, _ = load_clips('auto', seed)
for params in sys.argv[4:] or [None]:
    sensor = SensorModel(params, seed=seed)
    poses = FE.view_poses(sensor, 2, layout)
    for sc in scs:
        res = {}
        for hold in (False, True):
            F.HOLD_RELATIVE = hold
            e1, ef = [], []
            for clip in dev:
                views = [sensor.corrupt(clip, sc, seed=seed, max_frames=200, view=p) for p in poses]
                one = views[0] if layout == 'front-side' else sensor.corrupt(
                    clip, sc, seed=seed, max_frames=200, view=Transform.identity())
                fused = np.stack([f.positions for f in FE.fused_frames(views, poses)])
                e1.append(segerr(one.positions, one.truth))
                ef.append(segerr(fused, one.truth))
            res[hold] = (np.concatenate(e1).mean(), np.concatenate(ef).mean())
        b = res[False][0]
        print(f'{layout} {params or "default"} seed {seed} class {sc}: single {b:.2f}  '
              f'fused {res[False][1]:.2f} ({100 * (res[False][1] - b) / b:+.1f} %)  '
              f'fused+hold {res[True][1]:.2f} ({100 * (res[True][1] - b) / b:+.1f} %)')
