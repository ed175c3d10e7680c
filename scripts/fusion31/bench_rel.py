"""One Eq. 1-8 update (ReliabilityEstimator.update), compiled and numpy: best of 5 passes."""
import time

from pose_reconstruction.reliability import ReliabilityEstimator
from skeleton_eval.clips import load_clips
from skeleton_eval.sensor_model import SensorModel

_, dev, _ = load_clips('auto', 5)
s = SensorModel(None, seed=5).corrupt(dev[0], 'c', seed=5, max_frames=100)
n = len(s.positions)
for compiled in (True, False):
    e = ReliabilityEstimator()
    e._jit = e.plausibility._jit = compiled
    for i in range(n):
        e.update(s.positions[i], s.tracking_state[i])
    best = 1e9
    for _ in range(5):
        t = time.perf_counter()
        for i in range(n):
            e.update(s.positions[i], s.tracking_state[i])
        best = min(best, (time.perf_counter() - t) / n * 1e6)
    print('compiled' if compiled else 'numpy', f'{best:.1f} us per update')
