"""process_bag: a recorded sensor-model bag in, the reconstruction out (a bag rclpy can read, every
input topic kept), accuracy against the bag's ground truth; a corrupt message is skipped and
counted, not fatal."""
import numpy as np
import pytest

pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

from rclpy.serialization import deserialize_message  # noqa: E402
from skeleton_msgs.msg import SkeletonArray  # noqa: E402

from skeleton_core.bagio import BagWriter, bag_topics, read_messages  # noqa: E402
from skeleton_core.cdr import SKELETON_ARRAY, frames_to_cdr  # noqa: E402
from skeleton_core.conversions import SkeletonFrame, frames_from_array_msg  # noqa: E402
from skeleton_eval.evaluation import toy_clip  # noqa: E402
from skeleton_eval.sensor_model import SensorModel  # noqa: E402

from kinect_bringup.process_bag import process  # noqa: E402


def _bag(path, frames=90, corrupt_at=40):
    s = SensorModel(seed=3).corrupt(toy_clip(seconds=frames / 30.0), 'b', seed=3)
    with BagWriter(path) as bag:
        for i in range(len(s)):
            stamp = int(s.stamps_ns[i])
            raw = SkeletonFrame(positions=s.positions[i], tracking_state=s.tracking_state[i],
                                user_id=1, stamp_ns=stamp, frame_id='kinect_link')
            truth = SkeletonFrame(positions=s.truth[i], tracking_state=np.full(20, 2, np.uint8),
                                  user_id=1, stamp_ns=stamp, frame_id='kinect_link')
            data = frames_to_cdr([raw], stamp, 'kinect_link')
            if i == corrupt_at:
                data = data[:len(data) // 2]            # a truncated message
            bag.write_raw('/kinect/skeletons', data, stamp, SKELETON_ARRAY)
            bag.write_raw('/kinect/ground_truth', frames_to_cdr([truth], stamp, 'kinect_link'),
                          stamp, SKELETON_ARRAY)
    return len(s)


def test_process_bag_reconstructs_scores_and_skips_a_corrupt_message(tmp_path):
    n = _bag(tmp_path / 'in.mcap')
    summary = process(tmp_path / 'in.mcap', tmp_path / 'out.mcap', 'C', progress=False)
    assert summary['frames'] == n and summary['corrupt_messages'] == 1
    topics = bag_topics(str(tmp_path / 'out.mcap'))
    assert topics['/kinect/skeletons'][1] == n and topics['/kinect/ground_truth'][1] == n
    assert topics['/posture/reconstructed'] == (SKELETON_ARRAY, n - 1)
    outs = [m for m in read_messages(str(tmp_path / 'out.mcap'), decode=False)
            if m.topic == '/posture/reconstructed']
    msg = deserialize_message(outs[-1].data, SkeletonArray)      # rclpy reads our bytes
    f = frames_from_array_msg(msg)[0]
    assert f.user_id == 1 and f.frame_id == 'kinect_link' and np.all(np.isfinite(f.positions))
    acc = summary['accuracy']
    assert acc['C']['frames'] == n - 1
    assert acc['C']['eq18_cm'] < acc['raw']['eq18_cm']
