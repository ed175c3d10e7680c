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
from skeleton_eval.clips import toy_clip  # noqa: E402
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
    # one rigid skeleton: the output's lengths are the user's once estimated (the first
    # seconds), the sensor's are not; the jitter beside them
    b = summary['bone_lengths']
    assert b['tracks'] == 1 and b['frames'] == n - 1 and b['out_nan_frames'] == 0
    assert b['restarts'] == 0
    assert len(b['out_std_cm']) == len(b['segments']) == 19
    assert b['raw_std_mean_cm'] > 0.5 and b['out_std_mean_cm'] < 0.1 * b['raw_std_mean_cm']
    assert b['out_jitter_ms2'] < b['raw_jitter_ms2']


def test_process_bag_saves_the_reconstructions_lengths_as_a_profile(tmp_path):
    from pose_reconstruction.profile import load
    from pose_reconstruction.reconstructor import Reconstructor
    _users_bag(tmp_path / 'in.mcap', [(0, [1])], seconds=3.0)
    summary = process(tmp_path / 'in.mcap', tmp_path / 'out.mcap', 'C', progress=False,
                      save_profile='me', profile_dir=str(tmp_path / 'profiles'))
    L = summary['bone_lengths']['longest_track_lengths_m']
    prof = load(tmp_path / 'profiles' / 'me.json')
    np.testing.assert_allclose(prof.segment_lengths, L, atol=1e-5)
    import json
    assert json.loads((tmp_path / 'profiles' / 'me.json').read_text())['estimated_by'] == \
        'reconstruction'
    # the profile gives the next run those lengths from the first frame
    out = process(tmp_path / 'in.mcap', tmp_path / 'out2.mcap', 'C', progress=False,
                  params={'profile': prof})
    assert out['bone_lengths']['out_std_mean_cm'] < 1e-6
    assert Reconstructor   # the parameter is the reconstruction's
    with pytest.raises(ValueError, match='method B or C'):
        process(tmp_path / 'in.mcap', tmp_path / 'o3.mcap', 'A', progress=False,
                save_profile='me', profile_dir=str(tmp_path / 'profiles'))


def test_bone_length_std_is_per_user_track(tmp_path):
    """Two users in turn under the same id (the first leaves for longer than the timeout):
    two tracks, each with its own constant lengths, not one pooled std."""
    n = _users_bag(tmp_path / 'in.mcap', [(0, [1]), (160, [1])], seconds=3.0)
    summary = process(tmp_path / 'in.mcap', tmp_path / 'out.mcap', 'C', progress=False)
    b = summary['bone_lengths']
    assert b['tracks'] == 2 and b['frames'] == 2 * n
    # (3 s tracks of a noisy sensor: the first half second, while the estimate averages, is
    # most of what is left)
    assert b['out_std_mean_cm'] < 0.2 * b['raw_std_mean_cm']


def _users_bag(path, schedule, seconds=1.0, seed=5):
    """A bag of users coming and going: ``schedule`` = [(first frame, user ids)] — from that frame
    on, those users are in view (empty arrays when nobody is, as a live Kinect publishes)."""
    clip = SensorModel(seed=seed).corrupt(toy_clip(seconds=seconds), 'a', seed=seed)
    n = len(clip)
    end = max(start for start, _ in schedule) + n
    t0 = 1_700_000_000_000_000_000
    with BagWriter(path) as bag:
        for i in range(end):
            stamp = t0 + i * 33_333_333
            frames = []
            for start, uids in schedule:
                k = i - start
                if not 0 <= k < n:
                    continue
                for j, uid in enumerate(uids):
                    p = clip.positions[k].copy()
                    p[:, 1] += 0.8 * (j - (len(uids) - 1) / 2)   # side by side
                    frames.append(SkeletonFrame(positions=p, tracking_state=clip.tracking_state[k],
                                                user_id=uid, stamp_ns=stamp,
                                                frame_id='kinect_link'))
            bag.write_raw('/kinect/skeletons', frames_to_cdr(frames, stamp, 'kinect_link'), stamp,
                          SKELETON_ARRAY)
    return n


def _character_users(path):
    from skeleton_core.cdr import frames_from_cdr
    per_user = {}
    for m in read_messages(str(path), topics=['/character/skeletons'], decode=False):
        for f in frames_from_cdr(m.data)[2]:
            per_user[f.user_id] = per_user.get(f.user_id, 0) + 1
    return per_user


def test_users_in_sequence_each_get_a_character_offline(tmp_path):
    """20 users one after another (each 1 s in view, 2.5 s gaps: longer than the 2 s user
    timeout in the bag's time): 20 characters, a character on >= 99 % of user frames."""
    schedule = [(k * 105, (10 + k,)) for k in range(20)]
    n = _users_bag(tmp_path / 'seq.mcap', schedule)
    warned = []
    s = process(tmp_path / 'seq.mcap', tmp_path / 'out.mcap', 'A', physics=True, progress=False,
                warn=warned.append)
    assert s['users'] == 20 and s['user_arrivals'] == 20 and s['user_frames'] == 20 * n
    assert s['characters'] == 20 and s['refused'] == {} and not warned
    assert s['character_frame_share'] >= 0.99, s
    per_user = _character_users(tmp_path / 'out.mcap')
    assert sorted(per_user) == list(range(10, 30))
    # a character leaves with its user: none outlives the user by more than the timeout
    assert max(per_user.values()) <= n


def test_seven_users_at_once_give_six_characters_and_counted_refusals(tmp_path):
    n = _users_bag(tmp_path / 'seven.mcap', [(0, (1, 2, 3, 4, 5, 6, 7))])
    warned = []
    s = process(tmp_path / 'seven.mcap', tmp_path / 'out.mcap', 'A', physics=True,
                progress=False, warn=warned.append)
    assert s['users'] == 7 and s['characters'] == 6
    (reason, refused), = s['refused'].items()
    assert reason == 'too many users (max_characters 6)'
    assert refused == {'frames': n, 'users': [7]}
    assert len(warned) == 1 and 'max_characters 6' in warned[0]   # warned once, not per frame
    assert sorted(_character_users(tmp_path / 'out.mcap')) == [1, 2, 3, 4, 5, 6]


def test_a_user_who_returns_after_the_timeout_is_a_new_arrival(tmp_path):
    # user 3 leaves for 1 s (< 2 s timeout: the same visit), then for 3 s (a new arrival)
    _users_bag(tmp_path / 'back.mcap', [(0, (3,)), (60, (3,)), (180, (3,))], seconds=1.0)
    s = process(tmp_path / 'back.mcap', tmp_path / 'out.mcap', 'A', physics=True, progress=False,
                warn=lambda t: None)
    assert s['users'] == 1 and s['user_arrivals'] == 2 and s['characters'] == 1


def test_duplicate_and_out_of_order_stamps_are_skipped_where_they_arrive(tmp_path):
    n = _bag(tmp_path / 'in.mcap', frames=30, corrupt_at=-1)
    from skeleton_core.cdr import frames_from_cdr
    msgs = [m for m in read_messages(str(tmp_path / 'in.mcap'), topics=['/kinect/skeletons'],
                                     decode=False)]
    with BagWriter(tmp_path / 'dup.mcap') as bag:
        for k, m in enumerate(msgs):
            bag.write_raw(m.topic, m.data, m.stamp_ns, SKELETON_ARRAY)
            if k == 10:
                bag.write_raw(m.topic, m.data, m.stamp_ns + 1, SKELETON_ARRAY)       # repeated
            if k == 20:
                bag.write_raw(m.topic, msgs[15].data, m.stamp_ns + 1, SKELETON_ARRAY)  # late
    s = process(tmp_path / 'dup.mcap', tmp_path / 'out.mcap', 'C', progress=False)
    assert s['skipped_messages'] == {'duplicate stamp': 1, 'out-of-order stamp': 1}
    assert bag_topics(str(tmp_path / 'out.mcap'))['/posture/reconstructed'][1] == n
    assert frames_from_cdr(msgs[0].data)[2][0].user_id == 1
