"""``fusion`` node: several Kinects' skeletons fused into one SkeletonArray in ``world``.

Subscribes
  ``input_topics`` (default ``/kinect_1/skeletons``, ``/kinect_2/skeletons``: the drivers of
  ``driver.launch.py sensors:=2``) -- skeleton_msgs/SkeletonArray, each in its sensor's frame
  (``header.frame_id``, e.g. ``kinect_2_link``).
  ``/tf_static`` -- each sensor frame's pose in ``world`` (the launch files' ``static_tf``, from
  ``sensor_pose`` or a calibration file); messages whose frame TF does not know yet are held (the
  newest second of them per sensor) and taken when it does, older ones dropped (counted as
  ``no transform``, logged once).
Publishes
  ``output_topic`` (default ``/kinect/skeletons``, what the reconstruction reads) -- one
  SkeletonArray in ``world`` per capture of the first sensor still delivering, stamped with its
  capture time: every person once (stable ids), each joint the reliability-weighted mean of the
  sensors that see it, with the fused reliability and tracking state
  (:class:`~.fusion.MultiSensorFusion`). It waits for a late sensor at most one frame period
  (:class:`~.fusion_clock.FusionClock`). With one input topic the messages pass through as they
  came (same bytes, same frame).
  ``/diagnostics`` -- Health (latency = capture -> fused frame published) plus the fusion's
  counters (late views, mirrored views, tracks, stamps published without a late sensor).
"""
from __future__ import annotations

import time
from typing import Dict, List, Optional

from rclpy.qos import QoSProfile

from skeleton_core.cdr import frames_to_cdr
from skeleton_core.params import ParamSpec
from skeleton_core.rosnode import InputDrops, ManagedNode, Parameters, run_node
from skeleton_core.tf import WORLD_FRAME, HeldUntilTf, TfBuffer
from skeleton_core.tf_ros import StaticTfListener
from skeleton_msgs.msg import SkeletonArray

from .fusion import MultiSensorFusion
from .fusion_clock import FRAME_PERIOD_S, FusionClock

QOS_DEPTH = 10   # as the reconstruction's: a frame or two of slack, the newest always wins
MAX_SENSORS = 8  # as driver.launch.py sensors:=N


def _topics(v) -> Optional[str]:
    topics = list(v)
    if not 1 <= len(topics) <= MAX_SENSORS:
        return f'needs 1 to {MAX_SENSORS} topics, got {len(topics)}'
    if any(not t or not isinstance(t, str) for t in topics):
        return 'a topic name is empty'
    if len(set(topics)) != len(topics):
        return 'a topic is listed twice'
    return None


PARAMS: List[ParamSpec] = [
    ParamSpec('input_topics', ['/kinect_1/skeletons', '/kinect_2/skeletons'],
              "the sensors' SkeletonArray topics, one per sensor (the first is the reference: "
              'its capture stamps are the output stamps while it delivers)',
              validator=_topics, read_only=True),
    ParamSpec('output_topic', '/kinect/skeletons', 'fused SkeletonArray in world (the '
              "reconstruction's input)", read_only=True),
    ParamSpec('max_wait_ms', 5.0, 'longest a fused frame waits for a later sensor: a sensor whose '
              'frames come within it after the reference\'s (learned per sensor) is waited for, '
              'one trailing further is not (its newest frame is held, at most one period old); '
              '33.3 waits a whole frame period for every sensor',
              range=(0.0, 1000.0 * FRAME_PERIOD_S), read_only=True),
]


class FusionNode(ManagedNode):
    """Thin adapter: N SkeletonArray topics + /tf_static -> :class:`MultiSensorFusion` ->
    SkeletonArray. Configure builds the fusion and the TF listener; activate subscribes."""

    def __init__(self, **kwargs):
        super().__init__('fusion', **kwargs)
        self._drop = InputDrops(self.health, self.get_logger())
        self.fusion: Optional[MultiSensorFusion] = None
        self.params = Parameters(self, PARAMS)
        out = self.params['output_topic']
        if out in self.params['input_topics']:
            self.destroy_node()
            raise ValueError(f'invalid parameter: output_topic {out!r} is also an input topic')

    # ------------------------------------------------------------------ lifecycle
    def configure(self) -> None:
        self.sensors = list(self.params['input_topics'])
        if len(self.sensors) > 1:   # the per-sensor Eq. 1-8 and the per-track fusion step,
            #                         compiled now: not on the first frame
            from . import fusion_kernels, reliability_kernels
            warm_s = reliability_kernels.warm_up() + fusion_kernels.warm_up()
            if warm_s > 0.5:
                self.get_logger().info(f'compiled kernels ready in {warm_s:.1f} s (cached from now on)')
        self._new_state()
        self.tf = TfBuffer()
        self.tf_listener = StaticTfListener(self, self.tf, on_change=self._release_held)
        self._configured.append(('subscription', self.tf_listener.sub))
        self._pose_key: Dict[str, tuple] = {}   # sensor -> (frame, TF version) of its pose
        self.pub = self.publisher(SkeletonArray, self.params['output_topic'],
                                  QoSProfile(depth=QOS_DEPTH))
        self.diagnostics(extra=self._diag_extra)

    def _new_state(self) -> None:
        from skeleton_core.tf import Transform
        # placements start unknown: a sensor's frames are taken once TF has its frame
        self.fusion = MultiSensorFusion({s: Transform() for s in self.sensors})
        self.clock = FusionClock(self.sensors, max_wait_s=self.params['max_wait_ms'] / 1000.0)
        # the frames that came before TF knew their frame, in arrival order (1 s of each sensor's)
        self._held = HeldUntilTf(limit=round(len(self.sensors) / FRAME_PERIOD_S))

    def activate(self) -> None:
        self._new_state()
        for s in self.sensors:   # serialized: decoded straight to arrays (skeleton_core.cdr)
            self.subscription(SkeletonArray, s, lambda data, s=s: self._on_input(s, data),
                              QoSProfile(depth=QOS_DEPTH), raw=True, watch=True)
        self._deadline = self.timer(FRAME_PERIOD_S, self._on_deadline)
        self._deadline.cancel()   # armed while a stamp waits for a late sensor
        self.get_logger().info(
            f"{', '.join(self.sensors)} -> {self.params['output_topic']}"
            + (' (one sensor: passed through)' if len(self.sensors) == 1
               else f' in {WORLD_FRAME}'))

    def deactivate(self) -> None:
        self._new_state()   # a restart begins with every track anew

    def cleanup(self) -> None:
        self.fusion = None

    def _diag_extra(self) -> Dict:
        if self.fusion is None:
            return {}
        st = self.fusion.stats
        return {'sensors': len(self.sensors), 'tracks': st.tracks, 'late_views': st.late,
                'mirrored_views': st.mirrored, 'unswapped_views': st.unswapped,
                'published_without_late_sensor': self.clock.forced,
                'user_states': sum(len(h) for h in self.fusion._hist.values())}

    # ------------------------------------------------------------------ input
    def _on_input(self, sensor: str, data: bytes) -> None:
        self.health.on_receive()
        if len(self.sensors) == 1:   # one sensor: the message as it came
            self.pub.publish(data)
            self._published(self._stamp_of(data))
            return
        self._take_input(sensor, data)

    def _release_held(self) -> None:
        """TF changed: the frames held for want of it, in the order they came."""
        if self.fusion is None:
            return
        for sensor, data in self._held.take():
            self._take_input(sensor, data)

    def _take_input(self, sensor: str, data: bytes) -> None:
        decoded = self._drop.decode(data)
        if decoded is None:
            return
        stamp, frame_id, frames = decoded
        missing = self._sensor_pose(sensor, frame_id)
        if missing:   # held until TF knows the frame; what no longer fits is dropped
            if self._held.hold((sensor, data)) is not None:
                self._drop('no transform', missing)
            return
        try:
            self.fusion.add(sensor, frames, stamp)
        except (ValueError, FloatingPointError, ArithmeticError, IndexError) as e:
            self._drop('processing error', f'{sensor}: {type(e).__name__}: {e}')
            return
        self._publish(self.clock.on_frame(sensor, stamp, time.monotonic()))

    def _on_deadline(self) -> None:
        self._deadline.cancel()
        self._publish(self.clock.on_timer(time.monotonic()))

    def _publish(self, stamps: List[int]) -> None:
        for st in stamps:
            try:
                frames, stamp, frame_id = self.fusion.fuse(st)
                data = frames_to_cdr(frames, stamp, frame_id)
            except (ValueError, FloatingPointError, ArithmeticError, IndexError) as e:
                self._drop('processing error', f'{type(e).__name__}: {e}')
                continue
            self.pub.publish(data)
            self._published(stamp)
        deadline = self.clock.deadline()
        if deadline is not None:
            if self._deadline.is_canceled() or stamps:   # armed for the pending stamp's deadline
                self._deadline.timer_period_ns = max(
                    1, int((deadline - time.monotonic()) * 1e9))
                self._deadline.reset()
        elif not self._deadline.is_canceled():
            self._deadline.cancel()

    def _published(self, stamp_ns: Optional[int]) -> None:
        lat = None
        if stamp_ns:
            lat = time.time() - stamp_ns * 1e-9
            lat = lat if 0 <= lat < 60 else None
        self.health.on_publish(lat)

    @staticmethod
    def _stamp_of(data: bytes) -> Optional[int]:
        try:
            from skeleton_core.cdr import header_stamp_ns
            return header_stamp_ns(data)
        except Exception:  # noqa: BLE001 - passed through as it came: the stamp is only a figure
            return None

    def _sensor_pose(self, sensor: str, frame: str) -> str:
        """The sensor's placement (world <- ``frame``) from TF into the fusion; '' when it is
        there, else why not."""
        key = (frame, self.tf.version)
        if self._pose_key.get(sensor) == key:
            return ''
        try:   # (the listener's lookup: a /tf_static message the executor was not woken for
            #       is taken now; the frames held meanwhile are released first)
            pose = self.tf_listener.lookup(WORLD_FRAME, frame or '?')
        except LookupError as e:
            return (f'{sensor}: waiting for TF {WORLD_FRAME} -> {frame} ({e}); the launch files '
                    'publish it (static_tf: sensor_pose, extrinsics)')
        self.fusion.poses[sensor] = pose
        if self._pose_key.get(sensor, ('',))[0] != frame:
            self.get_logger().info(f'{sensor}: frame {frame} in {WORLD_FRAME}: {pose}')
        self._pose_key[sensor] = (frame, self.tf.version)
        return ''


def main(args=None) -> int:
    return run_node(FusionNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
