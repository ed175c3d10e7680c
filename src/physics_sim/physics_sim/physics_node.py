"""``physics`` node: MuJoCo characters PD-tracking the reconstructed postures (Shum & Ho 2012).

Subscribes
  ``input_topic`` (default ``/posture/reconstructed``; ``/posture/completed`` works too) --
  skeleton_msgs/SkeletonArray: every user's skeleton becomes the target of its character.
  ``~/push`` -- geometry_msgs/WrenchStamped: ``header.frame_id = "<user_id>/<segment>"`` (segment =
  child-joint name, e.g. ``"1/Spine"``), ``wrench.force`` in N (world frame), applied for
  ``push_duration`` s.
Publishes
  ``/character/skeletons`` -- SkeletonArray at ``output_rate``: joint positions and orientations of the
  simulated bodies, in the input's frame, header stamp = the stamp of the target being tracked.
  ``/physics/objects`` -- visualization_msgs/MarkerArray: one DELETEALL then the boxes (CUBE), balls
  (SPHERE) and mace (CYLINDER handle + SPHERE head, two ids) in the input's frame, namespace
  ``physics_objects``.
  ``/diagnostics`` -- Health plus the simulation's counters and real-time factor.
Service
  ``~/apply_push`` -- skeleton_msgs/srv/ApplyPush.

The simulation runs on a timer, independent of input arrival: each tick advances it by
1/output_rate in ``timestep`` steps; the last target is kept when input stops. A user who is absent
from incoming arrays for ``user_timeout`` s of the input's time is removed (its character too); a
new user spawns a character. The input's time (:class:`skeleton_core.presence.Presence`, the same
mechanism as ``process_bag``) is the newest header stamp, running on with the wall clock while
nothing arrives: when the input stops altogether (driver killed, a gap in a bag) the characters
leave ``user_timeout`` s later instead of being published forever.
"""
from __future__ import annotations

import math
import time
from typing import Dict, List, Optional

import numpy as np
from geometry_msgs.msg import WrenchStamped
from rclpy.node import Node
from skeleton_core.cdr import CdrError, frames_from_cdr, frames_to_cdr
from skeleton_core.conversions import SkeletonFormatError, SkeletonFrame, ns_to_stamp
from skeleton_core.health import Health
from skeleton_core.model import NUM_JOINTS, TRACKED
from skeleton_core.presence import Presence
from skeleton_core.rosnode import DiagnosticsPublisher, Parameters, ParamSpec, run_node
from skeleton_msgs.msg import SkeletonArray
from skeleton_msgs.srv import ApplyPush
from visualization_msgs.msg import Marker, MarkerArray

from .controller import Gains
from .mjcf_world import ObjectSpec
from .simulation import CONTROLLERS, INTEGRATORS, SOLVERS, SimConfig, Simulation


def _tuples(n: int):
    def check(v):
        if len(v) % n:
            return f'needs groups of {n} numbers, got {len(v)}'
        a = np.asarray(list(v), float)
        if not np.all(np.isfinite(a)):
            return 'values must be finite'
        return None
    return check


def _height(v):
    return None if v == 0.0 or 1.0 <= v <= 2.3 else 'body_height must be 0 (auto) or in [1.0, 2.3] m'


# Parameters: (spec, SimConfig/Gains field it sets or None)
PARAMS: List[ParamSpec] = [
    ParamSpec('input_topic', '/posture/reconstructed', 'target postures (SkeletonArray)',
              read_only=True),
    ParamSpec('output_topic', '/character/skeletons', 'simulated skeletons (SkeletonArray)',
              read_only=True),
    ParamSpec('objects_topic', '/physics/objects',
              'environment object poses (visualization_msgs/MarkerArray)', read_only=True),
    ParamSpec('output_rate', 30.0, 'simulation tick and output rate (Hz)', range=(1.0, 240.0),
              read_only=True),
    ParamSpec('input_depth', 1,
              'input queue depth: 1 = the character always tracks the newest target (when ticks '
              'fall behind the input, stale targets are skipped, not queued); more = every '
              'target is applied, at the cost of latency under load', range=(1, 100),
              read_only=True),
    ParamSpec('timestep', 0.002, 'physics time step (s)', range=(0.0005, 0.01), read_only=True),
    ParamSpec('sync_to_input', True,
              'tick as soon as a target arrives (phase-locked to the sensor: the output leaves '
              'right after its input instead of up to one period later); the timer keeps the '
              'output rate when input is slower or stops. Each tick simulates the wall time since '
              'the previous one (0.5 to 1.5 periods)'),
    ParamSpec('controller', 'auto',
              'actuator_pd = Eq. 1-2 evaluated by MuJoCo actuators at every step (fast for few '
              'characters); explicit_pd = the papers\' external PD forces computed in Python at '
              'every step (reference; faster from ~4 characters); auto = actuator_pd below '
              'auto_explicit_from characters, explicit_pd from there; mocap_constraints = soft '
              'connect constraints to mocap targets',
              choices=CONTROLLERS, read_only=True),
    ParamSpec('auto_explicit_from', 4,
              'controller auto: explicit_pd from this many characters on (the same control law; '
              'actuator_pd grows with the square of the characters)', range=(1, 100),
              read_only=True),
    ParamSpec('integrator', 'euler',
              'MuJoCo integrator: euler = explicit like the paper (fastest; stable up to Kd ~300 '
              'N s/m, Ke ~40000 N/m at 2 ms); implicitfast treats actuator_pd\'s Kd implicitly '
              '(stable at any gain, ~35 % slower)',
              choices=INTEGRATORS, read_only=True),
    ParamSpec('solver', 'auto',
              'MuJoCo constraint solver (contacts, foot pins, holds, mocap_constraints); all '
              'converge to the same forces. auto = pgs for actuator_pd/explicit_pd (few active '
              'rows: fastest), newton for mocap_constraints (60 stiff rows a character)',
              choices=SOLVERS, read_only=True),
    ParamSpec('implicit_joint_damping', False,
              'euler: integrate the ball joints\' damping implicitly (MuJoCo\'s default, ~6 us more '
              'a step); false = explicitly like the other forces, used only while timestep * '
              'joint_damping <= joint_armature / 4 (implicit otherwise)', read_only=True),
    ParamSpec('slow_control_every', 0,
              'physics steps between Python control updates (Eq. 2 twist targets, foot pins; '
              'actuator_pd and mocap_constraints targets); 0 = auto (4 for explicit_pd, one per '
              'tick otherwise)', range=(0, 50), read_only=True),
    ParamSpec('kp', 4000.0, 'Ke of Eq. 1 (N/m), shared by all joints', range=(0.0, 1e6)),
    ParamSpec('kd', 100.0, 'Kd of Eq. 1 (N s/m), shared by all joints', range=(0.0, 1e4)),
    ParamSpec('velocity_smoothing', 0.7, "exponential smoothing of the target velocity p'_target "
              '(frame differences) of Eq. 1; 0 = raw differences (more jitter)', range=(0.0, 0.95)),
    ParamSpec('max_force', 800.0, 'bound on |F| of Eq. 1 (N)', range=(0.0, 1e5)),
    ParamSpec('twist_kp', 400.0,
              'Eq. 2 elasticity per unit axial inertia (1/s^2): Ke_i = twist_kp * I_i',
              range=(0.0, 1e5)),
    ParamSpec('twist_kd', 40.0, 'Eq. 2 damping per unit axial inertia (1/s): Kd_i = twist_kd * I_i',
              range=(0.0, 1e4)),
    ParamSpec('twist_scale', [1.0] * 19,
              'per-segment factor on the Eq. 2 gains (19 values, skeleton_core.model.SEGMENTS '
              'order); the gains are Ke_i = twist_kp * scale_i * I_i', read_only=True,
              validator=lambda v: None if len(v) == 19 and all(
                  math.isfinite(x) and x >= 0 for x in v) else 'twist_scale needs 19 values >= 0'),
    ParamSpec('max_torque', 50.0, 'bound on |T| of Eq. 2 (N m)', range=(0.0, 1e4)),
    ParamSpec('track_timeconst', 0.02, 'mocap_constraints: spring time constant (s)',
              range=(0.001, 1.0), read_only=True),
    ParamSpec('track_dampratio', 1.0, 'mocap_constraints: damping ratio', range=(0.1, 10.0),
              read_only=True),
    ParamSpec('track_impedance', 0.9, 'mocap_constraints: solimp impedance d (share of the '
              'constraint force kept; lower = softer, more push response)', range=(0.01, 0.99),
              read_only=True),
    ParamSpec('body_height', 0.0, 'character height (m); 0 = estimated from the first target',
              validator=_height, read_only=True),
    ParamSpec('body_mass', 75.0, 'character mass at 1.75 m (kg), scaled with height^3',
              range=(20.0, 200.0), read_only=True),
    ParamSpec('retarget', True, 'retarget targets to the character (Shum & Ho 2012 Eq. 3-4)'),
    ParamSpec('joint_damping', 2.0, 'ball joint damping (N m s/rad)', range=(0.0, 100.0),
              read_only=True),
    ParamSpec('joint_armature', 0.02, 'ball joint armature (kg m^2)', range=(0.0, 10.0),
              read_only=True),
    ParamSpec('sensor_height', 0.8, 'sensor height above the floor (m)', range=(0.0, 3.0),
              read_only=True),
    ParamSpec('sensor_pitch_deg', 0.0, 'sensor tilt, positive = down (deg)', range=(-45.0, 45.0),
              read_only=True),
    ParamSpec('auto_floor', False, 'put the floor under the lowest foot of the first target '
              '(overrides sensor_height)', read_only=True),
    ParamSpec('pin_feet', True, 'virtual joints pinning supporting feet to the floor'),
    ParamSpec('pin_height', 0.04, 'pin a foot whose target is lower than this above its rest '
              'height (m)', range=(0.0, 0.5)),
    ParamSpec('pin_release_height', 0.07, 'release when the target rises above this (m)',
              range=(0.0, 0.5)),
    ParamSpec('pin_speed', 0.3, 'pin only if the foot target is slower than this (m/s)',
              range=(0.0, 10.0)),
    ParamSpec('pin_release_distance', 0.15, 'release when the target slides this far (m)',
              range=(0.01, 2.0)),
    ParamSpec('pin_max_force', 3000.0, 'a foot pin pulling harder than this (N) conflicts with '
              'the targets and is released (counted)', range=(100.0, 1e5)),
    ParamSpec('dodge', False, 'raise the forearms when a ball approaches the head'),
    ParamSpec('dodge_distance', 0.45, 'predicted miss distance that triggers a dodge (m)',
              range=(0.05, 3.0)),
    ParamSpec('user_timeout', 1.0, 'remove a character whose user is absent this long (s)',
              range=(0.05, 60.0)),
    ParamSpec('max_characters', 6, 'most characters at once', range=(1, 30), read_only=True),
    ParamSpec('boxes', [0.0], 'boxes: x y z half_x half_y half_z mass per box (world, m, kg); '
              '[0.0] = none', validator=lambda v: None if list(v) == [0.0] else _tuples(7)(v),
              read_only=True),
    ParamSpec('balls', [0.0], 'balls: x y z radius mass per ball (world); [0.0] = none',
              validator=lambda v: None if list(v) == [0.0] else _tuples(5)(v), read_only=True),
    ParamSpec('mace', False, 'give the first character a mace (held with a virtual joint)',
              read_only=True),
    ParamSpec('mace_hand', 'right', 'hand holding the mace', choices=('left', 'right'),
              read_only=True),
    ParamSpec('auto_throw_period', 0.0, 'throw a ball at the first character\'s head every N s '
              '(0 = off)', range=(0.0, 600.0)),
    ParamSpec('push_duration', 0.1, 'duration of pushes from the ~/push topic (s)',
              range=(0.001, 5.0)),
    ParamSpec('frame_id', 'kinect', 'frame of the outputs until an input arrives', read_only=True),
]

LIVE_GAINS = {'kp': 'ke', 'kd': 'kd', 'max_force': 'max_force', 'twist_kp': 'twist_ke',
              'twist_kd': 'twist_kd', 'max_torque': 'max_torque'}
LIVE_CONFIG = ('velocity_smoothing', 'retarget', 'pin_feet', 'pin_height', 'pin_release_height', 'pin_speed',
               'pin_release_distance', 'pin_max_force', 'dodge', 'dodge_distance')


def config_from_params(v: Dict) -> SimConfig:
    gains = Gains(ke=v['kp'], kd=v['kd'], max_force=v['max_force'], twist_ke=v['twist_kp'],
                  twist_kd=v['twist_kd'], max_torque=v['max_torque'])
    return SimConfig(timestep=v['timestep'], controller=v['controller'], gains=gains,
                     integrator=v['integrator'], solver=v['solver'],
                     implicit_joint_damping=v['implicit_joint_damping'],
                     slow_control_every=v['slow_control_every'],
                     auto_explicit_from=v['auto_explicit_from'],
                     track_timeconst=v['track_timeconst'], track_dampratio=v['track_dampratio'],
                     track_impedance=v['track_impedance'],
                     velocity_smoothing=v['velocity_smoothing'],
                     twist_scale=list(v['twist_scale']),
                     body_height=v['body_height'], body_mass=v['body_mass'],
                     retarget=v['retarget'], joint_damping=v['joint_damping'],
                     joint_armature=v['joint_armature'], sensor_height=v['sensor_height'],
                     sensor_pitch=math.radians(v['sensor_pitch_deg']), auto_floor=v['auto_floor'],
                     pin_feet=v['pin_feet'], pin_height=v['pin_height'],
                     pin_release_height=v['pin_release_height'], pin_speed=v['pin_speed'],
                     pin_release_distance=v['pin_release_distance'],
                     pin_max_force=v['pin_max_force'], dodge=v['dodge'],
                     dodge_distance=v['dodge_distance'], max_characters=v['max_characters'])


def objects_from_params(v: Dict) -> List[ObjectSpec]:
    objs = []
    boxes = [] if list(v['boxes']) == [0.0] else list(v['boxes'])
    for i in range(0, len(boxes), 7):
        x, y, z, hx, hy, hz, m = boxes[i:i + 7]
        objs.append(ObjectSpec(f'box{i // 7}', 'box', (x, y, z), (hx, hy, hz), m))
    balls = [] if list(v['balls']) == [0.0] else list(v['balls'])
    for i in range(0, len(balls), 5):
        x, y, z, r, m = balls[i:i + 5]
        objs.append(ObjectSpec(f'ball{i // 5}', 'ball', (x, y, z), (r,), m,
                               rgba=(0.9, 0.6, 0.2, 1.0)))
    if v['mace']:
        objs.append(ObjectSpec('mace', 'mace', (0.0, 0.0, 0.3), (0.3, 0.06), 2.0,
                               rgba=(0.5, 0.5, 0.55, 1.0)))
    return objs


class PhysicsNode(Node):
    """Thin adapter: SkeletonArray targets -> :class:`Simulation` -> SkeletonArray + markers."""

    def __init__(self, **kwargs):
        super().__init__('physics', **kwargs)
        self.health = Health()
        self.params = Parameters(self, PARAMS, on_change=self._on_params)
        v = self.params.values
        try:
            self.sim = Simulation(config_from_params(v), objects_from_params(v))
        except ValueError as e:
            raise ValueError(f'physics: {e}') from e
        self.frame_id = v['frame_id']
        self.presence = Presence(v['user_timeout'])
        self._user_stamp: Dict[int, int] = {}   # stamp of each user's newest target
        self._published_empty = True
        self._mace_given = False
        self._next_throw = None
        self._wall_in_step = 0.0
        self._sim_in_step = 0.0
        self._last_tick: Optional[float] = None
        self._last_input_tick: Optional[float] = None
        self._time_debt = 0.0
        self.pub = self.create_publisher(SkeletonArray, v['output_topic'], 10)
        self.obj_pub = self.create_publisher(MarkerArray, v['objects_topic'], 10)
        # serialized in and out (skeleton_core.cdr): no rclpy message objects per joint
        self.create_subscription(SkeletonArray, v['input_topic'], self._on_input,
                                 v['input_depth'], raw=True)
        self.create_subscription(WrenchStamped, '~/push', self._on_push_topic, 10)
        self.create_service(ApplyPush, '~/apply_push', self._on_push_srv)
        self.timer = self.create_timer(1.0 / v['output_rate'], self._on_timer)
        self.diag = DiagnosticsPublisher(self, self.health, extra=self._diag_extra)
        self.get_logger().info(
            f'physics: {v["controller"]} at {v["timestep"] * 1000:.1f} ms, input {v["input_topic"]}'
            f' -> {v["output_topic"]}, {len(self.sim.objects)} objects')

    # ------------------------------------------------------------------ parameters
    def _on_params(self, changed: Dict) -> Optional[str]:
        if 'pin_height' in changed or 'pin_release_height' in changed:
            lo = changed.get('pin_height', self.params.values['pin_height'])
            hi = changed.get('pin_release_height', self.params.values['pin_release_height'])
            if hi < lo:
                return 'pin_release_height must be >= pin_height'
        for k, val in changed.items():
            if k in LIVE_GAINS:
                setattr(self.sim.config.gains, LIVE_GAINS[k], float(val))
            elif k in LIVE_CONFIG:
                setattr(self.sim.config, k, val)
        return None

    def _diag_extra(self) -> Dict:
        out = {f'sim_{k}': v for k, v in self.sim.counters.items()}
        out['characters'] = len(self.sim.characters)
        out['objects'] = len(self.sim.objects)
        if self._wall_in_step > 0:
            out['real_time_factor'] = self._sim_in_step / self._wall_in_step
        return out

    # ------------------------------------------------------------------ input
    def _drop(self, cause: str, detail: str) -> None:
        if self.health.on_drop(cause):
            self.get_logger().warning(f'dropping input ({cause}): {detail} (logged once per cause)')

    def _on_input(self, data: bytes) -> None:
        self.health.on_receive()
        errors: list = []
        try:
            header_stamp, header_frame, frames = frames_from_cdr(data, errors)
        except CdrError as e:
            self._drop('malformed message', str(e))
            return
        for e in errors:
            cause = getattr(e, 'cause', 'malformed')
            self._drop(cause, str(e))
        now = time.monotonic()
        if header_frame:
            self.frame_id = header_frame
        self.presence.observe(header_stamp, (), wall=now)   # the input's clock moves on:
        self._expire(now)                                   # who left before this message?
        for f in frames:
            stamp = f.stamp_ns or header_stamp
            last = self._user_stamp.get(f.user_id)
            if stamp and last is not None and last - 1_000_000_000 <= stamp <= last:
                # a target already applied, or an older one (a bigger step back is a bag loop or
                # a restarted sensor: taken)
                self._drop('duplicate stamp' if stamp == last else 'out-of-order stamp',
                           f'user {f.user_id}: {(last - stamp) * 1e-6:.1f} ms back')
                continue
            try:
                self.sim.set_target(f.user_id, f.positions, f.orientations, stamp)
                self._user_stamp[f.user_id] = stamp
            except (SkeletonFormatError, ValueError) as e:
                if 'max_characters' in str(e):   # counted per reason, logged once
                    self._drop(f'too many users (max_characters '
                               f'{self.sim.config.max_characters})',
                               f'user {f.user_id} gets no character while {e}')
                else:
                    self._drop('bad target', str(e))
        self.presence.observe(header_stamp, [f.user_id for f in frames], wall=now)
        if self.params['mace'] and not self._mace_given and self.sim.characters:
            uid = next(iter(self.sim.characters))
            self.sim.hold(uid, 'mace', self.params['mace_hand'])
            self._mace_given = True
        if self.params['sync_to_input'] and frames:
            # phase-lock to the sensor: tick now unless the last input tick was recent (input
            # faster than the output rate: that frame rides on the next tick); the timer only
            # ticks when no input ticked for a period (see _on_timer)
            period = 1.0 / self.params['output_rate']
            if self._last_input_tick is None or now - self._last_input_tick >= 0.75 * period:
                self._last_input_tick = now
                self._tick()

    def _expire(self, wall: float) -> None:
        """Remove the characters of users unseen for ``user_timeout`` s of the input's time."""
        self.presence.timeout_s = self.params['user_timeout']
        for uid in self.presence.expired(wall=wall):
            self._user_stamp.pop(uid, None)
            if self.sim.remove_character(uid):
                self.get_logger().info(f'user {uid} left: character removed')

    def _push(self, user_id: int, segment: str, force, duration: float) -> str:
        try:
            self.sim.apply_push(user_id, segment, force, duration)
        except ValueError as e:
            return str(e)
        return ''

    def _on_push_topic(self, msg: WrenchStamped) -> None:
        uid, _, seg = msg.header.frame_id.partition('/')
        f = msg.wrench.force
        try:
            uid_i = int(uid)
        except ValueError:
            self._drop('bad push', f'frame_id must be "<user_id>/<segment>", got {msg.header.frame_id!r}')
            return
        err = self._push(uid_i, seg, (f.x, f.y, f.z), self.params['push_duration'])
        if err:
            self._drop('bad push', err)

    def _on_push_srv(self, req, resp):
        f = req.force
        err = self._push(int(req.user_id), req.segment, (f.x, f.y, f.z), float(req.duration))
        resp.success = not err
        resp.message = err or (f'pushing user {req.user_id} {req.segment} with '
                               f'({f.x:.1f}, {f.y:.1f}, {f.z:.1f}) N for {req.duration:.3f} s')
        return resp

    # ------------------------------------------------------------------ simulation tick
    def _on_timer(self) -> None:
        if (self.params['sync_to_input'] and self._last_input_tick is not None
                and time.monotonic() - self._last_input_tick < 1.0 / self.params['output_rate']):
            return   # input is flowing and ticking: the timer is the fallback when it stops
        self._tick()

    def _tick(self) -> None:
        now = time.monotonic()
        period = 1.0 / self.params['output_rate']
        if self.params['sync_to_input'] and self._last_tick is not None:
            # the wall time since the last tick, bounded: an overloaded machine gets a slower
            # simulation at a kept output rate, not ever longer (costlier) ticks
            dt = min(max(now - self._last_tick, 0.5 * period), 1.5 * period)
        else:
            dt = period
        self._last_tick = now
        self._expire(now)
        throw = self.params['auto_throw_period']
        if throw > 0 and self.sim.characters:
            if self._next_throw is None or now >= self._next_throw:
                if self._next_throw is not None:
                    self.sim.throw_at(next(iter(self.sim.characters)))
                    self._prune_thrown()
                self._next_throw = now + throw
        # whole physics steps; the remainder is carried to the next tick (sim time = wall time)
        ts = self.params['timestep']
        self._time_debt += dt
        steps = int(self._time_debt / ts + 1e-9)
        if steps:
            self._time_debt -= steps * ts
            t0 = time.perf_counter()
            self.sim.advance(steps * ts)
            self._wall_in_step = 0.9 * self._wall_in_step + 0.1 * (time.perf_counter() - t0)
            self._sim_in_step = 0.9 * self._sim_in_step + 0.1 * steps * ts
        self._publish()

    def _prune_thrown(self, keep: int = 8) -> None:
        thrown = [o.name for o in self.sim.objects if o.name.startswith('thrown')]
        for name in thrown[:-keep]:
            self.sim.remove_object(name)

    def _publish(self) -> None:
        states = self.sim.states()
        if not states and self._published_empty:
            self._publish_objects(None)
            return
        frames = []
        latest = 0
        for uid, st in states.items():
            frames.append(SkeletonFrame(
                positions=st.positions_sensor, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                reliability=np.ones(NUM_JOINTS, np.float32), orientations=st.orientations_sensor,
                user_id=uid, stamp_ns=st.stamp_ns, frame_id=self.frame_id))
            latest = max(latest, st.stamp_ns)
        self.pub.publish(frames_to_cdr(frames, latest, self.frame_id))
        self._published_empty = not frames
        lat = None
        if latest:
            lat = self.get_clock().now().nanoseconds * 1e-9 - latest * 1e-9
            lat = lat if 0 <= lat < 60 else None
        self.health.on_publish(lat)
        self._publish_objects(latest)

    def _publish_objects(self, stamp_ns: Optional[int]) -> None:
        if not self.sim.objects:
            return
        sensor = self.sim.sensor
        out = MarkerArray()
        clear = Marker()
        clear.action = Marker.DELETEALL
        clear.ns = 'physics_objects'
        out.markers.append(clear)
        stamp = self.get_clock().now().to_msg() if not stamp_ns else ns_to_stamp(stamp_ns)
        mid = 0
        for name, (pos, quat, spec) in self.sim.object_poses().items():
            if sensor is not None:
                pos = sensor.to_sensor(pos)
                quat = sensor.quat_to_sensor(quat)
            parts = []
            if spec.kind == 'box':
                parts.append((Marker.CUBE, np.zeros(3), 2 * np.asarray(spec.size), spec.rgba))
            elif spec.kind == 'ball':
                parts.append((Marker.SPHERE, np.zeros(3), np.full(3, 2 * spec.size[0]), spec.rgba))
            else:
                half, rh = spec.size
                parts.append((Marker.CYLINDER, np.zeros(3), np.array([0.03, 0.03, 2 * half]),
                              (0.4, 0.3, 0.2, 1.0)))
                parts.append((Marker.SPHERE, np.array([0.0, 0.0, half]), np.full(3, 2 * rh),
                              spec.rgba))
            from skeleton_core.geometry import quat_rotate
            for mtype, local, scale, rgba in parts:
                m = Marker()
                m.header.frame_id = self.frame_id
                m.header.stamp = stamp
                m.ns = 'physics_objects'
                m.id = mid
                mid += 1
                m.type = mtype
                m.action = Marker.ADD
                p = pos + quat_rotate(quat, local)
                m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(x) for x in p)
                (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
                 m.pose.orientation.w) = (float(x) for x in quat)
                m.scale.x, m.scale.y, m.scale.z = (float(x) for x in scale)
                m.color.r, m.color.g, m.color.b, m.color.a = (float(x) for x in rgba)
                m.text = name
                out.markers.append(m)
        self.obj_pub.publish(out)


def main(args=None) -> int:
    return run_node(PhysicsNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
