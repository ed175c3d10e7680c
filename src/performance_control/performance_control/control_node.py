"""``control`` node: performance-based character control (Ishigaki et al. 2009) between the
reconstruction and the physics.

Subscribes
  ``input_topic`` (default ``/posture/reconstructed``) -- skeleton_msgs/SkeletonArray: each user's
  performance.
Publishes
  ``output_topic`` (default ``/control/target``) -- SkeletonArray: the composed pose each user's
  physics character tracks (sensor frame, the input's frame and stamps; the physics node's
  ``input_topic`` points here when the launch file's ``control:=true``).
  ``/control/intention`` -- skeleton_msgs/Intention per user and frame: the engaged / imitated
  feature, confidence, e1, e2 (Eq. 5-6), the engaged effectors and their features.
  ``/control/markers`` -- visualization_msgs/MarkerArray: the features (namespace
  ``control_features``, 1 Hz and when they move) and the contacts (``control_contacts``).
  ``/diagnostics``.

Every tunable number is a parameter (thresholds and gains can be set at run time); the world is
read from ``world`` (a name in the package's config/worlds or a YAML path) at start-up.
"""
from __future__ import annotations

import math
import time
from typing import Dict, List, Optional

import numpy as np
from rclpy.node import Node
from skeleton_core.cdr import CdrError, frames_from_cdr, frames_to_cdr
from skeleton_core.conversions import SkeletonFrame, ns_to_stamp
from skeleton_core.health import Health
from skeleton_core.model import NUM_JOINTS, TRACKED
from skeleton_core.rosnode import DiagnosticsPublisher, Parameters, ParamSpec, run_node
from skeleton_msgs.msg import Intention, SkeletonArray
from visualization_msgs.msg import MarkerArray

from .controller import ControlParams, PerformanceController, build_models
from .features import WorldError, load_world
from .intention import RecognizerParams
from .markers import contact_shapes, to_marker_array, world_shapes

REC_KEYS = ('e1_threshold', 'e2_threshold', 'tau', 'smoothing', 'min_activity',
            'activity_window', 'prefilter', 'combine', 'normalise')
CTRL_KEYS = ('free_gain', 'release_after', 'hand_release_margin', 'regrab_speed', 'foot_down_height',
             'blend_time', 'w_e', 'w_s')
_R = RecognizerParams()
_C = ControlParams()

PARAMS: List[ParamSpec] = [
    ParamSpec('world', 'playground', 'feature world: a name in config/worlds or a YAML path',
              read_only=True),
    ParamSpec('start_feature', '', 'feature a new character starts on ("" = the world\'s spawn '
              'on the floor; e.g. monkey_bars: hanging from the nearest bar)', read_only=True),
    ParamSpec('input_topic', '/posture/reconstructed', 'performances (SkeletonArray)',
              read_only=True),
    ParamSpec('output_topic', '/control/target', 'composed poses for the physics (SkeletonArray)',
              read_only=True),
    ParamSpec('intention_topic', '/control/intention', 'skeleton_msgs/Intention', read_only=True),
    ParamSpec('markers_topic', '/control/markers', 'features and contacts (MarkerArray)',
              read_only=True),
    ParamSpec('e1_threshold', _R.e1_threshold, 'Eq. 5 threshold (squared error, body-height '
              'units): the user\'s pose near the example\'s PCA subspace', range=(1e-5, 10.0)),
    ParamSpec('e2_threshold', _R.e2_threshold, 'Eq. 6 threshold: consistency of the user\'s '
              'change over lag frames with the example', range=(1e-5, 10.0)),
    ParamSpec('tau', _R.tau, 'weight (s) of the effector velocities against positions in w',
              range=(0.0, 2.0)),
    ParamSpec('lag', _R.lag, 'frames of the velocity and of dw in Eq. 6', range=(1, 30),
              read_only=True),
    ParamSpec('smoothing', _R.smoothing, 'time constant (s) of the e1/e2 averages',
              range=(0.0, 5.0)),
    ParamSpec('prefilter', _R.prefilter, 'time constant (s) of the low-pass on the relative '
              'joint positions before the features (sensor noise)', range=(0.0, 1.0)),
    ParamSpec('min_activity', _R.min_activity, 'share of the example\'s RMS effector speed the '
              'user must reach to be imitating (a still pose has dw = 0)', range=(0.0, 10.0)),
    ParamSpec('activity_window', _R.activity_window, 'time constant (s) of the speed average of '
              'the activity gate', range=(0.0, 10.0)),
    ParamSpec('activity_lag', _R.activity_lag, 'frames of the activity gate\'s displacement',
              range=(1, 60), read_only=True),
    ParamSpec('combine', _R.combine, 'and: e1 and e2 under their thresholds; or: either (the '
              'paper\'s consistency read as an alternative to similarity)', choices=('and', 'or')),
    ParamSpec('normalise', _R.normalise, 'e1/e2 in units of each example\'s own spread (total '
              'variance of w, mean |dw|^2); the thresholds are then in those units'),
    ParamSpec('release_after', _C.release_after, 's without imitation before hands on a feature '
              'with an example let go (the character falls when the user stops; 0 = never)',
              range=(0.0, 60.0)),
    ParamSpec('hand_release_margin', _C.hand_release_margin, 'm: a held hand lets go when the '
              'user\'s hand drops this far below the feature\'s engage joint', range=(0.0, 1.0)),
    ParamSpec('regrab_speed', _C.regrab_speed, 'm/s: on a feature with engage.regrab (the rope) a '
              'held hand the user raises faster lets go to grab higher (hand over hand)',
              range=(0.05, 10.0)),
    ParamSpec('foot_down_height', _C.foot_down_height, 'm: the user\'s foot this close to their '
              'floor is constrained (may hold the floor / trampoline)', range=(0.005, 0.5)),
    ParamSpec('free_gain', _C.free_gain, 'N/m (N/rad): gain of effectors without a contact',
              range=(10.0, 1e5)),
    ParamSpec('blend_time', _C.blend_time, 's: transition in/out of the composed pose',
              range=(0.01, 5.0)),
    ParamSpec('w_e', _C.w_e, 'Eq. 8 weight of G_E (example similarity; w_P = 1)',
              range=(0.0, 100.0)),
    ParamSpec('w_s', _C.w_s, 'Eq. 8 weight of G_S (smoothness)', range=(0.0, 100.0)),
    ParamSpec('sensor_height', _C.sensor_height, 'm above the floor (the same world as the '
              'physics node)', range=(0.0, 5.0), read_only=True),
    ParamSpec('sensor_pitch_deg', 0.0, 'sensor tilt down (deg)', range=(-45.0, 45.0),
              read_only=True),
    ParamSpec('body_mass', _C.body_mass, 'kg at 1.75 m (scaled with height^3)',
              range=(20.0, 300.0), read_only=True),
    ParamSpec('user_timeout', 2.0, 's without a user before its controller is dropped',
              range=(0.1, 60.0)),
    ParamSpec('max_users', 6, 'users controlled at once (more are ignored)', range=(1, 30),
              read_only=True),
]


class ControlNode(Node):
    """Thin adapter: SkeletonArray -> :class:`PerformanceController` per user -> SkeletonArray,
    Intention and markers."""

    def __init__(self, **kwargs):
        super().__init__('control', **kwargs)
        self.health = Health()
        self.params = Parameters(self, PARAMS, on_change=self._on_params)
        v = self.params.values
        try:
            self.world = load_world(v['world'])
        except (WorldError, FileNotFoundError) as e:
            raise ValueError(f'control: {e}') from None
        if v['start_feature'] and v['start_feature'] not in self.world.features:
            raise ValueError(f'control: start_feature {v["start_feature"]!r} is not in world '
                             f'{self.world.name} ({sorted(self.world.features)})')
        self.rp = RecognizerParams(**{k: v[k] for k in REC_KEYS}, lag=v['lag'],
                                   activity_lag=v['activity_lag'])
        self.cp = ControlParams(recognizer=self.rp, sensor_height=v['sensor_height'],
                                sensor_pitch=math.radians(v['sensor_pitch_deg']),
                                body_mass=v['body_mass'], **{k: v[k] for k in CTRL_KEYS})
        self.cp.validate()
        self.models = build_models(self.world, self.rp)
        self.users: Dict[int, PerformanceController] = {}
        self.last_seen: Dict[int, float] = {}
        self.frame_id = 'kinect'
        self.ms: List[float] = []
        self.pub = self.create_publisher(SkeletonArray, v['output_topic'], 10)
        self.int_pub = self.create_publisher(Intention, v['intention_topic'], 10)
        self.mk_pub = self.create_publisher(MarkerArray, v['markers_topic'], 10)
        self.create_subscription(SkeletonArray, v['input_topic'], self._on_input, 1, raw=True)
        self.create_timer(1.0, self._publish_features)
        self.diag = DiagnosticsPublisher(self, self.health, extra=self._diag)
        self.get_logger().info(
            f'control: world {self.world.name} ({", ".join(self.world.features)}), '
            f'{v["input_topic"]} -> {v["output_topic"]}')

    def _on_params(self, changed: Dict) -> Optional[str]:
        for k, val in changed.items():
            if k in REC_KEYS:
                setattr(self.rp, k, val if isinstance(val, (str, bool)) else float(val))
            elif k in CTRL_KEYS:
                setattr(self.cp, k, float(val))
        return None

    def _diag(self) -> Dict:
        out = {'users': len(self.users), 'world': self.world.name}
        if self.ms:
            out['control_ms_median'] = float(np.median(self.ms[-300:]))
        return out

    def _drop(self, cause: str, detail: str) -> None:
        if self.health.on_drop(cause):
            self.get_logger().warning(f'dropping input ({cause}): {detail} (logged once per cause)')

    def _on_input(self, data: bytes) -> None:
        self.health.on_receive()
        errors: list = []
        try:
            stamp, frame, frames = frames_from_cdr(data, errors)
        except CdrError as e:
            self._drop('malformed message', str(e))
            return
        for e in errors:
            self._drop(getattr(e, 'cause', 'malformed'), str(e))
        if frame:
            self.frame_id = frame
        now = time.monotonic()
        out_frames = []
        for f in frames:
            uid = int(f.user_id)
            ctl = self.users.get(uid)
            if ctl is None:
                if len(self.users) >= self.params['max_users']:
                    self._drop('too many users', f'user {uid} ignored')
                    continue
                ctl = self.users[uid] = PerformanceController(
                    self.world, self.cp, self.models, start=self.params['start_feature'])
                self.get_logger().info(f'user {uid}: controller started')
            st = f.stamp_ns or stamp
            try:
                o = ctl.step(f.positions, st * 1e-9)
            except (ValueError, FloatingPointError) as e:
                self._drop('bad input', str(e))
                self.users.pop(uid, None)
                continue
            self.last_seen[uid] = now
            self.ms.append(o.compute_ms)
            del self.ms[:-1000]
            out_frames.append(SkeletonFrame(
                positions=o.positions_sensor, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                reliability=np.ones(NUM_JOINTS, np.float32), user_id=uid, stamp_ns=st,
                frame_id=self.frame_id))
            self._publish_intention(uid, st, o)
        for uid in [u for u, t in self.last_seen.items() if now - t > self.params['user_timeout']]:
            self.users.pop(uid, None)
            self.last_seen.pop(uid, None)
            self.get_logger().info(f'user {uid} left: controller dropped')
        if out_frames:
            self.pub.publish(frames_to_cdr(out_frames, stamp, self.frame_id))
            self.health.on_publish(None)
            self._publish_contacts(stamp)

    def _publish_intention(self, uid: int, stamp_ns: int, o) -> None:
        m = Intention()
        m.header.stamp = ns_to_stamp(stamp_ns)
        m.header.frame_id = self.frame_id
        m.user_id = uid
        m.feature = o.feature
        m.imitating = bool(o.imitating)
        r = o.recognition
        m.confidence = float(r.confidence) if r is not None else 0.0
        m.e1 = float(r.e1) if r is not None else float('nan')
        m.e2 = float(r.e2) if r is not None else float('nan')
        m.engaged_effectors = list(o.contacts.keys())
        m.engaged_features = list(o.contacts.values())
        self.int_pub.publish(m)

    def _sensor(self):
        return next(iter(self.users.values())).sensor if self.users else None

    def _publish_features(self) -> None:
        ctl = next(iter(self.users.values()), None)
        sensor = ctl.sensor if ctl is not None else None
        if sensor is None:
            from physics_sim.simulation import SensorPose
            sensor = SensorPose(self.cp.sensor_height, self.cp.sensor_pitch)
        shapes = world_shapes(self.world, ctl.obstacles if ctl is not None else None)
        self.mk_pub.publish(to_marker_array(shapes, 'control_features', self.frame_id,
                                            self.get_clock().now().to_msg(), sensor.to_sensor,
                                            sensor.quat_to_sensor))

    def _publish_contacts(self, stamp_ns: int) -> None:
        pts = {}
        for uid, ctl in self.users.items():
            if ctl.dp is None:
                continue
            eff = ctl.dp.effectors()
            from .features import EFFECTORS
            for e in ctl.dp.contacts:
                pts[f'{uid}/{e}'] = eff[EFFECTORS.index(e)]
        sensor = self._sensor()
        self.mk_pub.publish(to_marker_array(contact_shapes(pts), 'control_contacts',
                                            self.frame_id, ns_to_stamp(stamp_ns),
                                            sensor.to_sensor))


def main(args=None) -> int:
    return run_node(ControlNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
