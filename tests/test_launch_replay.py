"""A recording replayed through ``ros2 launch kinect_bringup pipeline.launch.py source:=replay
replay_file:=... record:=...`` loses nothing: the driver waits until the reconstruction
and the recorder have subscribed, every input frame is reconstructed, and the bag's ground truth
is replayed so the report of the run scores it. The recording is read while it is still being
written (crash-safe recorder: flushed every 0.25 s)."""
import tempfile
import time
from pathlib import Path

import numpy as np
import launch
from launch_support import include, launch_pytest  # noqa: E402
import pytest

from skeleton_core.bagio import BagWriter, read_messages  # noqa: E402
from skeleton_core.cdr import SKELETON_ARRAY, frames_to_cdr  # noqa: E402
from skeleton_core.conversions import SkeletonFrame  # noqa: E402
from skeleton_eval.clips import toy_clip  # noqa: E402
from skeleton_eval.sensor_model import SensorModel  # noqa: E402

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]

WORK = Path(tempfile.mkdtemp(prefix='kp_launch_replay_'))
INPUT, OUTPUT = WORK / 'input.mcap', WORK / 'replayed.mcap'
FRAMES = 90


def _write_input(path):
    s = SensorModel(seed=2).corrupt(toy_clip(seconds=FRAMES / 30.0), 'b', seed=2)
    with BagWriter(path) as bag:
        for i in range(FRAMES):
            stamp = int(s.stamps_ns[i]) + 1_700_000_000_000_000_000
            raw = SkeletonFrame(positions=s.positions[i], tracking_state=s.tracking_state[i],
                                user_id=1, stamp_ns=stamp, frame_id='kinect_link')
            truth = SkeletonFrame(positions=s.truth[i], tracking_state=np.full(20, 2, np.uint8),
                                  user_id=1, stamp_ns=stamp, frame_id='kinect_link')
            bag.write_raw('/kinect/skeletons', frames_to_cdr([raw], stamp, 'kinect_link'), stamp,
                          SKELETON_ARRAY)
            bag.write_raw('/kinect/ground_truth', frames_to_cdr([truth], stamp, 'kinect_link'),
                          stamp, SKELETON_ARRAY)


@launch_pytest.fixture(scope='module')
def replay_launch():
    _write_input(INPUT)
    return launch.LaunchDescription([
        include('pipeline.launch.py', source='replay', replay_file=str(INPUT),
                record=str(OUTPUT), physics='false',
                viz='false'),
        launch_pytest.actions.ReadyToTest(),
    ])


def _counts():
    out = {}
    if OUTPUT.exists():
        try:
            for m in read_messages(OUTPUT, decode=False, warn=lambda s: None):
                out[m.topic] = out.get(m.topic, 0) + 1
        except Exception:  # noqa: BLE001 - the header may not be on disk yet
            return {}
    return out


@pytest.mark.launch(fixture=replay_launch)
def test_replay_through_launch_reconstructs_every_frame_and_is_scored():
    deadline = time.monotonic() + 150
    counts = {}
    while time.monotonic() < deadline:
        counts = _counts()
        if counts.get('/posture/reconstructed', 0) >= FRAMES:
            break
        time.sleep(1.0)
    time.sleep(1.0)
    counts = _counts()
    assert counts.get('/kinect/skeletons') == FRAMES, counts
    assert counts.get('/posture/reconstructed') == FRAMES, counts      # 100 %
    assert counts.get('/kinect/ground_truth') == FRAMES, counts        # replayed
    from viz.report import summarize
    from viz.series import load_bag
    summary = summarize(load_bag(OUTPUT), 1)
    for role in ('raw', 'reconstructed'):   # scored against the replayed ground truth
        got = summary['methods'][role]
        assert got['matched_frames'] == FRAMES and np.isfinite(got['mean_error_m']), got


def test_the_replay_waits_for_every_reader_of_the_skeletons():
    from kinect_bringup.graph import graph_nodes, skeleton_subscribers
    assert skeleton_subscribers(graph_nodes()) == 2                    # reconstruction, viz raw
    assert skeleton_subscribers(graph_nodes(record=True)) == 3         # + the recorder
    assert skeleton_subscribers(graph_nodes(physics=False, viz=False, record=True)) == 2
    assert skeleton_subscribers(graph_nodes(reconstruction='split')) == 2   # reliability, viz
    assert skeleton_subscribers(['recorder'], recorded_topics=['/posture/reconstructed']) == 0


def test_a_recordings_readers_queue_it():
    """With the source a recording the reconstruction nodes' input queues are deep (ROS QoS
    overrides of their input topics); a live or synthetic source keeps the nodes' own depth."""
    from kinect_bringup.graph import REPLAY_QUEUE_DEPTH, graph_nodes, replay_overrides, replays
    assert replays('replay') and not replays('live') and not replays('synthetic')
    assert not replays('')    # the driver's YAML: synthetic
    assert replay_overrides(graph_nodes()) == {
        'reconstruction': {'qos_overrides./kinect/skeletons.subscription.depth': REPLAY_QUEUE_DEPTH}}
    split = replay_overrides(graph_nodes(reconstruction='split'))
    assert {n: list(v) for n, v in split.items()} == {
        'reliability': ['qos_overrides./kinect/skeletons.subscription.depth'],
        'completion': ['qos_overrides./kinect/skeletons_reliability.subscription.depth'],
        'optimizer': ['qos_overrides./posture/completed.subscription.depth']}
