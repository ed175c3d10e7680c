"""launch_pytest: pipeline.launch.py with rep155:=true joint_tf:=true, read by a REP-155 consumer
written against the REP alone (plain rclpy, its own TF buffer; tests/rep155_consumer.py): every
synthetic user is a tracked body whose URDF + joint states give /posture/reconstructed back by
forward kinematics, the openni2_tracker frames are where the joints are, and the physics
character's URDF + /character/joint_states give /character/skeletons back.
"""
import os
import time

import launch
import launch_pytest  # make setup builds the launch tooling: these tests never skip
import numpy as np
import pytest
from ament_index_python.packages import get_package_share_directory
from launch.actions import IncludeLaunchDescription
from launch.launch_description_sources import PythonLaunchDescriptionSource

pytest.importorskip('hri_msgs.msg', reason='hri_msgs not built (run scripts/setup.sh)')

from rep155_consumer import Consumer  # noqa: E402
from ros_helpers import wait_until  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from skeleton_core import model as m  # noqa: E402
from skeleton_core.kinematic_tree import forward_kinematics_urdf  # noqa: E402
from skeleton_core.rep155 import JOINT_FRAMES  # noqa: E402
from skeleton_msgs.msg import SkeletonArray  # noqa: E402
from std_msgs.msg import String  # noqa: E402

pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow]
SHARE = get_package_share_directory('kinect_bringup')
USERS = (1, 2)


@launch_pytest.fixture(scope='module')
def rep155_launch():
    path = os.path.join(SHARE, 'launch', 'pipeline.launch.py')
    return launch.LaunchDescription([
        IncludeLaunchDescription(PythonLaunchDescriptionSource(path), launch_arguments={
            'num_users': '2', 'scenario': 'b', 'viz': 'false', 'rep155': 'true',
            'joint_tf': 'true'}.items()),
        launch_pytest.actions.ReadyToTest(),
    ])


@pytest.fixture(scope='module')
def consumer():
    extra = {'/posture/reconstructed': SkeletonArray, '/character/skeletons': SkeletonArray,
             '/character/joint_states': JointState}
    extra.update({f'/character/u{u}/robot_description': String for u in USERS})
    c = Consumer(extra, name='launch_rep155_consumer')
    yield c
    c.close()


def _stamp(msg):
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec


def _skeletons(consumer, topic, last=60):
    with consumer.lock:
        msgs = list(consumer.extra[topic][-last:])
    return {_stamp(a): {s.user_id: np.array([(p.x, p.y, p.z) for p in s.positions])
                        for s in a.skeletons} for a in msgs}


@pytest.mark.launch(fixture=rep155_launch)
def test_rep155_consumer_sees_every_user_and_fk_gives_the_reconstruction(consumer):
    assert wait_until(lambda: consumer.last_tracked() == ['u1', 'u2'], 120), \
        consumer.last_tracked()
    assert wait_until(lambda: set(consumer.urdf) == {'u1', 'u2'}, 10)
    time.sleep(4.0)   # the bodies' lengths settle (the URDF is made again when they move)
    errors, hand = [], []
    for stamp, users in sorted(_skeletons(consumer, '/posture/reconstructed').items())[-45:-5]:
        sensor = consumer.tf.lookup('world', 'kinect_link', stamp)
        assert sensor is not None, 'no world -> kinect_link on /tf_static'
        for uid, x in users.items():
            bid = f'u{uid}'
            fk, tf = consumer.body_positions(bid, [f'{f}_{bid}' for f in JOINT_FRAMES], stamp,
                                             'world')
            if fk is None or tf is None:
                continue
            want = sensor.apply(x)
            errors.append(max(np.linalg.norm(fk - want, axis=1).max(),
                              np.linalg.norm(tf - want, axis=1).max()))
            lh = consumer.tf.lookup('world', f'left_hand_{uid}', stamp)
            if lh is not None:   # openni2_tracker's left hand: NiTE's, the wrist
                hand.append(np.linalg.norm(lh.translation - want[m.WRIST_LEFT]))
    assert len(errors) >= 20, len(errors)
    print(f'REP-155 FK vs /posture/reconstructed: {len(errors)} bodies, max {max(errors):.2e} m')
    assert max(errors) < 0.01
    assert len(hand) >= 20 and max(hand) < 1e-4


@pytest.mark.launch(fixture=rep155_launch)
def test_character_urdf_and_joint_states_give_the_character_back(consumer):
    def ready():
        with consumer.lock:
            return all(consumer.extra[f'/character/u{u}/robot_description'] for u in USERS)
    assert wait_until(ready, 120)
    with consumer.lock:
        urdf = {u: consumer.extra[f'/character/u{u}/robot_description'][-1].data for u in USERS}
    errors = []
    deadline = time.monotonic() + 30
    while len(errors) < 10 and time.monotonic() < deadline:
        time.sleep(1.0)   # (the consumer's /tf callbacks may lag on a loaded machine)
        errors = _character_errors(consumer, urdf)
    assert len(errors) >= 10, _character_report(consumer)
    print(f'character FK vs /character/skeletons: {len(errors)} characters, '
          f'max {max(errors):.2e} m')
    assert max(errors) < 0.01


def _character_errors(consumer, urdf):
    """FK of each character's URDF + joint states + root on TF against /character/skeletons, on
    the stamps published once (a physics tick without a new target publishes the same stamp
    again, with the character moved on: such stamps cannot be paired across topics), older than
    the newest ten."""
    from collections import Counter
    with consumer.lock:
        js_msgs = consumer.extra['/character/joint_states'][-90:]
        sk_msgs = consumer.extra['/character/skeletons'][-90:]
    once = {s for s, n in (Counter(map(_stamp, js_msgs)) + Counter(map(_stamp, sk_msgs))).items()
            if n == 2}
    # not the newest stamps either: a second publish of one may still be on its way
    newest = sorted({_stamp(m) for m in js_msgs} | {_stamp(m) for m in sk_msgs})[-10:]
    once -= set(newest)
    states = {_stamp(j): dict(zip(j.name, j.position)) for j in js_msgs}
    errors = []
    for stamp, users in sorted(_skeletons(consumer, '/character/skeletons', 90).items()):
        js = states.get(stamp)
        if js is None or stamp not in once:
            continue
        for uid, x in users.items():
            with consumer.lock:
                root = consumer.tf.lookup('world', f'u{uid}_seg_Spine', stamp)
            if root is None:
                continue
            poses = forward_kinematics_urdf(urdf[uid], js)
            # the joint points are the fixed frames u<id>_site_<Joint> (the MuJoCo sites)
            fk = np.array([root.apply(poses[f'u{uid}_site_{n}'][1]) for n in m.JOINT_NAMES])
            errors.append(np.linalg.norm(fk - x, axis=1).max())
    return errors


def _character_report(consumer) -> str:
    with consumer.lock:
        js = [_stamp(j) for j in consumer.extra['/character/joint_states'][-90:]]
        sk = [_stamp(j) for j in consumer.extra['/character/skeletons'][-90:]]
        roots = {u: sorted(consumer.tf.dynamic.get(f'u{u}_seg_Spine', {}))[-3:] for u in USERS}
    return (f'joint states {len(js)} (last {js[-3:]}), skeletons {len(sk)} (last {sk[-3:]}), '
            f'roots on TF: {roots}')
