"""hri node over real DDS: reconstructed skeletons in, REP-155 bodies and openni2_tracker frames
out, read by a consumer written against REP-155 alone (tests/rep155_consumer.py); users leaving."""
import os
import time
import uuid

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')
pytest.importorskip('hri_msgs.msg', reason='hri_msgs not built (run scripts/setup.sh)')

from rclpy.parameter import Parameter  # noqa: E402
from skeleton_msgs.msg import SkeletonArray  # noqa: E402

from ros_helpers import Spinner, wait_until  # noqa: E402
from rep155_consumer import Consumer  # noqa: E402
from skeleton_core import model as m  # noqa: E402
from skeleton_core.conversions import SkeletonFrame, frames_to_array_msg  # noqa: E402
from skeleton_core.rep155 import JOINT_FRAMES  # noqa: E402
from skeleton_core.rosnode import bring_up  # noqa: E402
from skeleton_core.tf import Transform  # noqa: E402
from skeleton_core.tf_ros import StaticTfBroadcaster  # noqa: E402
from skeleton_data.motions import builtin_clips  # noqa: E402
from viz.hri_node import HriNode  # noqa: E402

pytestmark = pytest.mark.ros
IN = f'/hritest_{os.getpid()}_{uuid.uuid4().hex[:6]}/posture/reconstructed'
SENSOR = Transform((0.0, 0.0, 0.8))   # world -> kinect_link
CLIPS = builtin_clips(seed=11)


def _frames(k, uids):
    out = []
    for uid in uids:
        x = np.asarray(CLIPS[uid].positions[k % 180], float) + (2.5, 1.2 * uid - 2.0, -0.8)
        out.append(SkeletonFrame(positions=x, tracking_state=np.full(m.NUM_JOINTS, 2, np.uint8),
                                 user_id=uid, frame_id='kinect_link'))
    return out


@pytest.fixture
def graph(rclpy_context, request):
    source = getattr(request, 'param', 'reconstructed')
    topic = {'reconstructed': '/posture/reconstructed', 'character': '/character/skeletons'}
    hri = bring_up(HriNode(context=rclpy_context, parameter_overrides=[
        Parameter('openni_tf', value=True), Parameter('source', value=source)],
        cli_args=['--ros-args', '-r', f'{topic[source]}:={IN}']))
    peer = rclpy.create_node('hri_test_peer', context=rclpy_context)
    spinner = Spinner(rclpy_context, hri, peer)
    consumer = Consumer()
    yield hri, peer, consumer
    consumer.close()
    spinner.stop()
    hri.destroy_node()
    peer.destroy_node()


def _play(peer, pub, uids, start, n, sent, frame='kinect_link'):
    for k in range(start, start + n):
        stamp = 1_000_000_000 + k * 33_333_333
        frames = _frames(k, uids)
        pub.publish(frames_to_array_msg(frames, stamp, frame))
        sent[stamp] = {f.user_id: f.positions for f in frames}
        time.sleep(1 / 30)


def test_rep155_bodies_joint_frames_and_leaving_users(graph):
    hri, peer, consumer = graph
    StaticTfBroadcaster(peer).send([('world', 'kinect_link', SENSOR)])
    pub = peer.create_publisher(SkeletonArray, IN, 10)
    assert wait_until(lambda: pub.get_subscription_count() > 0, 10)
    sent = {}
    _play(peer, pub, [1, 2], 0, 45, sent)
    assert wait_until(lambda: consumer.last_tracked() == ['u1', 'u2'], 5), consumer.last_tracked()
    assert wait_until(lambda: set(consumer.urdf) == {'u1', 'u2'}, 5)
    # every joint frame, by TF and by FK of the URDF + joint states, where the skeleton put it
    last = max(sent)

    def caught_up():   # (a loaded machine delays the consumer's callbacks)
        with consumer.lock:
            return all(last in consumer.joint_states.get(b, {}) for b in ('u1', 'u2')) and \
                consumer.tf.lookup('world', 'left_hand_2', last) is not None
    assert wait_until(caught_up, 10)
    checked = 0
    for stamp in sorted(sent)[-20:]:
        for uid in (1, 2):
            bid = f'u{uid}'
            frames = [f'{f}_{bid}' for f in JOINT_FRAMES]
            fk, tf = consumer.body_positions(bid, frames, stamp, 'world')
            if fk is None or tf is None:
                continue
            want = SENSOR.apply(sent[stamp][uid])
            assert np.linalg.norm(fk - want, axis=1).max() < 0.01
            assert np.linalg.norm(tf - want, axis=1).max() < 0.01
            # openni2_tracker's frame: world -> left_hand_1 is the left hand (NiTE's, the wrist)
            hand = consumer.tf.lookup('world', f'left_hand_{uid}', stamp)
            assert hand is not None
            assert np.linalg.norm(hand.translation - want[m.WRIST_LEFT]) < 1e-6
            checked += 1
    assert checked >= 10, checked
    # user 2 leaves: dropped from tracked and its frames stop within 1 s
    _play(peer, pub, [1], 45, 3, sent)
    t_left = time.monotonic()
    assert wait_until(lambda: consumer.last_tracked() == ['u1'], 1.0)
    _play(peer, pub, [1], 48, 30, sent)
    with consumer.lock:
        last_u2 = max(consumer.tf.arrival['body_u2'], consumer.tf.arrival['head_2'])
        last_u1 = consumer.tf.arrival['body_u1']
    assert last_u2 < t_left + 1.0 and last_u1 > t_left + 0.5
    # the input stops: nobody is tracked within 1 s
    t_stop = time.monotonic()
    assert wait_until(lambda: consumer.last_tracked() == [], 1.0), consumer.last_tracked()
    assert time.monotonic() - t_stop < 1.0


@pytest.mark.parametrize('graph', ['character'], indirect=True)
def test_bodies_of_the_physics_characters(graph):
    """rep155_source:=character: the characters' skeletons (in world) are bodies c<user>."""
    hri, peer, consumer = graph
    pub = peer.create_publisher(SkeletonArray, IN, 10)
    assert wait_until(lambda: pub.get_subscription_count() > 0, 10)
    sent = {}
    _play(peer, pub, [3], 0, 30, sent, frame='world')
    assert wait_until(lambda: consumer.last_tracked() == ['c3'], 5), consumer.last_tracked()
    last = max(sent)
    assert wait_until(lambda: consumer.tf.lookup('world', 'l_hand_c3', last) is not None, 10)
    fk, tf = consumer.body_positions('c3', [f'{f}_c3' for f in JOINT_FRAMES], last, 'world')
    assert fk is not None and tf is not None
    assert np.linalg.norm(fk - sent[last][3], axis=1).max() < 0.01
    assert np.linalg.norm(tf - sent[last][3], axis=1).max() < 0.01
