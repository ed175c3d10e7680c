"""``hri`` node: skeletons -> the outputs the ROS ecosystem reads (REP-155 bodies, TF per joint).

Subscribes to ``/posture/reconstructed`` (``source: reconstructed``; bodies ``u<user id>``) or
``/character/skeletons`` (``source: character``; bodies ``c<user id>``) and publishes

* REP-155 (ROS4HRI; ``rep155: true``): ``/humans/bodies/tracked`` (``hri_msgs/IdsList``), per
  body ``/humans/bodies/<id>/urdf`` (``std_msgs/String``, latched; made again only when the body's
  estimated segment lengths change), ``/humans/bodies/<id>/joint_states``
  (``sensor_msgs/JointState``) and on ``/tf`` the frame ``body_<id>`` (hip centre, x forward,
  z up) under the input's frame with every link of the body's URDF under it;
* openni2_tracker's frames (``openni_tf: true``): ``head_1``, ``left_hand_1``, ... under the
  input's frame.

A body that leaves the input (or all of them, when the input stops for ``stale_timeout_s``)
disappears from ``tracked``, its frames stop and its topics are removed. The bodies, their URDF,
angles and transforms are :class:`skeleton_core.rep155.BodyTracker`'s; this node adapts messages.
"""
from __future__ import annotations

import time
from typing import Any, Dict, Optional

from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy,
                       qos_profile_sensor_data)

from skeleton_core.cdr import CdrError, frames_from_cdr
from skeleton_core.conversions import ns_to_stamp
from skeleton_core.params import ParamSpec, hidden
from skeleton_core.rep155 import TRACKED_TOPIC, BodyTracker, TfEncoder, body_topic
from skeleton_core.rosnode import ManagedNode, Parameters, run_node

SOURCES = {'reconstructed': 'u', 'character': 'c'}
LATCHED = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
TF_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                    reliability=ReliabilityPolicy.RELIABLE)


def _topic_ok(v):
    return None if v else 'topic name must not be empty'


PARAMS = [
    ParamSpec('source', 'reconstructed', 'whose bodies: the reconstruction (bodies u<user>) or '
              'the physics character (bodies c<user>)', choices=tuple(SOURCES), read_only=True),
    ParamSpec('rep155', True, 'publish REP-155 bodies (/humans/bodies/..., body_<id> TF tree)'),
    ParamSpec('openni_tf', False, "publish openni2_tracker's TF frames per joint (head_1, "
              'left_hand_1, ...) under the skeleton frame'),
    hidden(ParamSpec('reconstructed_topic', '/posture/reconstructed', 'reconstructed postures',
                     read_only=True, validator=_topic_ok)),
    hidden(ParamSpec('character_topic', '/character/skeletons', 'simulated characters',
                     read_only=True, validator=_topic_ok)),
    hidden(ParamSpec('stale_timeout_s', 0.5, 'no input for this long: every body has left (s)',
                     range=(0.05, 10.0))),
    hidden(ParamSpec('length_window', 30, 'frames whose median segment lengths make a URDF',
                     range=(1, 1000))),
    hidden(ParamSpec('length_tolerance_m', 0.01, 'URDF made again when a median segment length '
                     'moved more than this (m; the stretch joints carry smaller changes)',
                     range=(0.0005, 0.5))),
]


class HriNode(ManagedNode):
    """Thin adapter: SkeletonArray -> BodyTracker -> IdsList, String, JointState, TFMessage."""

    def __init__(self, **kwargs):
        super().__init__('hri', **kwargs)
        self.tracker: Optional[BodyTracker] = None
        self._body_pubs: Dict[str, tuple] = {}
        self._tf_encoder = TfEncoder()
        self._last_input = None
        self.params = Parameters(self, PARAMS, apply=self._apply_change)

    def configure(self) -> None:
        from hri_msgs.msg import IdsList
        from tf2_msgs.msg import TFMessage
        v = self.params.values
        self.tracker = BodyTracker(SOURCES[v['source']], window=v['length_window'],
                                   length_tolerance=v['length_tolerance_m'],
                                   openni=v['openni_tf'], rep155=v['rep155'])
        self._tracked_pub = self.publisher(IdsList, TRACKED_TOPIC, 10)
        self._tf_pub = self.publisher(TFMessage, '/tf', TF_QOS)
        self.diagnostics(extra=lambda: {'bodies': len(self._body_pubs)})

    def activate(self) -> None:
        from skeleton_msgs.msg import SkeletonArray
        v = self.params.values
        topic = v[f"{v['source']}_topic"]
        self.subscription(SkeletonArray, topic, self._on_skeletons, qos_profile_sensor_data,
                          raw=True)
        self.timer(0.1, self._check_stale)
        self.get_logger().info(
            f"{topic} -> " + ', '.join(
                w for w, on in (('REP-155 bodies', v['rep155']),
                                ('openni2_tracker TF frames', v['openni_tf'])) if on))

    def deactivate(self) -> None:
        self._leave(self.tracker.clear(), None)

    def cleanup(self) -> None:
        self.tracker = None

    def _apply_change(self, changed: Dict[str, Any]) -> None:
        if self.tracker is None:
            return
        v = self.params.values
        self.tracker.openni = v['openni_tf']
        if 'rep155' in changed:
            self._leave(self.tracker.clear(), None)
            self.tracker.rep155 = v['rep155']

    # ---------------------------------------------------------------- input
    def _on_skeletons(self, data: bytes) -> None:
        self.health.on_receive()
        errors = []
        try:
            stamp_ns, frame_id, frames = frames_from_cdr(data, errors)
        except CdrError as e:
            if self.health.on_drop('malformed message'):
                self.get_logger().warning(f'dropped a malformed message ({e}); '
                                          'further drops of this cause are only counted')
            return
        for e in errors:
            if self.health.on_drop(e.cause):
                self.get_logger().warning(f'dropped a skeleton ({e}); '
                                          'further drops of this cause are only counted')
        self._last_input = time.monotonic()
        out = self.tracker.update(frames, stamp_ns, frame_id or 'kinect_link', self._last_input)
        self._publish(out)
        self.health.on_publish(latency_s=(time.time_ns() - stamp_ns) / 1e9 if stamp_ns else None)

    def _check_stale(self) -> None:
        if (self._last_input is not None and self.tracker.bodies
                and time.monotonic() - self._last_input > self.params.values['stale_timeout_s']):
            self._leave(self.tracker.clear(), None)

    # ---------------------------------------------------------------- output
    def _publish(self, out) -> None:
        from sensor_msgs.msg import JointState
        from std_msgs.msg import String
        self._leave(out.left, out.stamp_ns)
        if self.tracker.rep155:
            for bid in out.tracked:
                if bid not in self._body_pubs:
                    self._body_pubs[bid] = (
                        self.create_publisher(String, body_topic(bid, 'urdf'), LATCHED),
                        self.create_publisher(JointState, body_topic(bid, 'joint_states'), 10),
                        JointState())
            for bid, text in out.urdf.items():
                self._body_pubs[bid][0].publish(String(data=text))
            for bid in out.tracked:
                _, pub, js = self._body_pubs[bid]
                ns_to_stamp(out.stamp_ns, js.header.stamp)
                js.header.frame_id = ''
                js.name = out.joint_names[bid]
                js.position = out.angles[bid].tolist()
                pub.publish(js)
            self._publish_tracked(out.tracked, out.stamp_ns)
        if out.tf_pairs:
            self._publish_tf(out)

    def _publish_tracked(self, ids, stamp_ns) -> None:
        from hri_msgs.msg import IdsList
        msg = IdsList(ids=list(ids))
        if stamp_ns is not None:
            ns_to_stamp(stamp_ns, msg.header.stamp)
        else:
            msg.header.stamp = self.get_clock().now().to_msg()
        self._tracked_pub.publish(msg)

    def _leave(self, left, stamp_ns) -> None:
        for bid in left:
            pubs = self._body_pubs.pop(bid, None)
            if pubs is not None:
                self.destroy_publisher(pubs[0])
                self.destroy_publisher(pubs[1])
        if (left and stamp_ns is None and self.tracker is not None and self.tracker.rep155
                and self.context.ok()):
            self._publish_tracked([], None)   # the input stopped: nobody is tracked

    def _publish_tf(self, out) -> None:
        # serialized by TfEncoder: hundreds of transforms per frame with 6 users
        self._tf_pub.publish(self._tf_encoder.encode(out.tf_pairs, out.stamp_ns,
                                                     out.tf_translations, out.tf_rotations))


def main(args=None):
    return run_node(HriNode, args=args)


if __name__ == '__main__':
    main()
