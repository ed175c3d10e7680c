"""A real UI-PRMD recording, imported to a bag, replayed by the driver over real DDS."""
import os
import subprocess
import sys
import time

import numpy as np
import pytest

import domains  # noqa: E402  (tests/domains.py)

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from skeleton_msgs.msg import SkeletonArray  # noqa: E402

from skeleton_core.bagio import read_messages  # noqa: E402
from skeleton_core.conversions import frames_from_array_msg  # noqa: E402
from skeleton_core.model import HAND_LEFT, NOT_TRACKED, TRACKED  # noqa: E402

# A DDS domain of our own (scripts/env.sh exports ROS_DOMAIN_ID=42 for everybody)
DOMAIN = domains.claim(1 + (os.getpid() * 7 + 13) % 100)   # claimed: tests/domains.py


def test_imported_real_clip_replays_over_dds(shared_dir, tmp_path):
    from skeleton_eval import uiprmd_cli
    src = shared_dir / 'kinect' / 'ui-prmd'
    assert uiprmd_cli.main(['--src', str(src), '--out', str(tmp_path), '--subjects', 's02',
                            '--movements', 'm07', '--repetitions', '1', '--quiet']) == 0
    bag = tmp_path / 'm07_s02_e01.mcap'
    recorded = [m.data for m in read_messages(bag, ['/kinect/skeletons'], decode=False)]
    cmd = [sys.executable, '-m', 'kinect_driver.driver_node', '--ros-args',
           '-p', 'source:=replay', '-p', f'replay_file:={bag}', '-p', 'loop:=true']
    proc = subprocess.Popen(cmd, env=dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN)),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN)
    node = rclpy.create_node('uiprmd_replay_probe', context=ctx)
    got = []
    node.create_subscription(SkeletonArray, '/kinect/skeletons', got.append, 100, raw=True)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    try:
        deadline = time.monotonic() + 30
        while len(got) < len(recorded) + 10 and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
            if proc.poll() is not None:
                break
    finally:
        node.destroy_node()
        rclpy.shutdown(context=ctx)
        proc.terminate()
        try:
            out, _ = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, _ = proc.communicate()
    assert len(got) >= len(recorded), out
    index = {d: i for i, d in enumerate(recorded)}
    # (another engineer's test may share the DDS domain by chance: count only our messages)
    seq = [index[bytes(d)] for d in got if bytes(d) in index]
    assert len(seq) >= 0.9 * len(got), 'replayed messages differ from the bag'
    assert set(seq) == set(range(len(recorded)))              # every frame arrived, byte for byte
    assert all((b - a) % len(recorded) == 1 for a, b in zip(seq, seq[1:]))  # in recorded order
    from rclpy.serialization import deserialize_message
    f = frames_from_array_msg(deserialize_message(recorded[seq[0]], SkeletonArray))[0]
    assert f.frame_id == 'kinect_link' and f.user_id == 1
    assert f.tracking_state[HAND_LEFT] == NOT_TRACKED
    assert (np.delete(f.tracking_state, [7, 11]) == TRACKED).all()
