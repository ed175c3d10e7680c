"""``physics`` node: MuJoCo characters PD-tracking the reconstructed postures (Shum & Ho 2012).

Subscribes
  ``input_topic`` (default ``/posture/reconstructed``; ``/posture/completed`` works too) --
  skeleton_msgs/SkeletonArray: every user's skeleton becomes the target of its character.
  ``~/push`` -- geometry_msgs/WrenchStamped: ``header.frame_id = "<user_id>/<segment>"`` (segment =
  child-joint name, e.g. ``"1/Spine"``), ``wrench.force`` in N (world frame), applied for
  ``push_duration`` s.
Publishes
  ``/character/skeletons`` -- SkeletonArray at ``output_rate``: joint positions and orientations of the
  simulated bodies in ``world`` (floor at z = 0), header stamp = the stamp of the target being
  tracked.
  ``/physics/objects`` -- visualization_msgs/MarkerArray: one DELETEALL then the boxes (CUBE), balls
  (SPHERE) and mace (CYLINDER handle + SPHERE head, two ids) in ``world``, namespace
  ``physics_objects``.
  ``/character/joint_states`` -- sensor_msgs/JointState of every character (its MuJoCo ball joints
  as three revolute joints each, ``u<id>_ball_<Joint>_{z,y,x}``; only while subscribed), with each
  root on ``/tf``
  (``world -> u<id>_seg_Spine``) and each character's URDF latched on
  ``/character/u<id>/robot_description`` (std_msgs/String; :mod:`physics_sim.character_urdf`).
  ``/tf_static`` (subscribed) -- the input frame's pose in ``world`` (``world -> kinect_link``,
  published by the launch files' ``static_tf``): targets are moved to the world with it; targets
  whose frame TF does not know yet are held (the newest second of them) and taken when it does,
  older ones dropped (counted as ``no transform``, logged once).
  ``/diagnostics`` -- Health plus the simulation's counters and real-time factor.
Service
  ``~/apply_push`` -- skeleton_msgs/srv/ApplyPush.

The simulation runs on a timer, independent of input arrival: each tick advances it by
1/output_rate in ``timestep`` steps; the last target is kept when input stops. A user who is absent
from incoming arrays for ``user_timeout_s`` s of the input's time is removed (its character too);
a new user spawns a character. The input's time (:class:`skeleton_core.presence.Presence`, the
same mechanism as ``process_bag``) is the newest header stamp, running on with the wall clock
while nothing arrives: when the input stops altogether (driver killed, a gap in a bag) the
characters leave ``user_timeout_s`` later instead of being published forever.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Dict, List, Optional

import numpy as np
from geometry_msgs.msg import WrenchStamped
from skeleton_core.cdr import frames_to_cdr
from skeleton_core.conversions import ns_to_stamp
from skeleton_core.params import ParamSpec, assign, build, param, specs
from skeleton_core.presence import Presence
from skeleton_core.rosnode import InputDrops, ManagedNode, Parameters, fill_marker, run_node
from skeleton_core.tf import WORLD_FRAME, HeldUntilTf, TfBuffer, Transform
from skeleton_core.tf_ros import STATIC_BROADCASTER_QOS, StaticTfListener, to_tf_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, String
from skeleton_msgs.msg import Intention, SkeletonArray
from skeleton_msgs.srv import ApplyPush
from visualization_msgs.msg import Marker, MarkerArray

from .character_urdf import CharacterRobots, description_topic
from .mjcf_world import ObjectSpec
from .output import output_frames
from .scheduler import TickScheduler
from .simulation import SimConfig, Simulation, warm_up


def _tuples(n: int):
    def check(v):
        if len(v) % n:
            return f'needs groups of {n} numbers, got {len(v)}'
        a = np.asarray(list(v), float)
        if not np.all(np.isfinite(a)):
            return 'values must be finite'
        return None
    return check


def _objects(n: int):
    def check(v):
        return None if list(v) == [0.0] else _tuples(n)(v)
    return check


@dataclass
class PhysicsNodeConfig:
    """The physics node's own parameters (the simulation's are SimConfig's)."""

    input_topic: str = param('/posture/reconstructed', 'target postures (SkeletonArray)',
                             read_only=True)
    output_topic: str = param('/character/skeletons', 'simulated skeletons (SkeletonArray)',
                              read_only=True)
    objects_topic: str = param('/physics/objects', 'environment object poses '
                               '(visualization_msgs/MarkerArray)', read_only=True)
    output_rate: float = param(30.0, 'simulation tick and output rate (Hz)', range=(1.0, 240.0),
                               read_only=True)
    input_depth: int = param(
        3, 'input queue depth: the targets that bunched up behind a stall (a loaded machine) are '
        'each simulated for their own frame time and published, up to this many (3: a stall of '
        '3 frames loses none; each costs its own steps plus a tick\'s publish, see docs/physics.md); '
        'when ticks fall behind for good, the character lags its input by '
        'at most this many frames. 1 = only the newest waiting target is taken (stale ones '
        'skipped)', range=(1, 100), read_only=True, public=False)
    sync_to_input: bool = param(
        True, 'tick as soon as a target arrives (phase-locked to the sensor: the output leaves '
        'right after its input instead of up to one period later); the timer keeps the output '
        'rate when input is slower or stops. An input tick simulates the frame time since the '
        'previous one (capture stamps; 0.5 to 1.5 periods), a timer tick the wall time: frames '
        'delivered together after a delay tick each; a target sooner than 0.75 period after '
        'the last by its stamp is simulated 0.75 period after it', public=False)
    user_timeout_s: float = param(1.0, "remove a character whose user is absent this long (s) "
                                  "of the input's time (running on while nothing arrives)",
                                  range=(0.05, 60.0))
    boxes: List[float] = param([0.0], 'boxes: x y z half_x half_y half_z mass per box (world, '
                               'm, kg); [0.0] = none', validator=_objects(7), read_only=True)
    balls: List[float] = param([0.0], 'balls: x y z radius mass per ball (world); [0.0] = none',
                               validator=_objects(5), read_only=True)
    mace: bool = param(False, 'give the first character a mace (held with a virtual joint)',
                       read_only=True)
    mace_hand: str = param('right', 'hand holding the mace', choices=('left', 'right'),
                           read_only=True)
    push_duration: float = param(0.1, 'duration of pushes from the ~/push topic (s)',
                                 range=(0.001, 5.0), public=False)
    wait_for_frames: List[str] = param(
        [''], 'sensor frames whose pose in world (/tf_static) the node waits for before it takes '
        'input, at most 10 s (set by the launch files that publish them: the first targets are '
        'moved to world at once, none held); [""] = none', read_only=True)
    intention_topic: str = param('/control/intention', 'with feature_world: the control '
                                 "node's engaged effectors (skeleton_msgs/Intention), whose hands "
                                 'grip the features', read_only=True)


# the longest the activation waits for the frames of wait_for_frames on TF (then it takes input,
# held until TF has its frame, with a warning)
TF_WAIT_S = 10.0

# the node's parameters: its own and every SimConfig field (declared there, with its ROS name)
SIM_PARAMS = specs(SimConfig)
PARAMS: List[ParamSpec] = specs(PhysicsNodeConfig) + SIM_PARAMS
# what may change while the simulation runs (the others are read-only: fixed in the built world)
LIVE_PARAMS = {s.name: s for s in SIM_PARAMS if not s.read_only}


def config_from_params(v: Dict) -> SimConfig:
    return build(SimConfig, v)


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


class PhysicsNode(ManagedNode):
    """Thin adapter: SkeletonArray targets -> :class:`Simulation` -> SkeletonArray + markers.
    Configure builds the simulation (world, objects, compiled kernels); activate starts the
    input, the pushes and the tick timer."""

    def __init__(self, **kwargs):
        super().__init__('physics', **kwargs)
        self._drop = InputDrops(self.health, self.get_logger())
        self.sim: Optional[Simulation] = None
        # the one-shot tick of a frame that arrived too soon after a tick: one timer made at
        # activate and re-armed (period + reset), never a timer per frame (rclpy keeps a weak
        # reference per timer ever made in the callback group: a slow leak at 30 Hz)
        self._deferred = None
        self._deferred_armed = False
        self._urdf_pubs: Dict[int, object] = {}   # each character's latched URDF
        self.params = Parameters(self, PARAMS, validate=self._validate_change,
                                 apply=self._apply_change)

    # ------------------------------------------------------------------ lifecycle
    def configure(self) -> None:
        v = self.params.values
        try:
            self.sim = Simulation(config_from_params(v), objects_from_params(v))
        except ValueError as e:
            raise ValueError(f'physics: {e}') from e
        # frames on TF: the targets' frame (the sensor's) -> world from /tf_static; the
        # characters are published in world
        self.tf = TfBuffer()
        self._held = HeldUntilTf(limit=max(1, int(round(v['output_rate']))))   # 1 s of input
        self.tf_listener = StaticTfListener(self, self.tf, on_change=self._release_held)
        self._pose_key = None   # (input frame, TF version) of the sensor pose in use
        self.presence = Presence(v['user_timeout_s'])
        self.scheduler = TickScheduler(v['output_rate'], v['sync_to_input'])
        self._user_stamp: Dict[int, int] = {}   # stamp of each user's newest target
        self._published_empty = True
        self._mace_given = False
        self._wall_in_step = 0.0
        self._sim_in_step = 0.0
        # CPU (this thread's) in the ticks and in their physics steps, and in taking targets (s)
        self._cpu = {'tick': 0.0, 'step': 0.0, 'input': 0.0}
        self._inputs_taken = 0
        self.pub = self.publisher(SkeletonArray, v['output_topic'], 10)
        self.obj_pub = self.publisher(MarkerArray, v['objects_topic'], 10)
        self._robots = CharacterRobots()
        self._js_pub = self.publisher(JointState, '/character/joint_states', 10)
        try:
            from tf2_msgs.msg import TFMessage
            self._tf_pub = self.publisher(TFMessage, '/tf', 100)
        except ImportError:   # (every supported install has it: the launch tooling builds it)
            self._tf_pub = None
        # compiled kernels now, not on the first frame; last: DDS matches the publishers and
        # the /tf_static subscription made above meanwhile (the graph's start waits for it)
        warm_s = warm_up()
        if warm_s > 0.5:
            self.get_logger().info(f'compiled kernels ready in {warm_s:.1f} s (cached from now on)')
        self.diagnostics(extra=self._diag_extra)

    def activate(self) -> None:
        # the input only once TF has the sensor frames the launch publishes (wait_for_frames;
        # at most TF_WAIT_S): the first targets are then moved to world at once, not held and
        # released together later (the graph's start activates the driver after this node)
        frames = [f.lstrip('/') for f in self.params['wait_for_frames'] if f]
        self.when_ready(lambda: self.tf_listener.missing(frames, WORLD_FRAME), self._start_input,
                        TF_WAIT_S, f'no pose in {WORLD_FRAME} on TF; taking the input anyway '
                        '(held until TF has it)')

    def _start_input(self) -> None:
        v = self.params.values
        self.scheduler.reset()
        # serialized in and out (skeleton_core.cdr): no rclpy message objects per joint
        self.subscription(SkeletonArray, v['input_topic'], self._on_input, v['input_depth'],
                          raw=True, watch=True)   # a stream: told when matched but silent
        self.subscription(WrenchStamped, '~/push', self._on_push_topic, 10)
        if v['feature_world']:
            self.subscription(Intention, v['intention_topic'], self._on_intention, 10)
        self.service(ApplyPush, '~/apply_push', self._on_push_srv)
        self.tick_timer = self.timer(1.0 / v['output_rate'], self._on_timer)
        self._deferred = self.timer(1.0 / v['output_rate'], self._on_deferred)
        self._deferred.cancel()
        self._deferred_armed = False
        self.get_logger().info(
            f'physics: {v["controller"]} at {v["timestep"] * 1000:.1f} ms, input {v["input_topic"]}'
            f' -> {v["output_topic"]}, {len(self.sim.objects)} objects'
            + (f', features of {v["feature_world"]} ({", ".join(self.sim.shared.features)}),'
               f' grips from {v["intention_topic"]}' if v['feature_world'] else ''))

    def deactivate(self) -> None:
        self._held.take()   # input held for TF is not replayed after a restart
        self._cancel_deferred()
        self._deferred = None   # (destroyed with the other timers of the active state)

    def cleanup(self) -> None:
        self.sim = None
        for pub in self._urdf_pubs.values():
            self.destroy_publisher(pub)
        self._urdf_pubs = {}

    # ------------------------------------------------------------------ parameters
    def _validate_change(self, values: Dict, changed: Dict) -> Optional[str]:
        if values['pin_release_height'] < values['pin_height']:
            return 'pin_release_height must be >= pin_height'
        return None

    def _apply_change(self, changed: Dict) -> None:
        if self.sim is None:
            return   # configure reads the values
        for k, val in changed.items():
            if k in LIVE_PARAMS:
                assign(self.sim.config, LIVE_PARAMS[k], val)

    def _diag_extra(self) -> Dict:
        out = {f'sim_{k}': v for k, v in self.sim.counters.items()}
        out['characters'] = len(self.sim.characters)
        out['objects'] = len(self.sim.objects)
        out['worlds'] = len(self.sim.worlds)
        out['user_states'] = len(self._user_ids())
        if self._wall_in_step > 0:
            out['real_time_factor'] = self._sim_in_step / self._wall_in_step
        # ticks by kind (physics_sim.scheduler) with the time they simulated, and the CPU per
        # tick beside its steps (decoding, publishing: what each extra tick costs)
        sched = self.scheduler
        for kind, n in sched.ticks.items():
            out[f'ticks_{kind}'] = n
            out[f'simulated_s_{kind}'] = round(sched.simulated[kind], 3)
        ticks = sum(sched.ticks.values())
        if ticks:
            out['tick_cpu_ms'] = round(1e3 * self._cpu['tick'] / ticks, 3)
            out['tick_cpu_ms_outside_steps'] = round(
                1e3 * (self._cpu['tick'] - self._cpu['step']) / ticks, 3)
        if self._inputs_taken:
            out['input_cpu_ms'] = round(1e3 * self._cpu['input'] / self._inputs_taken, 3)
        return out

    def _user_ids(self) -> set:
        """Every user the node or its simulation holds state for."""
        sim = self.sim
        return (set(self.presence.users) | set(self._user_stamp) | set(sim.characters)
                | set(sim.engaged) | set(sim.grips))

    # ------------------------------------------------------------------ input
    def _on_intention(self, msg: Intention) -> None:
        try:
            self.sim.set_engaged(msg.user_id, msg.engaged_effectors, msg.engaged_features)
        except ValueError as e:
            self._drop('bad intention', str(e))

    def _on_input(self, data: bytes) -> None:
        self.health.on_receive()
        c0 = time.thread_time()
        tick_cpu = self._cpu['tick']
        self._take_input(data)
        # the input's own CPU: without the tick it may have run
        self._cpu['input'] += time.thread_time() - c0 - (self._cpu['tick'] - tick_cpu)
        self._inputs_taken += 1

    def _release_held(self) -> None:
        """TF changed: the input held for want of it, in the order it came."""
        if self.sim is not None:
            for data in self._held.take():
                self._take_input(data)

    def _take_input(self, data: bytes) -> None:
        decoded = self._drop.decode(data)
        if decoded is None:
            return
        header_stamp, header_frame, frames = decoded
        missing = self._sensor_pose(header_frame or 'kinect_link')
        if missing:   # held until TF knows the frame; what no longer fits is dropped
            if self._held.hold(data) is not None:
                self._drop('no transform', missing)
            return
        now = time.monotonic()
        self.presence.observe(header_stamp, (), wall=now)   # the input's clock moves on:
        self._expire(now)                                   # who left before this message?
        take, stamps = [], {}
        for f in frames:
            stamp = f.stamp_ns or header_stamp
            last = stamps.get(f.user_id, self._user_stamp.get(f.user_id))
            if stamp and last is not None and last - 1_000_000_000 <= stamp <= last:
                # a target already applied, or an older one (a bigger step back is a bag loop or
                # a restarted sensor: taken)
                self._drop('duplicate stamp' if stamp == last else 'out-of-order stamp',
                           f'user {f.user_id}: {(last - stamp) * 1e-6:.1f} ms back')
                continue
            take.append((f.user_id, f.positions, f.orientations, stamp))
            stamps[f.user_id] = stamp
        # every user's target at once: validated by the decoder, moved to the world and
        # retargeted together (Simulation.set_targets)
        refused = self.sim.set_targets(take)
        for uid, e in refused:
            if 'max_characters' in str(e):   # counted per reason, logged once
                self._drop(f'too many users (max_characters '
                           f'{self.sim.config.max_characters})',
                           f'user {uid} gets no character while {e}')
            else:
                self._drop('bad target', str(e))
        if refused:
            for uid in {u for u, _ in refused}:
                stamps.pop(uid, None)
        self._user_stamp.update(stamps)
        self.presence.observe(header_stamp, [f.user_id for f in frames], wall=now)
        if self.params['mace'] and not self._mace_given and self.sim.characters:
            uid = next(iter(self.sim.characters))
            self.sim.hold(uid, 'mace', self.params['mace_hand'])
            self._mace_given = True
        if self.params['sync_to_input'] and frames:
            # phase-lock to the sensor (physics_sim.scheduler): tick now, or once 0.75 period
            # after the last input tick when this target came sooner by its capture stamp
            stamp = max((f.stamp_ns or header_stamp) for f in frames) * 1e-9
            d = self.scheduler.on_input(stamp)
            if d.action == 'tick':
                self._cancel_deferred()
                self._tick(d.dt)
            elif d.action == 'defer' and not self._deferred_armed and self._deferred is not None:
                self._deferred.timer_period_ns = max(1, int(d.delay_s * 1e9))
                self._deferred.reset()
                self._deferred_armed = True

    def _on_deferred(self) -> None:
        if not self._deferred_armed:   # (cancelled after it became ready)
            self._cancel_deferred()
            return
        self._cancel_deferred()
        self._tick(self.scheduler.on_deferred())

    def _cancel_deferred(self) -> None:
        if self._deferred is not None and self._deferred_armed:
            self._deferred.cancel()
        self._deferred_armed = False

    def _expire(self, wall: float) -> None:
        """Remove the characters of users unseen for ``user_timeout_s`` of the input's time."""
        self.presence.timeout_s = self.params['user_timeout_s']
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
        if self.scheduler.timer_due():   # input ticking: the timer is the fallback when it stops
            self._tick()

    def _tick(self, dt: Optional[float] = None) -> None:
        """Advance and publish; ``dt``: the simulated time (s), else the scheduler's."""
        now = time.monotonic()
        c0 = time.thread_time()
        dt = self.scheduler.tick_time(dt)
        self._expire(now)
        # whole physics steps; the remainder is carried to the next tick (sim time = wall time)
        ts = self.params['timestep']
        steps = self.scheduler.steps(dt, ts)
        if steps:
            t0, c1 = time.perf_counter(), time.thread_time()
            self.sim.advance(steps * ts)
            self._wall_in_step = 0.9 * self._wall_in_step + 0.1 * (time.perf_counter() - t0)
            self._sim_in_step = 0.9 * self._sim_in_step + 0.1 * steps * ts
            self._cpu['step'] += time.thread_time() - c1
        self._publish()
        self._cpu['tick'] += time.thread_time() - c0

    def _sensor_pose(self, frame: str) -> str:
        """Take the sensor's pose (world <- ``frame``) from TF; '' when it did, else why not."""
        key = (frame, self.tf.version)
        if key == self._pose_key:
            return ''
        try:   # (the listener's lookup: a /tf_static message the executor was not woken for
            #       is taken now; the input held meanwhile is released first)
            pose = self.tf_listener.lookup(WORLD_FRAME, frame)
        except LookupError as e:
            return (f'waiting for TF {WORLD_FRAME} -> {frame} ({e}); the launch files publish it '
                    '(static_tf, launch argument sensor_pose)')
        self.sim.set_sensor_pose(pose)
        if self._pose_key is None or self._pose_key[0] != frame:
            self.get_logger().info(f'sensor frame {frame} in {WORLD_FRAME}: {pose}')
        self._pose_key = (frame, self.tf.version)
        return ''

    def _publish(self) -> None:
        states = self.sim.states()
        if not states and self._published_empty:
            self._publish_objects(None)
            return
        frames, latest, validated = output_frames(states, self._lift(), WORLD_FRAME)
        # a subscriber that appeared since activation (a recorder) is reached before this output:
        # DDS matching is two-sided, and the publisher's side may lag under load
        self.reach_subscribers([self.pub])
        self.pub.publish(frames_to_cdr(frames, latest, WORLD_FRAME, validated=validated))
        self._publish_robots(states, latest)
        self._published_empty = not frames
        lat = None
        if latest:
            lat = self.get_clock().now().nanoseconds * 1e-9 - latest * 1e-9
            lat = lat if 0 <= lat < 60 else None
        self.health.on_publish(lat)
        self._publish_objects(latest)

    def _publish_robots(self, states, stamp_ns: int) -> None:
        """The characters as robots: URDF (latched, when new), and while something subscribes
        to /character/joint_states, the joint states and the roots on TF."""
        listened = self._js_pub.get_subscription_count() > 0
        urdf, names, angles, roots = self._robots.update(states, self.sim.characters, self._lift(),
                                                         angles=listened)
        for uid in [u for u in self._urdf_pubs if u not in states]:
            self.destroy_publisher(self._urdf_pubs.pop(uid))
        for uid, text in urdf.items():
            if uid not in self._urdf_pubs:
                self._urdf_pubs[uid] = self.create_publisher(String, description_topic(uid),
                                                             STATIC_BROADCASTER_QOS)
            self._urdf_pubs[uid].publish(String(data=text))
        if not names or not listened:
            return
        stamp = ns_to_stamp(stamp_ns)
        self._js_pub.publish(JointState(header=Header(stamp=stamp), name=names,
                                        position=angles.tolist()))
        if self._tf_pub is not None:
            self._tf_pub.publish(to_tf_message(
                [(WORLD_FRAME, child, Transform(t, q)) for child, t, q in roots], stamp))

    def _lift(self) -> np.ndarray:
        """The simulated world's offset from TF's world (the feet's lift above the floor)."""
        sensor = self.sim.sensor
        return np.array([0.0, 0.0, sensor.lift if sensor is not None else 0.0])

    def _publish_objects(self, stamp_ns: Optional[int]) -> None:
        if not self.sim.objects:
            return
        lift = self._lift()
        out = MarkerArray()
        clear = Marker()
        clear.action = Marker.DELETEALL
        clear.ns = 'physics_objects'
        out.markers.append(clear)
        stamp = self.get_clock().now().to_msg() if not stamp_ns else ns_to_stamp(stamp_ns)
        mid = 0
        for name, (pos, quat, spec) in self.sim.object_poses().items():
            pos = pos - lift
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
                m.header.frame_id = WORLD_FRAME
                m.header.stamp = stamp
                m.ns = 'physics_objects'
                m.id = mid
                mid += 1
                m.type = mtype
                m.action = Marker.ADD
                fill_marker(m, pos + quat_rotate(quat, local), quat, scale, rgba, name)
                out.markers.append(m)
        self.obj_pub.publish(out)


def main(args=None) -> int:
    return run_node(PhysicsNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
