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

import time
from dataclasses import dataclass
from typing import Dict, List

import numpy as np
from skeleton_core.cdr import frames_to_cdr
from skeleton_core.conversions import SkeletonFrame, ns_to_stamp
from skeleton_core.model import NUM_JOINTS, TRACKED
from skeleton_core.params import ParamSpec, assign, build, param, specs
from skeleton_core.rosnode import InputDrops, ManagedNode, Parameters, run_node
from skeleton_msgs.msg import Intention, SkeletonArray
from visualization_msgs.msg import MarkerArray

from .controller import ControlParams, PerformanceController, build_models
from .features import WorldError, load_world
from .markers import contact_shapes, to_marker_array, world_shapes


@dataclass
class ControlNodeConfig:
    """The control node's own parameters (the controller's are ControlParams')."""

    world: str = param('playground', 'feature world: a name in config/worlds or a YAML path',
                       read_only=True)
    start_feature: str = param('', "feature a new character starts on ('' = the world's spawn on "
                               'the floor; e.g. monkey_bars: hanging from the nearest bar)',
                               read_only=True)
    input_topic: str = param('/posture/reconstructed', 'performances (SkeletonArray)',
                             read_only=True)
    output_topic: str = param('/control/target', 'composed poses for the physics (SkeletonArray)',
                              read_only=True)
    intention_topic: str = param('/control/intention', 'skeleton_msgs/Intention', read_only=True)
    markers_topic: str = param('/control/markers', 'features and contacts (MarkerArray)',
                               read_only=True)
    user_timeout_s: float = param(2.0, 'drop the controller of a user unseen this long (s)',
                                  range=(0.1, 60.0))
    max_users: int = param(6, 'users controlled at once (more are ignored)', range=(1, 30),
                           read_only=True)


CONTROL_PARAMS = specs(ControlParams)
PARAMS: List[ParamSpec] = specs(ControlNodeConfig) + CONTROL_PARAMS
LIVE = {s.name: s for s in CONTROL_PARAMS if not s.read_only}


class ControlNode(ManagedNode):
    """Thin adapter: SkeletonArray -> :class:`PerformanceController` per user -> SkeletonArray,
    Intention and markers. Configure reads the world file; activate starts the input."""

    def __init__(self, **kwargs):
        super().__init__('control', **kwargs)
        self._drop = InputDrops(self.health, self.get_logger())
        self.world = None
        self.cp = None
        self.users: Dict[int, PerformanceController] = {}
        self.last_seen: Dict[int, float] = {}
        self.params = Parameters(self, PARAMS, apply=self._apply_change)

    def configure(self) -> None:
        v = self.params.values
        try:
            self.world = load_world(v['world'])
        except (WorldError, FileNotFoundError) as e:
            raise ValueError(f'control: {e}') from None
        if v['start_feature'] and v['start_feature'] not in self.world.features:
            raise ValueError(f'control: start_feature {v["start_feature"]!r} is not in world '
                             f'{self.world.name} ({sorted(self.world.features)})')
        self.cp = build(ControlParams, v)
        self.rp = self.cp.recognizer          # shared by every user's controller: live changes
        self.cp.validate()
        self.models = build_models(self.world, self.rp)
        # the compiled kernel loaded now, not on a user's first control step (numba's cache:
        # 0.5 s on a quiet machine, seconds under load)
        from .composition import warm_up
        warm_s = warm_up()
        if warm_s > 0.5:
            self.get_logger().info(f'compiled kernels ready in {warm_s:.1f} s (cached from now on)')
        self.frame_id = 'kinect'
        self.ms: List[float] = []
        self.pub = self.publisher(SkeletonArray, v['output_topic'], 10)
        self.int_pub = self.publisher(Intention, v['intention_topic'], 10)
        self.mk_pub = self.publisher(MarkerArray, v['markers_topic'], 10)
        self.diagnostics(extra=self._diag)

    def activate(self) -> None:
        v = self.params.values
        self.subscription(SkeletonArray, v['input_topic'], self._on_input, 1, raw=True,
                          watch=True)   # a stream: told when matched but silent
        self.timer(1.0, self._publish_features)
        self.get_logger().info(
            f'control: world {self.world.name} ({", ".join(self.world.features)}), '
            f'{v["input_topic"]} -> {v["output_topic"]}')

    def deactivate(self) -> None:
        self.users.clear()
        self.last_seen.clear()

    def cleanup(self) -> None:
        self.world = self.cp = self.models = None

    def _apply_change(self, changed: Dict) -> None:
        if self.cp is None:
            return   # configure reads the values
        for k, val in changed.items():
            if k in LIVE:
                assign(self.cp, LIVE[k], val)

    def _diag(self) -> Dict:
        out = {'users': len(self.users), 'world': self.world.name}
        if self.ms:
            out['control_ms_median'] = float(np.median(self.ms[-300:]))
        return out

    def _on_input(self, data: bytes) -> None:
        self.health.on_receive()
        decoded = self._drop.decode(data)
        if decoded is None:
            return
        stamp, frame, frames = decoded
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
                o = ctl.step(f.positions, st * 1e-9, f.tracking_state)
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
        timeout = self.params['user_timeout_s']
        for uid in [u for u, t in self.last_seen.items() if now - t > timeout]:
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
