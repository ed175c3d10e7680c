"""Node ``driver``: publishes Kinect skeletons (``skeleton_msgs/SkeletonArray``) on
``/kinect/skeletons`` from one source:

* ``synthetic`` (default): built-in or CMU motion through the Kinect sensor model
  (:mod:`kinect_driver.sources.synthetic`); optionally the ground truth on ``/kinect/ground_truth``.
* ``replay``: a recorded bag (MCAP) or CSV file (:mod:`kinect_driver.sources.replay`); bag messages
  are republished byte for byte unless ``restamp`` is set, and so is every other topic of the bag
  that the graph does not produce itself (``/kinect/ground_truth`` included). With
  ``wait_for_subscribers`` > 0 (the launch file and ``pipeline`` set the graph's count) the replay
  waits before its first frame until ``/kinect/skeletons`` has that many subscribers, and after
  it until they acknowledged it (at most ``wait_timeout_s``): nothing is lost while the graph
  comes up. Every other source waits for those subscribers before its first frame too (counted
  by its publisher, which has then met them), and is not held after it.
* ``live``: an OpenNI2 sensor or ``.oni`` recording with the NiTE2 user tracker
  (:mod:`kinect_driver.sources.openni_live`, docs/live_kinect.md).
* ``azure_kinect``: the body markers of the Azure Kinect ROS driver (Azure Kinect, Orbbec Femto;
  :mod:`kinect_driver.sources.azure_kinect`, docs/azure_kinect.md); the node subscribes to what
  the source asks for and hands it the serialized messages.

A timer runs at the source's rate (rcl timers are drift-free: each deadline is the previous one
plus the period) and publishes what the source has due, stamped with the capture time. Optional TF
(``tf2_msgs/TFMessage`` on ``/tf``): one frame per NiTE joint and user named like the ROS 1
openni2_tracker (``head_1``, ``neck_1``, ``torso_1``, ...), child of the skeleton's frame.
Parameters: config/driver.yaml. Health on ``/diagnostics``.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import List

from rclpy.qos import QoSProfile

from skeleton_core.cdr import frames_to_cdr
from skeleton_core.conversions import frames_from_array_msg, frames_to_array_msg, ns_to_stamp
from skeleton_core.params import ParamSpec, build, param, specs
from skeleton_core.rosnode import ManagedNode, Parameters, run_node

from .replay_gate import ReplayGate
from .sources import SourceError, SourceOutput, source_class, source_names
from .tf_names import tf_frames

SKELETONS_TOPIC = '/kinect/skeletons'
GROUND_TRUTH_TOPIC = '/kinect/ground_truth'
STALL_S = 2.0  # live: warn when the device sends nothing for this long
# a recording's frames are kept until every reader acknowledged them (a reader held up for longer
# than the live depth of 10 frames would otherwise miss the ones behind them): 33 s at 30 Hz
RECORDING_DEPTH = 1000


def _non_empty(name):
    return lambda v: None if v else f'{name} must not be empty'


@dataclass
class DriverConfig:
    """The driver node's own parameters (each source adds its ``config_class``'s)."""

    source: str = param('synthetic', 'skeleton source (kinect_driver.sources: synthetic | replay '
                        '| live | azure_kinect, or a registered one)', read_only=True)
    frame_id: str = param('kinect_link', 'frame of the published skeletons (the sensor frame, '
                          'REP-103)', read_only=True, validator=_non_empty('frame_id'))
    publish_tf: bool = param(False, 'also broadcast one TF frame per NiTE joint and user '
                             '(head_1, neck_1, ...) on /tf')
    tf_prefix: str = param('', 'prefix of the TF joint frame names', public=False)
    publish_ground_truth: bool = param(
        True, 'publish the noise-free skeletons of a source that has them (synthetic) on '
        '/kinect/ground_truth', public=False)
    restamp: bool = param(False, 'stamp messages with the current time instead of the recorded '
                          'stamps (replay)', read_only=True)


def driver_params() -> List[ParamSpec]:
    """The node's parameters: its own, then every registered source's (read-only, the
    description prefixed with the source's name). Two sources may share a parameter only if they
    declare it alike."""
    out = specs(DriverConfig)
    names = source_names()
    out[0] = dataclasses.replace(out[0], choices=tuple(names))
    seen = {s.name: ('driver', s) for s in out}
    for name in names:
        cls = source_class(name)
        for s in specs(cls.config_class, read_only=True):
            prev = seen.get(s.name)
            if prev is not None:
                if (prev[1].default, prev[1].range, prev[1].choices) != (s.default, s.range, s.choices):
                    raise RuntimeError(f'source {name!r} declares parameter {s.name!r} unlike '
                                       f'{prev[0]!r}')
                continue
            s = dataclasses.replace(s, description=f'{name}: {s.description}')
            seen[s.name] = (name, s)
            out.append(s)
    return out


node_params = driver_params   # what kinect_experiments.param_docs documents (the registry of now)


def make_source(v, log=None, clock_ns=None):
    """The source named by the parameter values ``v`` (not opened)."""
    cls = source_class(v['source'])
    return cls.from_config(build(cls.config_class, v), frame_id=v['frame_id'], log=log,
                           clock_ns=clock_ns)


class DriverNode(ManagedNode):
    """Configure makes the source and opens it (a device that is not there yet, with a retry
    period, is retried while active); activate starts the capture timer; cleanup closes it."""

    def __init__(self, **kwargs):
        super().__init__('driver', **kwargs)
        self._first_out = True
        from skeleton_msgs.msg import SkeletonArray
        self._msg_type = SkeletonArray
        self.source = None
        self._other_pubs = {}
        self.params = Parameters(self, driver_params())

    def configure(self) -> None:
        v = self.params.values
        qos = QoSProfile(depth=10)
        recorded = getattr(source_class(v['source']), 'recorded', False)
        self.pub = self.publisher(self._msg_type, SKELETONS_TOPIC,
                                  QoSProfile(depth=RECORDING_DEPTH) if recorded else qos)
        self.truth_pub = self.publisher(self._msg_type, GROUND_TRUTH_TOPIC, qos) \
            if source_class(v['source']).has_truth else None
        self.tf_pub = None
        try:
            from tf2_msgs.msg import TFMessage
            self.tf_pub = self.publisher(TFMessage, '/tf', qos)
        except ImportError:
            if v['publish_tf']:
                self.get_logger().warning('publish_tf is set but tf2_msgs is not installed: '
                                          'no TF is published')
        self._warned = set()
        self.tracker_pub = None
        self._finished_logged = False
        self._stalled = False
        self._other_pubs = {}
        self.source = make_source(v, log=self._warn_once, clock_ns=self._now_ns)
        self._opened = False
        try:
            self.source.open()
            self._opened = True
            self._open_other_topics()
        except SourceError as e:
            if not (e.retryable and self.source.retry_s > 0):
                raise RuntimeError(str(e)) from None
            self.get_logger().warning(f'{e} - retrying every {self.source.retry_s:g} s')
        # the first frame only once the graph's readers are there (kinect_driver.replay_gate),
        # counted by this publisher (its side of the match; the graph's list may lag it); a
        # replay is also held until they acknowledged it, a live source cannot be held
        log = self.get_logger()
        self.gate = ReplayGate(v['wait_for_subscribers'], v['wait_timeout_s'], info=log.info,
                               warn=log.warning, on_release=self._delay_source,
                               topic=SKELETONS_TOPIC, hold_first=self.source.recorded,
                               label='replay' if self.source.recorded else v['source'])
        self.diagnostics(extra=self.source.status)

    def activate(self) -> None:
        self._retry_timer = None
        self._first_out = True   # the first frame of this activation: see _publish
        self._subscribe_source()
        if self._opened:
            self._started()
        else:
            self._retry_timer = self.timer(self.source.retry_s, self._retry_open)
        self.timer(self.source.period_s, self._tick)

    def _subscribe_source(self) -> None:
        """The topics a source takes its input from (e.g. azure_kinect: the Azure Kinect ROS
        driver's markers), as serialized messages handed to the source's callback."""
        import importlib
        for topic, msgtype, callback in getattr(self.source, 'subscriptions', lambda: [])():
            pkg, kind, name = msgtype.split('/')
            try:
                cls = getattr(importlib.import_module(f'{pkg}.{kind}'), name)
            except (ImportError, AttributeError):
                self.get_logger().error(f'cannot subscribe to {topic}: {msgtype} is not installed')
                continue
            self.subscription(cls, topic, callback, QoSProfile(depth=30), raw=True)

    def cleanup(self) -> None:
        if self.source is not None:
            self.source.close()
            self.source = None
        self._other_pubs = {}

    def _delay_source(self, held_s: float) -> None:
        if hasattr(self.source, 'delay'):
            self.source.delay(int(held_s * 1e9))

    # ------------------------------------------------------------------------------------
    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _warn_once(self, text: str) -> None:
        # the live reader thread reports through here; repeated identical lines are logged once
        if text not in self._warned:
            self._warned.add(text)
            self.get_logger().warning(text)

    def _started(self) -> None:
        v = self.params.values
        if self.source.tracker and self.tracker_pub is None:
            # the skeleton tracker, latched for late joiners (skeleton_core.tracker)
            from rclpy.qos import DurabilityPolicy
            from std_msgs.msg import String
            from skeleton_core.tracker import TOPIC
            self.tracker_pub = self.create_publisher(
                String, TOPIC, QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
            self.tracker_pub.publish(String(data=self.source.tracker))
        extra = self.source.describe()
        extra = f' {extra}' if extra else ''
        self.get_logger().info(f"source {v['source']} started at "
                               f'{1.0 / self.source.period_s:.1f} Hz on {SKELETONS_TOPIC};{extra}')

    def _open_other_topics(self) -> None:
        """Publishers for the replayed bag's other topics (types from the installed packages)."""
        import importlib
        for topic, msgtype in getattr(self.source, 'other_topics', {}).items():
            try:
                pkg, kind, name = msgtype.split('/')
                cls = getattr(importlib.import_module(f'{pkg}.{kind}'), name)
            except (ImportError, AttributeError, ValueError):
                self._warn_once(f'replay: {topic} ({msgtype}) is not replayed: the message type '
                                f'is not installed')
                continue
            self._other_pubs[topic] = self.publisher(cls, topic, QoSProfile(depth=100))

    def _retry_open(self) -> None:
        try:
            self.source.open()
        except SourceError as e:
            self._warn_once(str(e))
            return
        self._opened = True
        self._retry_timer.cancel()   # (destroyed on deactivate)
        self._open_other_topics()
        self._started()

    def _tick(self) -> None:
        if not self._opened:
            return
        if not self.gate.playing and not self.gate.may_poll(
                self.pub.get_subscription_count,
                lambda: [t for t, p in self._other_pubs.items() if p.get_subscription_count() == 0],
                self._all_acked):
            return
        now = self._now_ns()
        try:
            outputs = self.source.poll(now)
        except Exception as e:  # noqa: BLE001 - a source bug must not kill the node silently
            if self.health.on_drop(f'source error: {type(e).__name__}'):
                self.get_logger().error(f'source failed: {e}')
            return
        try:
            for out in outputs:
                self._publish(out, now)
        except Exception:  # noqa: BLE001
            if not self.context.ok():  # shutting down (Ctrl-C / SIGTERM) mid-callback
                return
            raise
        if not self.gate.playing:
            self.gate.published(len(outputs))
        try:
            self.source.prepare()
        except Exception as e:  # noqa: BLE001 - as poll(): counted and logged, never fatal
            if self.health.on_drop(f'source error: {type(e).__name__}'):
                self.get_logger().error(f'source failed: {e}')
        last = getattr(self.source, 'last_frame_ns', 0)
        if last and now - last > STALL_S * 1e9:
            if not self._stalled:
                self._stalled = True
                self.get_logger().warning(f'no frames from the device for {STALL_S:g} s '
                                          f'(unplugged or covered?)')
        elif self._stalled and last:
            self._stalled = False
            self.get_logger().info('frames from the device again')
        if self.source.finished and not self._finished_logged:
            self._finished_logged = True
            self.get_logger().info('replay finished (set loop:=true to repeat)')

    def _publish_other(self, out: SourceOutput, now: int) -> None:
        """A replayed message of another topic: as recorded (restamped like the skeletons)."""
        pub = self._other_pubs.get(out.topic)
        if pub is None:
            return
        data = out.raw
        if self.params['restamp'] and out.msgtype == 'skeleton_msgs/msg/SkeletonArray':
            from rclpy.serialization import deserialize_message
            data = deserialize_message(out.raw, self._msg_type)
            ns_to_stamp(now, data.header.stamp)
            for sk in data.skeletons:
                ns_to_stamp(now, sk.header.stamp)
        pub.publish(data)

    def _publish(self, out: SourceOutput, now: int) -> None:
        if out.topic:
            self._publish_other(out, now)
            return
        v = self.params.values
        self.health.on_receive()
        live_stamp = not self.source.recorded or v['restamp']
        first = self._first_out
        if first and not self.source.recorded:
            # a live source's first frame reaches every subscriber the graph knows (the nodes
            # activated before this driver; DDS matching is two-sided, and the driver's side may
            # lag): bounded by REACH_WAIT_S. A replay has its own handshake (replay_gate)
            self.reach_subscribers([p for p in (self.pub, self.truth_pub) if p is not None])
        msg = None
        if out.raw is not None:
            if v['restamp'] or (v['publish_tf'] and self.tf_pub is not None):
                from rclpy.serialization import deserialize_message
                msg = deserialize_message(out.raw, self._msg_type)
            if v['restamp']:
                ns_to_stamp(now, msg.header.stamp)
                for sk in msg.skeletons:
                    ns_to_stamp(now, sk.header.stamp)
                self.pub.publish(msg)
            else:
                self.pub.publish(out.raw)
            stamp = now if v['restamp'] else out.stamp_ns
        else:
            stamp = now if (self.source.recorded and v['restamp']) else out.stamp_ns
            frames = [f.copy(stamp_ns=stamp) for f in out.frames] if stamp != out.stamp_ns \
                else out.frames
            fid = out.frame_id or v['frame_id']
            try:
                if v['publish_tf'] and self.tf_pub is not None:
                    msg = frames_to_array_msg(frames, stamp, fid)   # the TF needs the message
                    data = msg
                else:   # serialized directly (skeleton_core.cdr): no message objects per joint
                    data = frames_to_cdr(frames, stamp, fid)
            except ValueError as e:
                if self.health.on_drop(getattr(e, 'cause', 'invalid skeleton')):
                    self.get_logger().warning(f'dropped a frame: {e}')
                return
            self.pub.publish(data)
        self.health.on_publish(latency_s=(now - stamp) / 1e9 if live_stamp else None)
        if out.truth is not None and v['publish_ground_truth'] and self.truth_pub is not None:
            self.truth_pub.publish(frames_to_cdr(out.truth, stamp, out.frame_id or v['frame_id']))
        if first:   # a recording can be checked to start with it
            self._first_out = False
            self.get_logger().info(f'first frame on {SKELETONS_TOPIC}: stamp '
                                   f'{stamp // 10**9}.{stamp % 10**9:09d}')
        if v['publish_tf'] and self.tf_pub is not None and msg is not None:
            self._publish_tf(msg)

    def _publish_tf(self, msg) -> None:
        from geometry_msgs.msg import TransformStamped
        from tf2_msgs.msg import TFMessage
        prefix = self.params['tf_prefix']
        tfs: List[TransformStamped] = []
        for f in frames_from_array_msg(msg):
            parent = f.frame_id or msg.header.frame_id or self.params['frame_id']
            for child, j in tf_frames(f, prefix):
                t = TransformStamped()
                t.header.frame_id = parent
                ns_to_stamp(f.stamp_ns, t.header.stamp)
                t.child_frame_id = child
                x, y, z = f.positions[j]
                t.transform.translation.x, t.transform.translation.y = float(x), float(y)
                t.transform.translation.z = float(z)
                if f.orientations is not None:
                    qx, qy, qz, qw = f.orientations[j]
                    t.transform.rotation.x, t.transform.rotation.y = float(qx), float(qy)
                    t.transform.rotation.z, t.transform.rotation.w = float(qz), float(qw)
                else:
                    t.transform.rotation.w = 1.0
                tfs.append(t)
        if tfs:
            self.tf_pub.publish(TFMessage(transforms=tfs))

    def _all_acked(self) -> bool:
        from rclpy.duration import Duration
        zero = Duration(seconds=0)
        return all(p.wait_for_all_acked(zero) for p in [self.pub, *self._other_pubs.values()])


def main(args=None) -> int:
    return run_node(DriverNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
