"""The physics world: characters PD-tracking their users' target postures (Shum & Ho 2012, Sec. 4,
6, 8; Shum et al. 2013, Sec. VII) in MuJoCo, with virtual joints, objects, pushes and dodging.

Library API (no ROS)::

    sim = Simulation(SimConfig())
    states = sim.step({user_id: positions_20x3}, duration=1/30)   # -> {user_id: CharacterState}
    sim.apply_push(user_id, 'Spine', (200, 0, 0), 0.1)
    sim.throw_ball(position, velocity, radius=0.1, mass=0.5)

Targets arrive in the *sensor* frame (REP-103: x forward from the sensor, z up) and are moved to
the world (floor at z = 0) with :class:`SensorPose` (sensor height and downward pitch). Every state
is reported in both frames. Bad targets (NaN, wrong shape) raise ``ValueError`` before anything
in the simulation changes.

Controllers (``SimConfig.controller``):

* ``explicit_pd`` -- the papers' scheme: Eq. 1 forces at every joint point + Eq. 2 torques about
  every segment axis, applied as external forces (``xfrc_applied``), integrated explicitly.
* ``mocap_constraints`` -- the positional PD is replaced by one soft ``connect`` equality per joint
  between the body point and a mocap body moved along the target; the spring-damper is the
  constraint's ``solref`` (time constant, damping ratio) and is solved implicitly by MuJoCo's
  constraint solver, so it stays stable at any stiffness the time step can resolve. Eq. 2 torques
  are kept as in the paper. Force clamping is then done by the solver's impedance, not max_force.
* ``actuator_pd`` -- Eq. 1 with the same Ke, Kd, evaluated by MuJoCo at every step: three
  actuators per joint along the world axes on a site at the joint point, whose integrator state
  follows the interpolated target ``p_t + (Kd/Ke) p'_t``; bounded by max_force per axis (so
  ``|F| <= sqrt(3) max_force``). With ``integrator='euler'`` it is the paper's explicit scheme;
  with ``'implicitfast'`` MuJoCo integrates the Kd term implicitly. Eq. 2 as in the paper.

* ``auto`` (the node's default) -- ``actuator_pd`` for fewer than ``auto_explicit_from`` (4)
  characters, ``explicit_pd`` from there on: the same control law, whichever is faster. Each
  site actuator takes a Jacobian over every degree of freedom of the world, so ``actuator_pd``
  grows with the square of the characters (``bench_physics``, CPU real-time factor, actuator_pd
  vs explicit_pd: 3 characters 6.6 vs 5.4, 4: 3.2 vs 3.8, 6: 1.8 vs 3.0). The world is
  recompiled whenever a character comes or goes, and the choice is made then.

``explicit_pd`` computes the control law in Python at every physics step (the reference). The two
others update their targets, Eq. 2 twist targets and foot pins once every ``slow_control_every``
steps (default: once per ``advance``) and let ``mj_step`` run the steps in between in C:
``actuator_pd`` is 3-5 times faster than ``explicit_pd`` with the same tracking, jitter and (with
``integrator='euler'``) the same stability limits (``bench_physics``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, List, Mapping, Optional, Sequence

import mujoco
import numpy as np
from skeleton_core.conversions import validate_arrays
from skeleton_core.geometry import (quat_conjugate, quat_multiply, quat_rotate, retarget,
                                    retarget_by_joint)
from skeleton_core.model import (ELBOW_LEFT, ELBOW_RIGHT, HAND_LEFT, HAND_RIGHT, HEAD,
                                 JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, SEGMENT_OF_JOINT,
                                 SEGMENTS, SHOULDER_LEFT, SHOULDER_RIGHT, WRIST_LEFT,
                                 WRIST_RIGHT, Body, estimate_height, standard_body)
from skeleton_core.params import check, nested, param

from .character import Character, Target
from .controller import Gains, is_identity, joint_quats_to_segment, segment_quats_to_joints
from .mjcf_body import ROOT_SEGMENT, CharacterParams, joint_anchor
from .mjcf_world import ALL_BITS, CharacterEntry, ObjectSpec, WorldParams, character_bits, world_xml

CONTROLLERS = ('explicit_pd', 'actuator_pd', 'mocap_constraints', 'auto')
INTEGRATORS = ('euler', 'implicitfast')
SOLVERS = ('auto', 'pgs', 'cg', 'newton')
SEGMENT_CHILDREN_A = tuple(c for _, c in SEGMENTS)
SEGMENT_PARENTS_A = tuple(p for p, _ in SEGMENTS)


# vec(q1 * conj(q0)) = w0 v1 - w1 v0 + v0 x v1 as bilinear forms q0^T N_k q1 (w x y z), k = x, y, z
_VEC_Q1_Q0INV = np.zeros((3, 4, 4))
for _k, (_i, _j) in enumerate(((1, 2), (2, 0), (0, 1))):
    _VEC_Q1_Q0INV[_k, 0, 1 + _k] = 1.0
    _VEC_Q1_Q0INV[_k, 1 + _k, 0] = -1.0
    _VEC_Q1_Q0INV[_k, 1 + _i, 1 + _j] = 1.0
    _VEC_Q1_Q0INV[_k, 1 + _j, 1 + _i] = -1.0


def _as_slice(ids):
    """``ids`` flattened, as a slice when they are consecutive (None stays None)."""
    if ids is None:
        return None
    flat = np.asarray(ids).reshape(-1)
    if flat.size and np.array_equal(flat, np.arange(flat[0], flat[0] + flat.size)):
        return slice(int(flat[0]), int(flat[0]) + flat.size)
    return flat


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (N, 3) arrays (np.cross is slow for small arrays)."""
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


# ---------------------------------------------------------------------------------------------
# Frames
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SensorPose:
    """Where the sensor is in the world: ``height`` (m) above the floor and ``pitch`` (rad, positive
    = tilted down). ``lift`` (m) raises every target so the model's foot capsules (whose axis is at
    the Kinect foot joint) rest on the floor instead of sinking by their radius."""

    height: float = 0.8
    pitch: float = 0.0
    lift: float = 0.0

    def __post_init__(self):   # the offset every target and state is moved by, made once
        object.__setattr__(self, '_off', np.array([0.0, 0.0, self.height + self.lift]))
        self._off.flags.writeable = False

    def rotation(self) -> np.ndarray:
        c, s = math.cos(self.pitch), math.sin(self.pitch)
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])

    def quat(self) -> np.ndarray:
        return np.array([0.0, math.sin(self.pitch / 2), 0.0, math.cos(self.pitch / 2)])

    def offset(self) -> np.ndarray:
        return self._off.copy()

    def to_world(self, p: np.ndarray) -> np.ndarray:
        if self.pitch == 0.0:
            return np.asarray(p, float) + self._off
        return np.asarray(p, float) @ self.rotation().T + self._off

    def to_sensor(self, p: np.ndarray) -> np.ndarray:
        if self.pitch == 0.0:
            return np.asarray(p, float) - self._off
        return (np.asarray(p, float) - self._off) @ self.rotation()

    def quat_to_world(self, q: np.ndarray) -> np.ndarray:
        if self.pitch == 0.0:
            return np.array(q, float)
        return quat_multiply(np.broadcast_to(self.quat(), np.shape(q)), q)

    def quat_to_sensor(self, q: np.ndarray) -> np.ndarray:
        if self.pitch == 0.0:
            return np.array(q, float)
        return quat_multiply(np.broadcast_to(quat_conjugate(self.quat()), np.shape(q)), q)


# ---------------------------------------------------------------------------------------------
# Configuration and state
# ---------------------------------------------------------------------------------------------
def _body_height_ok(v):
    return None if v == 0.0 or 1.0 <= v <= 2.3 else 'body_height must be 0 (auto) or in [1.0, 2.3] m'


def _twist_scale_ok(v):
    return None if len(v) == len(SEGMENTS) and all(
        math.isfinite(x) and x >= 0 for x in v) else f'twist_scale needs {len(SEGMENTS)} values >= 0'


@dataclass
class SimConfig:
    """Everything tunable about the simulation: each field is a parameter of the physics node
    (skeleton_core.params; ``read_only``: fixed once the world is built, the others change the
    running simulation)."""

    timestep: float = param(0.002, 'physics time step (s)', range=(0.0005, 0.01), read_only=True)
    controller: str = param(
        'auto', 'actuator_pd = Eq. 1-2 evaluated by MuJoCo actuators at every step (fast for few '
        "characters); explicit_pd = the papers' external PD forces computed in Python at every "
        'step (reference; faster from ~4 characters); auto = actuator_pd below '
        'auto_explicit_from characters, explicit_pd from there; mocap_constraints = soft '
        'connect constraints to mocap targets', choices=CONTROLLERS, read_only=True)
    integrator: str = param(
        'euler', 'MuJoCo integrator: euler = explicit like the paper (fastest; stable up to Kd '
        "~300 N s/m, Ke ~40000 N/m at 2 ms); implicitfast treats actuator_pd's Kd implicitly "
        '(stable at any gain, ~35 % slower)', choices=INTEGRATORS, read_only=True)
    solver: str = param(
        'auto', 'MuJoCo constraint solver (contacts, foot pins, holds, mocap_constraints); all '
        'converge to the same forces. auto = pgs for actuator_pd/explicit_pd (few active rows: '
        'fastest), newton for mocap_constraints (60 stiff rows a character)', choices=SOLVERS,
        read_only=True)
    implicit_joint_damping: bool = param(
        False, "euler: integrate the ball joints' damping implicitly (MuJoCo's default, ~6 us "
        'more a step); false = explicitly like the other forces, used only while timestep * '
        'joint_damping <= joint_armature / 4 (implicit otherwise)', read_only=True)
    gains: Gains = nested(Gains)
    track_timeconst: float = param(0.02, 'mocap_constraints: spring time constant (s)',
                                   range=(0.001, 1.0), read_only=True)
    track_dampratio: float = param(1.0, 'mocap_constraints: damping ratio', range=(0.1, 10.0),
                                   read_only=True)
    track_impedance: float = param(
        0.9, 'mocap_constraints: solimp impedance d (share of the constraint force kept; lower = '
        'softer, more push response)', range=(0.01, 0.99), read_only=True)
    # character model
    velocity_smoothing: float = param(
        0.7, "exponential smoothing of the target velocity p'_target (frame differences) of "
        'Eq. 1; 0 = raw differences (more jitter)', range=(0.0, 0.95))
    body_height: float = param(0.0, 'character height (m); 0 = estimated from the first target',
                               validator=_body_height_ok, read_only=True)
    body_mass: float = param(75.0, 'character mass at 1.75 m (kg), scaled with height^3',
                             range=(20.0, 200.0), read_only=True)
    retarget: bool = param(True, 'retarget targets to the character (Shum & Ho 2012 Eq. 3-4)')
    joint_damping: float = param(2.0, 'ball joint damping (N m s/rad)', range=(0.0, 100.0),
                                 read_only=True)
    joint_armature: float = param(0.02, 'ball joint armature (kg m^2)', range=(0.0, 10.0),
                                  read_only=True)
    friction: float = param(1.0, 'sliding friction of the character capsules', range=(0.0, 10.0),
                            read_only=True)
    # frames
    sensor_height: float = param(0.8, 'sensor height above the floor (m)', range=(0.0, 3.0),
                                 read_only=True)
    sensor_pitch: float = param(0.0, 'sensor tilt, positive = down (deg)', range=(-45.0, 45.0),
                                read_only=True, name='sensor_pitch_deg', degrees=True)
    auto_floor: bool = param(False, 'put the floor under the lowest foot of the first target '
                             '(overrides sensor_height)', read_only=True)
    lift_feet: bool = param(True, 'raise the targets by the foot capsule radius (the capsules '
                            'rest on the floor instead of sinking into it)', read_only=True)
    # virtual joints
    pin_feet: bool = param(True, 'virtual joints pinning supporting feet to the floor')
    pin_height: float = param(0.04, 'pin a foot whose target is lower than this above its rest '
                              'height (m)', range=(0.0, 0.5))
    pin_release_height: float = param(0.07, 'release when the target rises above this (m)',
                                      range=(0.0, 0.5))
    pin_speed: float = param(0.3, 'pin only if the foot target is slower than this (m/s)',
                             range=(0.0, 10.0))
    pin_release_distance: float = param(0.15, 'release when the target slides this far (m)',
                                        range=(0.01, 2.0))
    pin_max_force: float = param(3000.0, 'a foot pin pulling harder than this (N) conflicts with '
                                 'the targets and is released (counted)', range=(100.0, 1e5))
    conflict_tolerance: float = param(0.05, 'a virtual joint stretched more than this (m) '
                                      'conflicts with the targets', range=(0.0, 1.0),
                                      read_only=True)
    conflict_release: float = param(0.3, '... and is released when stretched more than this (m)',
                                    range=(0.0, 2.0), read_only=True)
    # interaction
    dodge: bool = param(False, 'raise the forearms when a ball approaches the head')
    dodge_distance: float = param(0.45, 'predicted miss distance that triggers a dodge (m)',
                                  range=(0.05, 3.0))
    dodge_time: float = param(0.6, 'dodge: look-ahead of the ball prediction (s)',
                              range=(0.05, 5.0), read_only=True)
    dodge_hold: float = param(0.5, 'dodge: the arms stay up this long after the last threat (s)',
                              range=(0.0, 10.0), read_only=True)
    max_characters: int = param(6, 'most characters at once', range=(1, 30), read_only=True)
    slow_control_every: int = param(
        0, 'physics steps between Python control updates (Eq. 2 twist targets, foot pins; '
        'actuator_pd and mocap_constraints targets); 0 = auto (4 for explicit_pd, one per tick '
        'otherwise)', range=(0, 50), read_only=True)
    auto_explicit_from: int = param(
        4, 'controller auto: explicit_pd from this many characters on (the same control law; '
        'actuator_pd grows with the square of the characters)', range=(1, 100), read_only=True)
    twist_scale: List[float] = param(
        [1.0] * len(SEGMENTS), 'per-segment factor on the Eq. 2 gains (19 values, '
        'skeleton_core.model.SEGMENTS order); the gains are Ke_i = twist_kp * scale_i * I_i',
        validator=_twist_scale_ok, read_only=True)

    def validate(self) -> None:
        """The declared ranges / choices (the gains: finite and >= 0, Gains.validate) and the
        cross-field rules."""
        check(self, nested=False)
        if self.track_timeconst < 2 * self.timestep:
            raise ValueError('track_timeconst must be at least 2 x timestep')
        self.gains.validate()


@dataclass
class CharacterState:
    """Simulated joint positions (20, 3) and orientations (20, 4, x y z w) in the world and in the
    sensor frame, with the stamp of the target being tracked."""

    user_id: int
    positions: np.ndarray
    orientations: np.ndarray
    positions_sensor: np.ndarray
    orientations_sensor: np.ndarray
    stamp_ns: int
    pinned: Dict[str, bool]
    target_world: np.ndarray


# ---------------------------------------------------------------------------------------------
# Simulation
# ---------------------------------------------------------------------------------------------
class Simulation:
    """A MuJoCo world with characters (one per user) and objects."""

    def __init__(self, config: Optional[SimConfig] = None, objects: Sequence[ObjectSpec] = ()):
        self.config = config or SimConfig()
        self.config.validate()
        self.characters: Dict[int, Character] = {}
        self.objects: List[ObjectSpec] = list(objects)
        self.holds: Dict[str, tuple] = {}   # object name -> (user_id, hand joint)
        self.pushes: List[tuple] = []       # (user_id, segment index, force (3,), end time)
        self.counters: Dict[str, int] = {'constraint_conflict': 0, 'virtual_joint_released': 0,
                                         'nan_reset': 0, 'refused_target': 0, 'rebuilds': 0,
                                         'pins': 0}
        self.sensor: Optional[SensorPose] = None
        self._obj_state: Dict[str, tuple] = {}
        self._ball_count = 0
        self.time = 0.0
        self._rebuild()

    # ------------------------------------------------------------------ model
    @property
    def controller(self) -> str:
        """The controller in use: ``config.controller``, or for ``'auto'`` the faster one for
        the current number of characters (module docstring)."""
        c = self.config
        if c.controller != 'auto':
            return c.controller
        return 'explicit_pd' if len(self.characters) >= c.auto_explicit_from else 'actuator_pd'

    def _world_params(self) -> WorldParams:
        c = self.config
        ctrl = self.controller
        cp = CharacterParams(joint_damping=c.joint_damping, joint_armature=c.joint_armature,
                             friction=c.friction,
                             mocap_targets=(ctrl == 'mocap_constraints'),
                             track_solref=(c.track_timeconst, c.track_dampratio),
                             track_solimp=(c.track_impedance, c.track_impedance, 0.001),
                             pin_solref=(2.0 * c.timestep, 1.0),  # stiffest MuJoCo allows
                             pd_actuators=(ctrl == 'actuator_pd'),
                             pd_kp=c.gains.ke, pd_kv=c.gains.kd,
                             pd_force_limit=c.gains.max_force)
        solver = c.solver if c.solver != 'auto' else (
            'newton' if ctrl == 'mocap_constraints' else 'pgs')
        return WorldParams(timestep=c.timestep, integrator=c.integrator, solver=solver,
                           euler_implicit_damping=self.implicit_damping(), character=cp)

    def implicit_damping(self) -> bool:
        """Whether the Euler integrator treats the joint damping implicitly (see SimConfig)."""
        c = self.config
        return (c.implicit_joint_damping
                or c.timestep * c.joint_damping > 0.25 * c.joint_armature)

    def _rebuild(self) -> None:
        """(Re)compile the world from the current characters and objects, keeping the state of
        everything that already existed (matched by name)."""
        old_m = getattr(self, 'model', None)
        old_d = getattr(self, 'data', None)
        entries = []
        for ch in self.characters.values():
            entries.append(CharacterEntry(ch.prefix, ch.body, tuple(ch.cur.positions[0]), ch.slot,
                                          ch.cur.positions))
        xml = world_xml(entries, self.objects, self._world_params())
        m = mujoco.MjModel.from_xml_string(xml)
        d = mujoco.MjData(m)
        self.xml = xml
        if old_m is not None:
            self._copy_state(old_m, old_d, m, d)
        d.time = self.time
        self.model, self.data = m, d
        for ch in self.characters.values():
            ch.bind(m)
            if not ch.spawned:
                ch.set_pose(m, d, ch.cur.positions, ch.cur.seg_quats)
                ch.spawned = True
        for name, (uid, hand) in list(self.holds.items()):
            if uid in self.characters and self._obj_id(name) >= 0:
                self._activate_hold(name, uid, hand, teleport=False)
            else:
                del self.holds[name]
        for ch in self.characters.values():
            for j, pin in ch.pins.items():
                if pin.active:
                    self._set_pin(ch, j, True, pin.point)
        mujoco.mj_forward(m, d)
        self._pack_indices()
        self._pack_targets()
        self.counters['rebuilds'] += 1

    @staticmethod
    def _copy_state(om, od, m, d) -> None:
        for j in range(m.njnt):
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
            oj = mujoco.mj_name2id(om, mujoco.mjtObj.mjOBJ_JOINT, name)
            if oj < 0:
                continue
            nq = {0: 7, 1: 4, 2: 1, 3: 1}[int(m.jnt_type[j])]
            nv = {0: 6, 1: 3, 2: 1, 3: 1}[int(m.jnt_type[j])]
            d.qpos[m.jnt_qposadr[j]:m.jnt_qposadr[j] + nq] = od.qpos[om.jnt_qposadr[oj]:om.jnt_qposadr[oj] + nq]
            d.qvel[m.jnt_dofadr[j]:m.jnt_dofadr[j] + nv] = od.qvel[om.jnt_dofadr[oj]:om.jnt_dofadr[oj] + nv]

    def _obj_id(self, name: str) -> int:
        return mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, f'obj_{name}')

    # ------------------------------------------------------------------ targets
    def _sensor_pose(self, first_world_positions: Optional[np.ndarray] = None) -> SensorPose:
        if self.sensor is None:
            c = self.config
            height = c.sensor_height
            if c.auto_floor and first_world_positions is not None:
                rot = SensorPose(0.0, c.sensor_pitch).to_world(first_world_positions)
                from skeleton_core.model import FOOT_LEFT, FOOT_RIGHT
                height = -float(min(rot[FOOT_LEFT, 2], rot[FOOT_RIGHT, 2]))
            lift = 0.0
            if c.lift_feet:
                from skeleton_core.model import FOOT_LEFT as FL
                lift = float(standard_body(max(self._body_height_for(first_world_positions), 0.6))
                             .segment_radii[SEGMENT_OF_JOINT[FL]])
            self.sensor = SensorPose(height, c.sensor_pitch, lift)
        return self.sensor

    def _body_height_for(self, positions: Optional[np.ndarray]) -> float:
        if self.config.body_height > 0:
            return self.config.body_height
        if positions is None:
            return 1.75
        h = estimate_height(positions)
        return float(np.clip(h, 1.0, 2.3)) if np.isfinite(h) else 1.75

    def make_target(self, user_id: int, positions, orientations=None, stamp_ns: int = 0) -> Target:
        """Validate a sensor-frame target and express it in the world (retargeted if configured).
        Raises ``ValueError`` for NaN / wrong shapes; nothing in the simulation changes then."""
        try:
            p, _, _, q = validate_arrays(positions, orientations=orientations)
        except ValueError:
            self.counters['refused_target'] += 1
            raise
        return self._make_target(user_id, p, q, stamp_ns)

    def _make_target(self, user_id: int, p: np.ndarray, q, stamp_ns: int = 0) -> Target:
        """:meth:`make_target` of arrays that ``validate_arrays`` has already returned."""
        sensor = self._sensor_pose(p)
        pw = sensor.to_world(p)
        ch = self.characters.get(int(user_id))
        body = ch.body if ch is not None else self._new_body(pw)
        if self.config.retarget:
            if ch is not None:   # the character's Eq. 3-4 lengths and fallback directions, cached
                pw = retarget_by_joint(pw, ch.retarget_bone, ch.retarget_dirs)
            else:
                pw = retarget(pw, body)
        if is_identity(q):
            sq = Character.default_seg_quats(pw, body)
        else:
            sq = joint_quats_to_segment(sensor.quat_to_world(q))
        return Target(pw, sq, self.time, int(stamp_ns))

    def _new_body(self, world_positions: np.ndarray) -> Body:
        h = self._body_height_for(world_positions)
        return standard_body(h, self.config.body_mass * (h / 1.75) ** 3)

    def set_target(self, user_id: int, positions, orientations=None, stamp_ns: int = 0) -> None:
        """Give user ``user_id`` a new target (sensor frame). A new user spawns a character in
        the target posture."""
        try:
            p, _, _, q = validate_arrays(positions, orientations=orientations)
        except ValueError:
            self.counters['refused_target'] += 1
            raise
        self._set_target(int(user_id), p, q, stamp_ns)

    def _set_target(self, uid: int, p: np.ndarray, q, stamp_ns: int = 0) -> None:
        """:meth:`set_target` of validated arrays."""
        target = self._make_target(uid, p, q, stamp_ns)
        ch = self.characters.get(uid)
        if ch is None:
            if len(self.characters) >= self.config.max_characters:
                raise ValueError(f'already {len(self.characters)} characters (max_characters)')
            used = {c.slot for c in self.characters.values()}
            slot = min(set(range(30)) - used)
            body = self._new_body(target.positions)
            ch = Character(uid, body, slot, target)
            self.characters[uid] = ch
            self._rebuild()
        else:
            ch.push_target(target, self.config.velocity_smoothing)

    def remove_character(self, user_id: int) -> bool:
        if int(user_id) not in self.characters:
            return False
        del self.characters[int(user_id)]
        self.pushes = [p for p in self.pushes if p[0] != int(user_id)]
        self._rebuild()
        return True

    # ------------------------------------------------------------------ objects
    def add_object(self, spec: ObjectSpec) -> None:
        if any(o.name == spec.name for o in self.objects):
            raise ValueError(f'object {spec.name!r} exists')
        self.objects.append(spec)
        self._rebuild()
        oid = self._obj_id(spec.name)
        adr = self.model.jnt_dofadr[self.model.body_jntadr[oid]]
        self.data.qvel[adr:adr + 3] = spec.vel

    def remove_object(self, name: str) -> bool:
        n = len(self.objects)
        self.objects = [o for o in self.objects if o.name != name]
        self.holds.pop(name, None)
        if len(self.objects) != n:
            self._rebuild()
            return True
        return False

    def throw_ball(self, position, velocity, radius: float = 0.1, mass: float = 0.5,
                   name: Optional[str] = None) -> str:
        """Add a ball at ``position`` (world) flying at ``velocity`` (m/s); returns its name."""
        self._ball_count += 1
        name = name or f'thrown{self._ball_count}'
        self.add_object(ObjectSpec(name, 'ball', tuple(position), (radius,), mass, tuple(velocity),
                                   rgba=(0.9, 0.3, 0.2, 1.0)))
        return name

    def throw_at(self, user_id: int, joint: int = HEAD, speed: float = 6.0, distance: float = 3.0,
                 radius: float = 0.1, mass: float = 0.5) -> str:
        """Throw a ball at a character's joint from ``distance`` in front of it (gravity-corrected)."""
        ch = self.characters[int(user_id)]
        aim = ch.joint_points(self.data)[joint]
        fwd = quat_rotate(ch.segment_quats(self.data)[0], np.array([1.0, 0.0, 0.0]))
        fwd[2] = 0.0
        fwd /= max(np.linalg.norm(fwd), 1e-9)
        start = aim + distance * fwd
        t = distance / speed
        vel = -fwd * speed + np.array([0.0, 0.0, 0.5 * 9.81 * t])
        return self.throw_ball(start, vel, radius, mass)

    def object_poses(self) -> Dict[str, tuple]:
        """name -> (position (3,), quaternion x y z w, spec), world frame."""
        out = {}
        for o in self.objects:
            b = self._obj_id(o.name)
            q = self.data.xquat[b]
            out[o.name] = (self.data.xpos[b].copy(), np.array([q[1], q[2], q[3], q[0]]), o)
        return out

    def hold(self, user_id: int, object_name: str, hand: str = 'right') -> None:
        """Virtual joint (ball) between a character's hand and a holdable object (Sec. 6.1)."""
        if int(user_id) not in self.characters:
            raise ValueError(f'no character {user_id}')
        spec = next((o for o in self.objects if o.name == object_name), None)
        if spec is None or not spec.holdable:
            raise ValueError(f'{object_name!r} is not a holdable object')
        hand_j = HAND_RIGHT if hand == 'right' else HAND_LEFT
        self.holds[object_name] = (int(user_id), hand_j)
        self._activate_hold(object_name, int(user_id), hand_j, teleport=True)

    def release(self, object_name: str) -> None:
        if object_name in self.holds:
            uid, hand = self.holds.pop(object_name)
            e = self._hold_eq(uid, hand, object_name)
            if e >= 0:
                self.data.eq_active[e] = 0
            self._set_object_bits(object_name, ALL_BITS, ALL_BITS)

    def _hold_eq(self, uid, hand, obj) -> int:
        return mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_EQUALITY,
                                 f'u{uid}_hold_{obj}_{JOINT_NAMES[hand]}')

    def _set_object_bits(self, name, ct, ca) -> None:
        b = self._obj_id(name)
        for g in range(self.model.ngeom):
            if self.model.geom_bodyid[g] == b:
                self.model.geom_contype[g] = ct
                self.model.geom_conaffinity[g] = ca

    def _activate_hold(self, name, uid, hand, teleport: bool) -> None:
        m, d = self.model, self.data
        ch = self.characters[uid]
        spec = next(o for o in self.objects if o.name == name)
        e = self._hold_eq(uid, hand, name)
        _, local = joint_anchor(ch.body, hand)
        m.eq_data[e, 0:3] = local
        m.eq_data[e, 3:6] = spec.grip
        d.eq_active[e] = 1
        bit, aff = character_bits(ch.slot)
        self._set_object_bits(name, bit, aff)  # the holder's hand does not collide with it
        if teleport:
            mujoco.mj_forward(m, d)
            hand_p = ch.joint_points(d)[hand]
            oid = self._obj_id(name)
            adr = m.jnt_qposadr[m.body_jntadr[oid]]
            q = d.qpos[adr + 3:adr + 7]
            qx = np.array([q[1], q[2], q[3], q[0]])
            d.qpos[adr:adr + 3] = hand_p - quat_rotate(qx, spec.grip)
            dadr = m.jnt_dofadr[m.body_jntadr[oid]]
            d.qvel[dadr:dadr + 6] = 0.0
            mujoco.mj_forward(m, d)

    # ------------------------------------------------------------------ pushes
    def apply_push(self, user_id: int, segment, force, duration: float) -> None:
        """External force (N, world) on a segment's centre of mass for ``duration`` s. ``segment`` is
        the segment's child-joint name (e.g. 'Spine'), its SEGMENT_NAMES name, or an index."""
        uid = int(user_id)
        if uid not in self.characters:
            raise ValueError(f'no character {uid}')
        f = np.asarray(force, float)
        if f.shape != (3,) or not np.all(np.isfinite(f)):
            raise ValueError('force must be 3 finite numbers')
        if not (np.isfinite(duration) and 0.0 < duration <= 5.0):
            raise ValueError('duration must be in (0, 5] s')
        k = self.segment_index(segment)
        self.pushes.append((uid, k, f, self.time + float(duration)))

    @staticmethod
    def segment_index(segment) -> int:
        from skeleton_core.model import SEGMENT_NAMES
        if isinstance(segment, (int, np.integer)):
            if 0 <= int(segment) < len(SEGMENTS):
                return int(segment)
        elif segment in JOINT_INDEX and SEGMENT_OF_JOINT[JOINT_INDEX[segment]] >= 0:
            return SEGMENT_OF_JOINT[JOINT_INDEX[segment]]
        elif segment in SEGMENT_NAMES:
            return SEGMENT_NAMES.index(segment)
        raise ValueError(f'unknown segment {segment!r} (use a child joint name such as "Spine")')

    # ------------------------------------------------------------------ stepping
    def step(self, targets=None, duration: Optional[float] = None) -> Dict[int, CharacterState]:
        """Set targets (``{user_id: positions}`` / ``{user_id: (positions, orientations)}`` or one
        (20, 3) array for user 0), advance by ``duration`` (default 1/30 s), return the states.
        All targets are validated before any is applied."""
        if targets is not None:
            if not isinstance(targets, Mapping):
                targets = {0: targets}
            prepared = []
            for uid, t in targets.items():
                if isinstance(t, tuple):
                    pos, ori = t
                else:
                    pos, ori = t, None
                try:  # SkeletonFormatError is a ValueError
                    p, _, _, q = validate_arrays(pos, orientations=ori)
                except ValueError:
                    self.counters['refused_target'] += 1
                    raise
                prepared.append((int(uid), p, q))
            for uid, p, q in prepared:
                self._set_target(uid, p, q)
        self.advance(1.0 / 30.0 if duration is None else duration)
        return self.states()

    def advance(self, duration: float) -> None:
        """Simulate ``duration`` seconds in fixed time steps."""
        m, d = self.model, self.data
        n = max(1, int(round(duration / m.opt.timestep)))
        if self.config.dodge:
            self._update_dodge()
        self._pack_targets()
        if self.controller == 'explicit_pd':
            for _ in range(n):
                mujoco.mj_step1(m, d)   # kinematics + velocities of the current state
                self._control()         # forces from the current state (not one step old)
                mujoco.mj_step2(m, d)
                self.time = float(d.time)
        else:
            self._sync_actuator_gains()
            spans = -(-n // (int(self.config.slow_control_every) or 50))  # equal spans
            for i in range(spans):
                nstep = (n * (i + 1)) // spans - (n * i) // spans
                self._control_span(nstep)
                mujoco.mj_step(m, d, nstep=nstep)
                self.time = float(d.time)
        self._pts = None
        self._check_health()

    def _sync_actuator_gains(self) -> None:
        """Copy the run-time settable gains and bounds (Eq. 1 Ke, Kd, max_force; Eq. 2 Kd_i,
        max_torque) into actuator_pd's actuators."""
        if self._act is None:
            return
        g = self.config.gains
        key = (g.ke, g.kd, g.max_force, g.twist_kd, g.max_torque)
        if key == self._act_gains:
            return
        m, ids = self.model, self._act.ravel()
        m.actuator_gainprm[ids, 0] = g.ke
        m.actuator_biasprm[ids, 1] = -g.ke
        m.actuator_biasprm[ids, 2] = -g.kd
        m.actuator_forcerange[ids] = (-g.max_force, g.max_force)
        m.actuator_biasprm[self._tw_act, 2] = -g.twist_kd * self._tw_i
        m.actuator_forcerange[self._tw_act] = (-g.max_torque, g.max_torque)
        self._act_gains = key

    def _frame_shares(self, times) -> np.ndarray:
        """Share (0..1) of every character's target interpolation reached at each of ``times``
        (T,): (T, N) -- linear over one frame period, then held."""
        tg = self._tg
        return np.minimum(np.maximum((np.array(times)[:, None] - tg['T0']) / tg['PER'], 0.0), 1.0)

    def _targets_at(self, t: float):
        """Interpolated targets (N*20, 3) and their velocities at time ``t``: linear over one
        frame period, then held."""
        tg = self._tg
        sj = self._frame_shares((t,))[0][self._jchar][:, None]
        return tg['P0'] + sj * tg['dP'], tg['V'] * (sj < 1.0)

    _XYZW = np.array([1, 2, 3, 0])
    _WXYZ = np.array([3, 0, 1, 2])

    def _points_now(self) -> np.ndarray:
        """:meth:`_joint_points` of the state after the last advance, computed once (the health
        check and the states share it); anything else that moves the bodies clears it."""
        if self._pts is None:
            self._pts = self._joint_points()
        return self._pts

    def _joint_points(self) -> np.ndarray:
        """World positions (N*20, 3) of the joint points (the joint sites, which MuJoCo computes
        in every step's kinematics)."""
        if self._js is not None:
            return self.data.site_xpos[self._js]
        d, jb = self.data, self._jb
        xm = d.xmat[jb].reshape(-1, 3, 3)
        return d.xpos[jb] + (xm @ self._jl[:, :, None])[:, :, 0]

    def _control_span(self, nstep: int) -> None:
        """Targets, Eq. 2 torques, pins and pushes for the next ``nstep`` steps (actuator_pd and
        mocap_constraints), evaluated at the middle of the span; actuator_pd's targets move on
        inside the span (actuator integrator states with the target's slope as their rate)."""
        d, c = self.data, self.config
        xfrc = d.xfrc_applied
        xfrc[:] = 0.0
        span = nstep * self.model.opt.timestep
        t = self.time + 0.5 * span
        tg = self._tg
        if tg is not None:
            # interpolation shares at the span's start, middle and end: numbers when the
            # characters share their frame times, else (3, N*20, 1)
            if tg['uniform'] is not None:
                t0, per = tg['uniform']
                sj = [min(max((x - t0) / per, 0.0), 1.0) for x in (self.time, t, self.time + span)]
                sh_mid = sj[1]
                v_t = tg['V'] if sj[1] < 1.0 else tg['V'] * 0.0
            else:
                sh = self._frame_shares((self.time, t, self.time + span))
                sj = sh[:, self._jchar, None]
                sh_mid = sh[1]
                v_t = tg['V'] * (sj[1] < 1.0)
            p_t = tg['P0'] + sj[1] * tg['dP']
            pts = self._joint_points()
            if self._act is not None:
                ff = c.gains.kd / c.gains.ke if c.gains.ke > 0 else 0.0
                d.act[self._act_adr_s] = (tg['P0'] + sj[0] * tg['dP'] + ff * v_t).reshape(-1)
                d.ctrl[self._act_s] = (((sj[2] - sj[0]) / span) * tg['dP']).reshape(-1)
                d.ctrl[self._tw_act_s] = self._twist_torques(t, tg, pts, damped=False,
                                                             share=sh_mid)
            else:  # mocap_constraints
                lead = 2.0 * c.track_impedance * c.track_timeconst * c.track_dampratio ** 2
                d.mocap_pos[self._mocap] = p_t + lead * v_t
                xfrc[self._sb, 3:] += self._twist_torques(t, tg, pts, share=sh_mid)
            self._update_pins(p_t, v_t, pts)
        self._apply_pushes(t)

    def _apply_pushes(self, t: float) -> None:
        if self.pushes:
            xfrc = self.data.xfrc_applied
            for uid, k, f, t_end in self.pushes:
                if t < t_end and uid in self.characters:
                    xfrc[self.characters[uid].seg_body[k], :3] += f
            self.pushes = [p for p in self.pushes if p[3] > t]

    def _pack_indices(self) -> None:
        """Index arrays over all characters (after every rebuild): the control law runs once,
        vectorised, for the whole world."""
        chars = list(self.characters.values())
        self._chars = chars
        n = len(chars)
        cat = (lambda xs, shape: np.concatenate(xs) if xs else np.zeros(shape))  # noqa: E731
        self._jb = cat([c.joint_body for c in chars], (0,)).astype(int)
        self._jl = cat([c.joint_local for c in chars], (0, 3))
        self._sb = cat([c.seg_body for c in chars], (0,)).astype(int)
        child = np.array(SEGMENT_CHILDREN_A)
        parent = np.array(SEGMENT_PARENTS_A)
        self._sc = cat([child + NUM_JOINTS * i for i in range(n)], (0,)).astype(int)
        self._sp = cat([parent + NUM_JOINTS * i for i in range(n)], (0,)).astype(int)
        scale = (np.ones(len(SEGMENTS)) if self.config.twist_scale is None
                 else np.asarray(self.config.twist_scale, float))
        self._tw_i = cat([c.twist_inertia * scale for c in chars], (0,))
        # Eq. 2's twist error: u . vec(conj(q) * q_t) = q^T M_u q_t (w x y z) for the segment's
        # body-frame axis u: M[0, 1:] = u, M[1:, 0] = -u, M[1:, 1:] = [u]x
        u = np.array([c.segment_axes_local for c in chars]).reshape(-1, 3)
        m4 = np.zeros((len(u), 4, 4))
        m4[:, 0, 1:], m4[:, 1:, 0] = u, -u
        m4[:, 1, 2], m4[:, 1, 3] = -u[:, 2], u[:, 1]
        m4[:, 2, 1], m4[:, 2, 3] = u[:, 2], -u[:, 0]
        m4[:, 3, 1], m4[:, 3, 2] = -u[:, 1], u[:, 0]
        self._tw_m = m4
        self._jroot = self.model.body_rootid[self._jb] if n else np.zeros(0, int)
        self._ub, inv = np.unique(self._jb, return_inverse=True)
        self._sum_rows = np.zeros((len(self._ub), len(self._jb)))
        self._sum_rows[inv, np.arange(len(self._jb))] = 1.0
        self._mocap = (cat([c.mocap_ids for c in chars], (0,)).astype(int)
                       if n and chars[0].mocap_ids is not None else None)
        self._act = (np.concatenate([c.actuator_ids for c in chars]).astype(int)
                     if n and chars[0].actuator_ids is not None else None)   # (N*20, 3)
        self._act_adr = None if self._act is None else self.model.actuator_actadr[self._act]
        self._tw_act = (np.concatenate([c.twist_actuator_ids for c in chars]).astype(int)
                        if self._act is not None else None)
        # the same as slices where the ids are consecutive (one character): cheaper to assign
        self._act_adr_s = _as_slice(self._act_adr)
        self._act_s = _as_slice(self._act)
        self._tw_act_s = _as_slice(self._tw_act)
        self._axis_site = (np.concatenate([c.axis_site_ids for c in chars]).astype(int)
                           if n and chars[0].axis_site_ids is not None else None)
        self._js = (np.concatenate([c.joint_site_ids for c in chars]).astype(int)
                    if n and chars[0].joint_site_ids is not None else None)
        self._pts = None
        self._act_gains = None
        # character of every stacked joint / segment row (per-character frame times)
        self._jchar = np.repeat(np.arange(n), NUM_JOINTS)
        self._schar = np.repeat(np.arange(n), len(SEGMENTS))
        # output orientations by joint: the segment ending at the joint (root: the root body)
        by_joint = np.full(NUM_JOINTS, ROOT_SEGMENT)
        by_joint[list(SEGMENT_CHILDREN_A)] = np.arange(len(SEGMENTS))
        self._jq = cat([by_joint + len(SEGMENTS) * i for i in range(n)], (0,)).astype(int)
        # foot pins (the PinState objects live as long as their characters)
        self._feet = [(i, j, ch.pins[j]) for i, ch in enumerate(chars) for j in ch.pins]
        self._feet_idx = np.array([i * NUM_JOINTS + j for i, j, _ in self._feet], int)
        self._feet_eq = np.array([chars[i].pin_eq[j] for i, j, _ in self._feet], int)

    def _pack_targets(self) -> None:
        """Stacked target frames (previous, newest, velocities) of all characters for this
        advance; dodging characters get their arm targets replaced."""
        chars = self._chars
        if not chars:
            self._tg = None
            return
        if len(chars) == 1:
            ch = chars[0]
            dodging = ch.dodge_until > self.time
            P0, P1 = ch.prev.positions, ch.cur.positions
            if dodging:
                P0, P1 = self._dodge_targets(ch, P0), self._dodge_targets(ch, P1)
            V = ch.velocity * 0.0 if dodging else ch.velocity
            Q0, Q1 = ch.prev.seg_quats, ch.cur.seg_quats
            T0, PER = np.array([ch.cur.sim_time]), np.array([ch.period])
        else:
            P0, P1, V = [], [], []
            for ch in chars:
                p0, p1 = ch.prev.positions, ch.cur.positions
                if ch.dodge_until > self.time:
                    p0, p1 = self._dodge_targets(ch, p0), self._dodge_targets(ch, p1)
                    V.append(ch.velocity * 0.0)
                else:
                    V.append(ch.velocity)
                P0.append(p0)
                P1.append(p1)
            P0, P1, V = np.concatenate(P0), np.concatenate(P1), np.concatenate(V)
            Q0 = np.concatenate([ch.prev.seg_quats for ch in chars])
            Q1 = np.concatenate([ch.cur.seg_quats for ch in chars])
            T0 = np.array([ch.cur.sim_time for ch in chars])
            PER = np.array([ch.period for ch in chars])
        Q0w, Q1w = Q0[:, self._WXYZ], Q1[:, self._WXYZ]     # w x y z from here on
        Q1w *= np.copysign(1.0, np.einsum('ij,ij->i', Q0w, Q1w))[:, None]
        # segment angular velocity over the frame: 2 vec(q1 q0^-1) / period (the rotation
        # vector to within 1 % up to 30 degrees per frame; q1 is on q0's side)
        W = np.einsum('ni,kij,nj->nk', Q0w, _VEC_Q1_Q0INV, Q1w)
        # one frame time and period for all characters (targets arriving together): the
        # interpolation shares are plain numbers
        t0s, pers = T0.tolist(), PER.tolist()
        uniform = all(x == t0s[0] for x in t0s) and all(x == pers[0] for x in pers)
        W *= 2.0 / pers[0] if uniform else (2.0 / PER)[self._schar, None]
        self._tg = dict(P0=P0, dP=P1 - P0, V=V, Q0w=Q0w, dQw=Q1w - Q0w, W=W, T0=T0, PER=PER,
                        uniform=(float(T0[0]), float(PER[0])) if uniform else None)
        self._feet_active = np.array([pin.active for _, _, pin in self._feet], bool)
        self._feet_manual = np.array([pin.manual for _, _, pin in self._feet], bool)
        self._pin_pts = None
        self._twist = None      # recomputed on the next step
        self._step_count = 0

    def _control(self) -> None:
        """``explicit_pd`` at every step: Eq. 1 forces at the joint points from the current state,
        Eq. 2 torques and foot pins every ``slow_control_every`` steps."""
        d = self.data
        c = self.config
        g = c.gains
        xfrc = d.xfrc_applied
        xfrc[:] = 0.0
        t = self.time
        tg = self._tg
        if tg is not None:
            p_t, v_t = self._targets_at(t)
            jb = self._jb
            pts = self._joint_points()
            cvel = d.cvel[jb]
            vel = cvel[:, 3:] + _cross(cvel[:, :3], pts - d.subtree_com[self._jroot])
            f = g.ke * (p_t - pts) + g.kd * (v_t - vel)
            nrm = np.sqrt(np.sum(f * f, axis=1, keepdims=True))
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                f *= np.minimum(1.0, g.max_force / np.maximum(nrm, 1e-300))
            wr = np.concatenate([f, _cross(pts - d.xipos[jb], f)], axis=1)
            xfrc[self._ub] += self._sum_rows @ wr  # several joints share a body
            self._step_count += 1
            if self._twist is None or self._step_count >= (c.slow_control_every or 4):
                self._step_count = 0
                self._twist = self._twist_torques(t, tg, pts)
                self._update_pins(p_t, v_t, pts)
            xfrc[self._sb, 3:] += self._twist
        self._apply_pushes(t)

    def _twist_torques(self, t: float, tg: Dict, pts: np.ndarray, damped: bool = True,
                       share: Optional[np.ndarray] = None) -> np.ndarray:
        """Eq. 2 torques (N*19, 3) about each segment's own axis, bounded by max_torque; with
        ``damped=False`` only ``Ke_i dtheta + Kd_i theta'_t`` (N*19,) for the twist actuators, which
        subtract ``Kd_i theta'`` and bound the sum at every step themselves. ``share``: the
        characters' interpolation shares at ``t`` when the caller has them."""
        d, g = self.data, self.config.gains
        if share is None:
            share = self._frame_shares((t,))[0]
        if isinstance(share, float) or len(share) == 1:
            ss = float(share) if isinstance(share, float) else float(share[0])
            q_t = tg['Q0w'] + ss * tg['dQw']
        else:
            ss = share[self._schar]
            q_t = tg['Q0w'] + ss[:, None] * tg['dQw']
        qc = d.xquat[self._sb]  # w x y z
        # rel = conj(q_cur) * q_t (w x y z; q_t need not be unit: the angle below depends on the
        # ratio of its parts): its w part is q_cur . q_t and its vector part along the segment's
        # body-frame axis u is q_cur^T M_u q_t (bilinear, M_u from _pack_indices); the twist of
        # q_t * conj(q_cur) about the world axis R u is the same angle
        rw = np.einsum('ij,ij->i', qc, q_t)
        proj = np.einsum('ni,nij,nj->n', qc, self._tw_m, q_t)
        err = 2.0 * np.arctan2(proj * np.copysign(1.0, rw), np.abs(rw))  # shortest way round
        if self._axis_site is not None:   # the axis sites' z (the twist actuators' axis)
            axes = d.site_xmat[self._axis_site][:, 2::3]
        else:
            axes = pts[self._sc] - pts[self._sp]
            axes /= np.maximum(np.sqrt(np.einsum('ij,ij->i', axes, axes)), 1e-9)[:, None]
        rate_t = np.einsum('ij,ij->i', tg['W'], axes) * (ss < 1.0)  # target twist rate
        if not damped:   # (Ke_i err + Kd_i rate_t) with Ke_i, Kd_i = gain per unit inertia * I_i
            return (g.twist_ke * err + g.twist_kd * rate_t) * self._tw_i
        k_e, k_d = g.twist_ke * self._tw_i, g.twist_kd * self._tw_i
        rate = np.einsum('ij,ij->i', d.cvel[self._sb, :3], axes)
        tau = np.minimum(np.maximum(k_e * err + k_d * (rate_t - rate), -g.max_torque),
                         g.max_torque)
        return tau[:, None] * axes

    # ------------------------------------------------------------------ virtual joints
    def _set_pin(self, ch: Character, j: int, on: bool, point=None) -> None:
        e = ch.pin_eq[j]
        if on:
            self.model.eq_data[e, 3:6] = point
        self.data.eq_active[e] = 1 if on else 0
        te = ch.track_eq.get(j, -1)
        if te >= 0:  # constraint controller: the pin replaces the foot's tracking spring
            self.data.eq_active[te] = 0 if on else 1

    def pin(self, user_id: int, joint: str, point=None) -> None:
        """Pin a foot joint ('FootLeft'/'FootRight') to a world point (default: where it is) with
        a virtual ball joint until :meth:`unpin`; it is not released when the target lifts."""
        ch = self.characters[int(user_id)]
        j = JOINT_INDEX.get(joint, -1)
        if j not in ch.pins:
            raise ValueError(f'only {[JOINT_NAMES[k] for k in ch.pins]} can be pinned')
        p = ch.joint_points(self.data)[j] if point is None else np.asarray(point, float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError('pin point must be 3 finite numbers')
        pin = ch.pins[j]
        pin.active, pin.manual, pin.point = True, True, p.copy()
        self._set_pin(ch, j, True, p)
        self._pack_targets()

    def unpin(self, user_id: int, joint: str) -> None:
        ch = self.characters[int(user_id)]
        j = JOINT_INDEX.get(joint, -1)
        if j in ch.pins:
            ch.pins[j].active = ch.pins[j].manual = False
            self._set_pin(ch, j, False)
            self._pack_targets()

    def _update_pins(self, p_t, v_t, pts) -> None:
        """Pin a foot whose target is on the floor and slow; release it when the target lifts or
        slides away (Shum & Ho 2012, Sec. 6.1). Scalar code: two feet per character, where
        numpy's per-call cost would dominate."""
        c = self.config
        fi = self._feet_idx
        if fi.size == 0:
            return
        floor = self.sensor.lift if self.sensor else 0.0
        act = self._feet_active
        any_act = any(pin.active for _, _, pin in self._feet)
        xt = p_t[fi].tolist()
        ht = [x[2] - floor for x in xt]
        speed2 = [v[0] * v[0] + v[1] * v[1] + v[2] * v[2] for v in v_t[fi].tolist()]
        slow2 = c.pin_speed * c.pin_speed
        if not any_act and not (c.pin_feet and any(h < c.pin_height and s2 < slow2
                                                   for h, s2 in zip(ht, speed2))):
            return  # nothing pinned and no foot target on the floor: nothing can change
        # the simulated foot must be on the floor and slow too: pinning a flailing foot would
        # stop it dead in one step (an impulse the solver cannot absorb)
        d = self.data
        xf = pts[fi]
        forces = self._pin_forces(c.pin_max_force).tolist() if any_act else None
        pin_pts = self._pin_points().tolist() if any_act else None
        cv = arm = None
        changes = []
        for n, (i, j, pin) in enumerate(self._feet):
            if pin.active:
                dx, dy = xt[n][0] - pin_pts[n][0], xt[n][1] - pin_pts[n][1]
                up = (ht[n] > c.pin_release_height or not c.pin_feet
                      or dx * dx + dy * dy > c.pin_release_distance ** 2)
                if forces[n] > c.pin_max_force:  # conflicting constraints: let go before the
                    self.counters['constraint_conflict'] += 1   # solver blows up
                    self.counters['virtual_joint_released'] += 1
                    changes.append(n)
                elif up and not pin.manual:
                    changes.append(n)
            elif c.pin_feet and not pin.manual and ht[n] < c.pin_height and speed2[n] < slow2:
                if cv is None:   # the simulated feet's velocities, only when one may be pinned
                    cv = d.cvel[self._jb[fi]].tolist()
                    arm = (xf - d.subtree_com[self._jroot[fi]]).tolist()
                w, v, r = cv[n][:3], cv[n][3:], arm[n]
                vs = (v[0] + w[1] * r[2] - w[2] * r[1], v[1] + w[2] * r[0] - w[0] * r[2],
                      v[2] + w[0] * r[1] - w[1] * r[0])
                if (float(xf[n, 2]) - floor < c.pin_height + 0.03
                        and vs[0] * vs[0] + vs[1] * vs[1] + vs[2] * vs[2] < 4.0 * slow2):
                    changes.append(n)
        for n in changes:
            i, j, pin = self._feet[n]
            if not pin.active:
                pin.active = True
                pin.point = xf[n].copy()
                self._set_pin(self._chars[i], j, True, pin.point)
                self.counters['pins'] += 1
            else:
                pin.active = pin.manual = False
                self._set_pin(self._chars[i], j, False)
                self._feet_manual[n] = False
            act[n] = pin.active
            self._pin_pts = None

    def _pin_forces(self, below: float = 0.0) -> np.ndarray:
        """Magnitude (N) of each foot pin's constraint force in the last step (0 if inactive).
        With ``below`` > 0, all zeros when no equality row can reach it (|F| <= sqrt(3) max |row|):
        the caller only asks which pins pull harder than that."""
        d = self.data
        out = np.zeros(len(self._feet))
        ne = int(d.ne)   # equality rows come first in the constraint arrays, by equality id
        if ne and below > 0.0 and 1.7320508075688772 * np.abs(d.efc_force[:ne]).max() <= below:
            ne = 0
        if ne:
            f2 = np.bincount(d.efc_id[:ne], d.efc_force[:ne] ** 2, minlength=self.model.neq)
            out = np.sqrt(f2[self._feet_eq]) * self._feet_active
        self._pin_forces_cache = out
        return out

    def _pin_points(self) -> np.ndarray:
        if getattr(self, '_pin_pts', None) is None or len(self._pin_pts) != len(self._feet):
            self._pin_pts = np.array([pin.point for _, _, pin in self._feet]).reshape(-1, 3)
        return self._pin_pts

    def _check_health(self) -> None:
        """Stretched virtual joints are conflicts (counted; released if badly stretched); a
        non-finite state resets every character to its target."""
        d = self.data
        c = self.config
        act = [n for n, (_, _, pin) in enumerate(self._feet) if pin.active]
        if act:
            gap_v = self._points_now()[self._feet_idx] - self._pin_points()
            gaps = np.sqrt(np.sum(gap_v * gap_v, axis=1)).tolist()
            for n in act:
                i, j, pin = self._feet[n]
                if gaps[n] > c.conflict_tolerance:
                    self.counters['constraint_conflict'] += 1
                if gaps[n] > c.conflict_release:
                    pin.active = pin.manual = False
                    self._set_pin(self._chars[i], j, False)
                    self._pin_pts = None
                    self.counters['virtual_joint_released'] += 1
        for name, (uid, hand) in list(self.holds.items()):
            ch = self.characters.get(uid)
            if ch is None:
                continue
            spec = next(o for o in self.objects if o.name == name)
            b = self._obj_id(name)
            grip_w = d.xpos[b] + d.xmat[b].reshape(3, 3) @ spec.grip
            gap = float(np.linalg.norm(ch.joint_points(d)[hand] - grip_w))
            if gap > c.conflict_tolerance:
                self.counters['constraint_conflict'] += 1
            if gap > c.conflict_release:
                self.release(name)
                self.counters['virtual_joint_released'] += 1
        w = d.warning[mujoco.mjtWarning.mjWARN_BADQACC]
        # a sum is finite only when every term is (or overflows: a blown-up state too)
        bad = not math.isfinite(float(d.qpos.sum()) + float(d.qvel.sum())) or w.number > 0
        if bad:
            self.counters['nan_reset'] += 1
            w.number = 0
            self.reset_to_targets()

    def reset_to_targets(self) -> None:
        m, d = self.model, self.data
        t = self.time
        mujoco.mj_resetData(m, d)
        for ch in self.characters.values():
            for pin in ch.pins.values():
                pin.active = False
            ch.set_pose(m, d, ch.cur.positions, ch.cur.seg_quats)
        d.eq_active[:] = m.eq_active0
        for name, (uid, hand) in list(self.holds.items()):
            self._activate_hold(name, uid, hand, teleport=True)
        d.time = t
        mujoco.mj_forward(m, d)
        self._pts = None

    # ------------------------------------------------------------------ dodge (Fig. 4)
    def _update_dodge(self) -> None:
        c = self.config
        d = self.data
        for ch in self.characters.values():
            head = ch.joint_points(d)[HEAD]
            for o in self.objects:
                if o.kind != 'ball' or o.name in self.holds:
                    continue
                b = self._obj_id(o.name)
                adr = self.model.jnt_dofadr[self.model.body_jntadr[b]]
                v = d.qvel[adr:adr + 3]
                r = d.xpos[b] - head
                vv = float(v @ v)
                if vv < 1.0:
                    continue
                tc = -float(r @ v) / vv
                if 0.0 < tc < c.dodge_time and np.linalg.norm(r + tc * v) < c.dodge_distance:
                    ch.dodge_until = self.time + c.dodge_hold

    def _dodge_targets(self, ch: Character, p_t: np.ndarray) -> np.ndarray:
        """Forearms raised in front of the head (Shum & Ho 2012, Sec. 8.2)."""
        p = p_t.copy()
        q0 = ch.cur.seg_quats[0]
        fwd = quat_rotate(q0, np.array([1.0, 0.0, 0.0]))
        left = quat_rotate(q0, np.array([0.0, 1.0, 0.0]))
        up = np.array([0.0, 0.0, 1.0])
        head = p_t[HEAD]
        s = ch.body.height / 1.75
        for side, sh, el, wr, hd in ((1.0, SHOULDER_LEFT, ELBOW_LEFT, WRIST_LEFT, HAND_LEFT),
                                     (-1.0, SHOULDER_RIGHT, ELBOW_RIGHT, WRIST_RIGHT, HAND_RIGHT)):
            p[el] = p_t[sh] + s * (0.22 * fwd - 0.05 * up + side * 0.08 * left)
            p[wr] = head + s * (0.22 * fwd + 0.02 * up + side * 0.06 * left)
            p[hd] = head + s * (0.24 * fwd + 0.10 * up + side * 0.04 * left)
        return p

    # ------------------------------------------------------------------ state
    def state(self, user_id: int) -> CharacterState:
        ch = self.characters[int(user_id)]
        d = self.data
        pts = ch.joint_points(d)
        q = segment_quats_to_joints(ch.segment_quats(d))
        sensor = self.sensor or SensorPose(self.config.sensor_height, self.config.sensor_pitch)
        return CharacterState(
            user_id=ch.user_id, positions=pts, orientations=q,
            positions_sensor=sensor.to_sensor(pts), orientations_sensor=sensor.quat_to_sensor(q),
            stamp_ns=ch.cur.stamp_ns,
            pinned={JOINT_NAMES[j]: p.active for j, p in ch.pins.items()},
            target_world=ch.cur.positions.copy())

    def states(self) -> Dict[int, CharacterState]:
        """:meth:`state` of every character, computed for all of them at once."""
        chars = self._chars
        if len(chars) != len(self.characters) or not chars:
            return {uid: self.state(uid) for uid in self.characters}
        d = self.data
        pts = self._points_now()
        qs = d.xquat[self._sb][:, self._XYZW][self._jq]  # by joint, x y z w
        sensor = self.sensor or SensorPose(self.config.sensor_height, self.config.sensor_pitch)
        ps, qss = sensor.to_sensor(pts), sensor.quat_to_sensor(qs)
        out = {}
        for i, ch in enumerate(chars):
            r = slice(i * NUM_JOINTS, (i + 1) * NUM_JOINTS)
            out[ch.user_id] = CharacterState(
                user_id=ch.user_id, positions=pts[r], orientations=qs[r],
                positions_sensor=ps[r], orientations_sensor=qss[r], stamp_ns=ch.cur.stamp_ns,
                pinned={JOINT_NAMES[j]: p.active for j, p in ch.pins.items()},
                target_world=ch.cur.positions.copy())
        return out


__all__ = ['Simulation', 'SimConfig', 'SensorPose', 'CharacterState', 'CONTROLLERS', 'SOLVERS',
           'Gains',
           'ObjectSpec']
