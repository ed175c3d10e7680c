"""skeleton_core.bagio: MCAP bags written without rclpy, checked against rclpy serialization."""
import numpy as np
import pytest

pytest.importorskip('mcap_ros2')
from skeleton_core import bagio  # noqa: E402
from skeleton_core.bagio import BagError, BagWriter, bag_topics, read_messages  # noqa: E402

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from skeleton_msgs.msg import SkeletonArray  # noqa: E402

from skeleton_core.conversions import (SkeletonFrame, frames_from_array_msg,  # noqa: E402
                                       frames_to_array_msg)
from skeleton_core.model import standard_body  # noqa: E402


def _array_msg(stamp_ns, users=(1, 4)):
    frames = []
    for uid in users:
        rng = np.random.default_rng(uid + stamp_ns % 97)
        q = rng.normal(size=(20, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        frames.append(SkeletonFrame(
            positions=standard_body().rest_positions() + rng.normal(0, 0.05, (20, 3)),
            tracking_state=rng.integers(0, 3, 20).astype(np.uint8),
            reliability=rng.random(20).astype(np.float32), orientations=q, user_id=uid,
            stamp_ns=stamp_ns, frame_id='kinect_depth'))
    return frames_to_array_msg(frames, stamp_ns, 'kinect_depth')


def _canonical(msg, msgtype):
    """CDR with zeroed alignment padding (the schema-driven encoder of mcap_ros2)."""
    from mcap_ros2._dynamic import serialize_dynamic
    return serialize_dynamic(msgtype, bagio.message_definition(msgtype))[msgtype](msg)


def _same_cdr(data: bytes, canonical: bytes) -> bool:
    """Equal bytes except alignment padding: rclpy/Fast CDR leaves padding uninitialized, so
    ``data`` may differ from the zero-padded ``canonical`` only where the latter is zero."""
    if len(data) != len(canonical):
        return False
    return all(canonical[i] == 0 for i in range(len(data)) if data[i] != canonical[i])


def test_skeleton_array_round_trip_matches_rclpy_serialization(tmp_path):
    path = tmp_path / 'run.mcap'
    msgs = [_array_msg(1_700_000_000_000_000_000 + k * 33_333_333) for k in range(5)]
    with BagWriter(path) as bag:
        for k, m in enumerate(msgs):
            bag.write('/kinect/skeletons', m, 1000 + k)
    got = list(read_messages(path))
    assert [g.stamp_ns for g in got] == [1000 + k for k in range(5)]
    for g, m in zip(got, msgs):
        assert g.topic == '/kinect/skeletons' and g.msgtype == 'skeleton_msgs/msg/SkeletonArray'
        canonical = _canonical(m, 'skeleton_msgs/msg/SkeletonArray')
        assert _same_cdr(g.data, canonical) and _same_cdr(serialize_message(m), canonical)
        assert deserialize_message(g.data, SkeletonArray) == m
        # the decoded message has attribute access and converts like a ROS message
        frames = frames_from_array_msg(g.msg)
        ref = frames_from_array_msg(m)
        assert [f.user_id for f in frames] == [1, 4]
        for a, b in zip(frames, ref):
            assert np.array_equal(a.positions, b.positions)
            assert np.array_equal(a.tracking_state, b.tracking_state)
            assert np.array_equal(a.reliability, b.reliability)
            assert a.stamp_ns == b.stamp_ns and a.frame_id == b.frame_id
    assert bag_topics(path) == {'/kinect/skeletons': ('skeleton_msgs/msg/SkeletonArray', 5)}


def test_rclpy_decodes_when_available_and_matches_the_pure_decoder(tmp_path, monkeypatch):
    with BagWriter(tmp_path / 'a.mcap') as bag:
        bag.write('/x', _array_msg(42), 7)
    fast = next(read_messages(tmp_path / 'a.mcap')).msg
    assert isinstance(fast, SkeletonArray)               # rclpy's C deserializer
    assert fast == deserialize_message(next(read_messages(tmp_path / 'a.mcap')).data, SkeletonArray)
    monkeypatch.setenv('KP_BAGIO_PURE', '1')
    pure = next(read_messages(tmp_path / 'a.mcap')).msg
    assert not isinstance(pure, SkeletonArray)
    for a, b in zip(frames_from_array_msg(fast), frames_from_array_msg(pure)):
        assert np.array_equal(a.positions, b.positions) and a.user_id == b.user_id
        assert np.array_equal(a.orientations, b.orientations) and a.stamp_ns == b.stamp_ns


def test_decoded_message_rewrites_to_identical_bytes(tmp_path, monkeypatch):
    monkeypatch.setenv('KP_BAGIO_PURE', '1')   # the pure-Python decoder's look-alike messages
    with BagWriter(tmp_path / 'a.mcap') as bag:
        bag.write('/x', _array_msg(42), 7)
    first = next(read_messages(tmp_path / 'a.mcap'))
    with BagWriter(tmp_path / 'b.mcap') as bag:
        bag.write('/y', first.msg, 8)                      # a decoded (non-rclpy) message
        bag.write_raw('/z', first.data, 9)                 # raw CDR copy
    second = {m.topic: m for m in read_messages(tmp_path / 'b.mcap')}
    assert second['/z'].data == first.data                  # raw copy: identical bytes
    assert _same_cdr(first.data, second['/y'].data)         # re-encoded: same up to padding
    assert second['/y'].data == _canonical(first.msg, 'skeleton_msgs/msg/SkeletonArray')
    assert deserialize_message(second['/y'].data, SkeletonArray) == \
        deserialize_message(first.data, SkeletonArray)
    assert list(read_messages(tmp_path / 'b.mcap', topics=['/z']))[0].stamp_ns == 9


def test_complete_ros2msg_definition_has_dependencies():
    text = bagio.message_definition('skeleton_msgs/SkeletonArray')
    assert text.startswith('# All users seen')
    for dep in ('std_msgs/msg/Header', 'builtin_interfaces/msg/Time', 'skeleton_msgs/msg/Skeleton',
                'geometry_msgs/msg/Point', 'geometry_msgs/msg/Quaternion'):
        assert f'{"=" * 80}\nMSG: {dep}\n' in text
    assert text.count('MSG: ') == 5


def test_other_message_types_round_trip(tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from geometry_msgs.msg import Point
    from visualization_msgs.msg import Marker, MarkerArray
    diag = DiagnosticArray()
    diag.header.stamp.sec = 5
    diag.status = [DiagnosticStatus(level=DiagnosticStatus.WARN, name='driver', message='hi',
                                    values=[KeyValue(key='rate_hz', value='30.0')])]
    mk = Marker(ns='skeleton', id=3, type=Marker.LINE_LIST, action=Marker.ADD)
    mk.header.frame_id = 'world'
    mk.scale.x = 0.02
    mk.color.a = 1.0
    mk.points = [Point(x=1.0, y=2.0, z=3.0), Point(x=-1.0, y=0.5, z=0.0)]
    markers = MarkerArray(markers=[mk])
    written = [('/diagnostics', diag, DiagnosticArray), ('/viz/markers', markers, MarkerArray)]
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage  # make setup builds tf2_msgs: never optional
    tf = TFMessage(transforms=[TransformStamped(child_frame_id='head_1')])
    tf.transforms[0].header.frame_id = 'kinect_depth'
    tf.transforms[0].transform.rotation.w = 1.0
    written.append(('/tf', tf, TFMessage))
    with BagWriter(tmp_path / 'mixed.mcap') as bag:
        for k, (topic, msg, _) in enumerate(written):
            bag.write(topic, msg, k)
    got = {m.topic: m for m in read_messages(tmp_path / 'mixed.mcap')}
    for topic, msg, cls in written:
        assert deserialize_message(got[topic].data, cls) == msg, topic
        if topic != '/diagnostics':  # mcap_ros2's encoder cannot take rclpy's bytes-valued `byte`
            assert _same_cdr(got[topic].data, _canonical(msg, got[topic].msgtype))
    assert got['/viz/markers'].msg.markers[0].points[0].y == 2.0
    assert got['/viz/markers'].msgtype == 'visualization_msgs/msg/MarkerArray'


@pytest.mark.parametrize('content', [b'', b'hello, this is not a bag', b'SQLite format 3\x00xxxx'])
def test_unreadable_bag_names_the_file(tmp_path, content):
    p = tmp_path / 'broken.mcap'
    p.write_bytes(content)
    with pytest.raises(BagError, match='broken.mcap'):
        list(read_messages(p))
    with pytest.raises(BagError, match='broken.mcap'):
        bag_topics(p)


def test_truncated_and_missing_bags(tmp_path):
    good = tmp_path / 'good.mcap'
    with BagWriter(good, compression='none', chunk_size=4000) as bag:
        for k in range(50):
            bag.write('/kinect/skeletons', _array_msg(k), k)
    data = good.read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:len(data) // 2])
    # read up to the last complete message, with one warning line (tests/test_recovery.py)
    warned = []
    got = list(read_messages(cut, warn=warned.append))
    assert 0 < len(got) < 50 and len(warned) == 1 and 'cut.mcap is truncated at byte' in warned[0]
    with pytest.raises(BagError, match='nothere.mcap: no such file|nothere.mcap'):
        list(read_messages(tmp_path / 'nothere.mcap'))


def test_file_follows_the_mcap_ros2_profile(tmp_path):
    from mcap.reader import make_reader
    with BagWriter(tmp_path / 'p.mcap') as bag:
        for k in range(3):
            bag.write('/kinect/skeletons', _array_msg(k), k)
    with open(tmp_path / 'p.mcap', 'rb') as f:
        reader = make_reader(f)
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
    schema, = summary.schemas.values()
    channel, = summary.channels.values()
    assert schema.encoding == 'ros2msg' and schema.name == 'skeleton_msgs/msg/SkeletonArray'
    assert channel.message_encoding == 'cdr' and channel.topic == '/kinect/skeletons'
    # rosbag2's MCAP storage reads message counts and times from the statistics record
    assert summary.statistics.message_count == 3
    assert summary.statistics.channel_message_counts[channel.id] == 3


def test_topic_type_conflict_is_refused(tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    with BagWriter(tmp_path / 'c.mcap') as bag:
        bag.write('/t', _array_msg(1), 1)
        with pytest.raises(BagError, match='already recorded'):
            bag.write('/t', DiagnosticArray(), 2)
