#!/bin/bash
# Fusion cost, two source trees in alternating processes (the machine is shared: old and new see
# the same load): scripts/fusion31/ab_proc.sh OLD_SRC ROUNDS FRAMES. OLD_SRC: a `git archive
# <commit> src | tar -x` of the commit to compare against; new = this worktree's install.
# Run from the workspace root after `source scripts/env.sh`.
old=$1; rounds=${2:-3}; frames=${3:-200}
oldpath=$(ls -d "$old"/src/*/ | tr '\n' ':')
py='import sys, json
from skeleton_eval.clips import load_clips
from skeleton_eval.sensor_model import SensorModel
from kinect_experiments import fusion_eval as FE
_, dev, _ = load_clips("auto", 5)
sensor = SensorModel(None, seed=5)
poses = FE.view_poses(sensor, 2)
longest = max(dev, key=lambda c: len(c.positions))
streams = [sensor.corrupt(longest, "c", seed=5, max_frames=int(sys.argv[2]), view=p) for p in poses]
FE.fusion_cost(streams, poses, users=1)
for u in (1, 3, 6):
    c = FE.fusion_cost(streams, poses, users=u)
    print(sys.argv[1], u, round(c["mean_ms"], 3), round(c["no_eq8_mean_ms"], 3), round(c["cpu_mean_ms"], 3), flush=True)'
for r in $(seq "$rounds"); do
  KP_SHARED="$(cd ../shared && pwd)" PYTHONPATH="$oldpath$PYTHONPATH" python -c "$py" old "$frames"
  python -c "$py" new "$frames"
done
