"""Everything tunable about the simulation (:class:`SimConfig`) and what it reports per character
(:class:`CharacterState`)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, List

import numpy as np
from skeleton_core.model import SEGMENTS
from skeleton_core.params import check, nested, param

from .controller import Gains
from .controllers import controller_names

INTEGRATORS = ('euler', 'implicitfast')
SOLVERS = ('auto', 'pgs', 'cg', 'newton')
WORLD_SPLITS = ('contact', 'shared')


def controllers() -> tuple:
    """The controller names ``SimConfig.controller`` accepts: every registered controller and
    ``auto``."""
    return controller_names() + ('auto',)


def _controller_ok(v):
    """A registered controller or auto (the registry is live: a controller registered after this
    module's import is accepted too)."""
    return None if v in controllers() else f'controller must be one of {controllers()}, got {v!r}'


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

    timestep: float = param(0.002, 'physics time step (s)', range=(0.0005, 0.01), read_only=True,
                            public=False)
    controller: str = param(
        'auto', 'actuator_pd = Eq. 1-2 evaluated by MuJoCo actuators at every step (fast for few '
        "characters); explicit_pd = the papers' external PD forces computed at every step (Eq. 1 "
        'compiled; faster with several characters in one model); auto = per model, actuator_pd below '
        'auto_explicit_from characters, explicit_pd from there; mocap_constraints = soft '
        'connect constraints to mocap targets (physics_sim.controllers: every registered one)',
        validator=_controller_ok, read_only=True)
    integrator: str = param(
        'euler', 'MuJoCo integrator: euler = explicit like the paper (fastest; stable up to a '
        "bounded Kd and Ke at a given timestep); implicitfast treats actuator_pd's Kd implicitly "
        '(stable at any gain, slower)', choices=INTEGRATORS, read_only=True, public=False)
    solver: str = param(
        'auto', 'MuJoCo constraint solver (contacts, foot pins, holds, mocap_constraints); all '
        'converge to the same forces. auto = newton (pgs is as fast for one character alone, '
        'two to three times slower once characters touch)', choices=SOLVERS,
        read_only=True, public=False)
    implicit_joint_damping: bool = param(
        False, "euler: integrate the ball joints' damping implicitly (MuJoCo's default, "
        'slower); false = explicitly like the other forces, used only while timestep * '
        'joint_damping <= joint_armature / 4 (implicit otherwise)', read_only=True, public=False)
    gains: Gains = nested(Gains)
    track_timeconst: float = param(0.02, 'mocap_constraints: spring time constant (s)',
                                   range=(0.001, 1.0), read_only=True, public=False)
    track_dampratio: float = param(1.0, 'mocap_constraints: damping ratio', range=(0.1, 10.0),
                                   read_only=True, public=False)
    track_impedance: float = param(
        0.9, 'mocap_constraints: solimp impedance d (share of the constraint force kept; lower = '
        'softer, more push response)', range=(0.01, 0.99), read_only=True, public=False)
    # character model
    velocity_smoothing: float = param(
        0.7, "exponential smoothing of the target velocity p'_target (frame differences) of "
        'Eq. 1; 0 = raw differences (more jitter)', range=(0.0, 0.95), public=False)
    body_height: float = param(0.0, 'character height (m); 0 = estimated from the first target',
                               validator=_body_height_ok, read_only=True)
    body_mass: float = param(75.0, 'character mass at 1.75 m (kg), scaled with height^3',
                             range=(20.0, 200.0), read_only=True)
    retarget: bool = param(True, 'retarget targets to the character (Shum & Ho 2012 Eq. 3-4)',
                           public=False)
    joint_damping: float = param(2.0, 'ball joint damping (N m s/rad)', range=(0.0, 100.0),
                                 read_only=True, public=False)
    joint_armature: float = param(0.02, 'ball joint armature (kg m^2)', range=(0.0, 10.0),
                                  read_only=True, public=False)
    friction: float = param(1.0, 'sliding friction of the character capsules', range=(0.0, 10.0),
                            read_only=True, public=False)
    # frames
    # (the sensor's pose is on TF: world -> the input's frame; see frames.py)
    auto_floor: bool = param(False, 'put the floor under the lowest foot of the first target '
                             "(overrides the height of the sensor's TF pose)", read_only=True,
                             public=False)
    lift_feet: bool = param(True, 'raise the targets by the foot capsule radius (the capsules '
                            'rest on the floor instead of sinking into it)', read_only=True,
                            public=False)
    # virtual joints
    pin_feet: bool = param(True, 'virtual joints pinning supporting feet to the floor',
                           public=False)
    pin_height: float = param(0.04, 'pin a foot whose target is lower than this above its rest '
                              'height (m)', range=(0.0, 0.5), public=False)
    pin_release_height: float = param(0.07, 'release when the target rises above this (m)',
                                      range=(0.0, 0.5), public=False)
    pin_speed: float = param(0.3, 'pin only if the foot target is slower than this (m/s)',
                             range=(0.0, 10.0), public=False)
    pin_release_distance: float = param(0.15, 'release when the target slides this far (m)',
                                        range=(0.01, 2.0), public=False)
    pin_max_force: float = param(3000.0, 'a foot pin pulling harder than this (N) conflicts with '
                                 'the targets and is released (counted)', range=(100.0, 1e5),
                                 public=False)
    conflict_tolerance: float = param(0.05, 'a virtual joint stretched more than this (m) '
                                      'conflicts with the targets', range=(0.0, 1.0),
                                      read_only=True, public=False)
    conflict_release: float = param(0.3, '... and is released when stretched more than this (m)',
                                    range=(0.0, 2.0), read_only=True, public=False)
    # virtual features (Ishigaki et al. 2009; docs/control.md)
    feature_world: str = param(
        '', "path of a performance_control world YAML: its features' static geometry (bars, "
        'rope at rest, trampoline surface) is added to the world and hands the control node '
        'reports engaged (intention_topic) grip them; empty = no features', read_only=True)
    grip_reach: float = param(0.15, 'an engaged hand grips the feature when its axis is within '
                              'this distance (m); farther, it is tried again every frame',
                              range=(0.01, 1.0), public=False)
    # interaction
    dodge: bool = param(False, 'raise the forearms when a ball approaches the head')
    dodge_distance: float = param(0.45, 'predicted miss distance that triggers a dodge (m)',
                                  range=(0.05, 3.0), public=False)
    dodge_time: float = param(0.6, 'dodge: look-ahead of the ball prediction (s)',
                              range=(0.05, 5.0), read_only=True, public=False)
    dodge_hold: float = param(0.5, 'dodge: the arms stay up this long after the last threat (s)',
                              range=(0.0, 10.0), read_only=True, public=False)
    max_characters: int = param(6, 'most characters at once', range=(1, 30), read_only=True)
    slow_control_every: int = param(
        0, 'physics steps between Python control updates (Eq. 2 twist targets, foot pins; '
        'actuator_pd and mocap_constraints targets); 0 = auto (4 for explicit_pd, one per tick '
        'otherwise)', range=(0, 50), read_only=True, public=False)
    auto_explicit_from: int = param(
        3, 'controller auto: explicit_pd from this many characters in one model on (the same '
        'control law; actuator_pd grows with the square of the characters)', range=(1, 100),
        read_only=True, public=False)
    world_split: str = param(
        'shared', "shared = one MuJoCo model for all characters (fastest with explicit_pd's "
        'compiled Eq. 1); contact = characters that cannot touch each other in separate models '
        '(faster for actuator_pd at several characters; merged while their boxes come within '
        'contact_margin; one model while there are objects)', choices=WORLD_SPLITS, read_only=True,
        public=False)
    contact_margin: float = param(
        0.25, "world_split contact: margin (m) added to every side of a character's horizontal box "
        '(joint points and newest target) when deciding who may touch whom', range=(0.0, 5.0),
        read_only=True, public=False)
    twist_scale: List[float] = param(
        [1.0] * len(SEGMENTS), 'per-segment factor on the Eq. 2 gains (19 values, '
        'skeleton_core.model.SEGMENTS order); the gains are Ke_i = twist_kp * scale_i * I_i',
        validator=_twist_scale_ok, read_only=True, public=False)

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


__all__ = ['SimConfig', 'CharacterState', 'INTEGRATORS', 'SOLVERS', 'WORLD_SPLITS',
           'controllers']
