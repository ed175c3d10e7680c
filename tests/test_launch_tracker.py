"""The tracker travels with the data: a bag that declares its skeleton tracker
(``/kinect/tracker``), replayed through ``ros2 launch kinect_bringup pipeline.launch.py
source:=replay replay_file:=...`` with no other argument, gets the sensor correction learned for
that tracker (``cache/sensor_correction_<tracker>.npz``, here a file written by the test with a
10 cm offset of every joint, so its effect is unmistakable), and the recording of the run
declares the tracker too."""
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

import launch  # noqa: E402
from launch_support import include, launch_pytest  # noqa: E402

from skeleton_core import tracker as T  # noqa: E402
from skeleton_core.bagio import BagWriter, read_messages  # noqa: E402
from skeleton_core.cdr import SKELETON_ARRAY, frames_from_cdr, frames_to_cdr  # noqa: E402
from skeleton_core.conversions import SkeletonFrame  # noqa: E402
from skeleton_eval.clips import toy_clip  # noqa: E402
from skeleton_eval.sensor_model import SensorModel  # noqa: E402

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]

WORK = Path(tempfile.mkdtemp(prefix='kp_launch_tracker_'))
INPUT, OUTPUT = WORK / 'input.mcap', WORK / 'replayed.mcap'
CACHE = WORK / 'cache'
FRAMES = 60
SHIFT = 0.10   # m, forward in the body frame


def _write_inputs():
    from pose_reconstruction import correction as C
    s = SensorModel(seed=2).corrupt(toy_clip(seconds=FRAMES / 30.0), 'a', seed=2)
    with BagWriter(INPUT) as bag:
        t0 = int(s.stamps_ns[0]) + 1_700_000_000_000_000_000
        T.write_to_bag(bag, 'nite2', t0)   # what the live driver's recording declares
        for i in range(FRAMES):
            stamp = int(s.stamps_ns[i]) + 1_700_000_000_000_000_000
            raw = SkeletonFrame(positions=s.positions[i], tracking_state=s.tracking_state[i],
                                user_id=1, stamp_ns=stamp, frame_id='kinect_link')
            bag.write_raw('/kinect/skeletons', frames_to_cdr([raw], stamp, 'kinect_link'), stamp,
                          SKELETON_ARRAY)
    import shutil
    from skeleton_data.database import DEFAULT_FILE, default_path
    CACHE.mkdir(parents=True, exist_ok=True)
    shutil.copy(default_path(), CACHE / DEFAULT_FILE)   # the nodes load it, never build it
    offset = np.zeros((20, 3))
    offset[:, 0] = SHIFT
    C.SensorCorrection('nite2', offset, np.zeros((C.NUM_FEATURES, 60)),
                       np.zeros(C.NUM_FEATURES)).save(CACHE / 'sensor_correction_nite2.npz')


@launch_pytest.fixture(scope='module')
def tracker_launch():
    _write_inputs()
    os.environ['KINECT_POSTURE_CACHE'] = str(CACHE)   # the launched nodes' cache/
    return launch.LaunchDescription([
        include('pipeline.launch.py', source='replay', replay_file=str(INPUT),
                record=str(OUTPUT), physics='false',
                viz='false'),
        launch_pytest.actions.ReadyToTest(),
    ])


def _topic(topic):
    out = {}
    if OUTPUT.exists():
        try:
            for m in read_messages(OUTPUT, topics=[topic], decode=False, warn=lambda s: None):
                for f in frames_from_cdr(m.data)[2]:
                    out[f.stamp_ns] = f.positions
        except Exception:  # noqa: BLE001 - the header may not be on disk yet
            return {}
    return out


@pytest.mark.launch(fixture=tracker_launch)
def test_a_replayed_bag_gets_the_correction_of_its_declared_tracker():
    deadline = time.monotonic() + 150
    while time.monotonic() < deadline and len(_topic('/posture/reconstructed')) < FRAMES:
        time.sleep(1.0)
    time.sleep(1.0)
    raw, rec = _topic('/kinect/skeletons'), _topic('/posture/reconstructed')
    # every frame but at most one: on a loaded machine the latched tracker declaration can reach
    # the reconstruction after the replay has started (DDS still matching); its users are then
    # rebuilt with the correction and one frame around that switch has been seen missing (once,
    # Jazzy fresh clone, 59 of 60). Once (Kilted, two clean-clone CI runs side by side) frames
    # 1-19 were missing: the reconstruction stalled on its first frame (it loaded its compiled
    # kernels there; now on configure) while the replay played on at rate 1, and its depth-10
    # queue kept only the newest ten. Every frame of a replay is test_launch_replay's assertion.
    assert len(rec) >= FRAMES - 1, len(rec)
    from pose_reconstruction.correction import body_frame
    keys = sorted(rec)[10:]        # after the first frames (the tracker arrives with them)
    r = np.stack([raw[k] for k in keys])
    o = np.stack([rec[k] for k in keys])
    # the pelvis of the output sits SHIFT forward of the raw one, in the body frame
    d = np.einsum('nk,nkl->nl', o[:, 0] - r[:, 0], body_frame(r))
    assert np.median(d[:, 0]) == pytest.approx(SHIFT, abs=0.03), np.median(d, axis=0)
    assert T.from_bag(OUTPUT) == 'nite2'    # the recording of the run declares it too
