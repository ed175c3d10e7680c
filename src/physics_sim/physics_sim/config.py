"""Everything tunable about the simulation (:class:`SimConfig`) and what it reports per character
(:class:`CharacterState`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, Optional, Sequence

import numpy as np
from skeleton_core.model import SEGMENTS

from .controller import Gains
from .controllers import controller_names

INTEGRATORS = ('euler', 'implicitfast')
SOLVERS = ('auto', 'pgs', 'cg', 'newton')
WORLD_SPLITS = ('contact', 'shared')


def controllers() -> tuple:
    """The controller names ``SimConfig.controller`` accepts: every registered controller and
    ``auto``."""
    return controller_names() + ('auto',)


@dataclass
class SimConfig:
    """Everything tunable about the simulation (the node maps each field to a ROS parameter)."""

    timestep: float = 0.002
    controller: str = 'actuator_pd'
    # MuJoCo integrator of the world (INTEGRATORS): euler = explicit, as the paper (fastest);
    # implicitfast also integrates actuator_pd's Kd implicitly (stable at any gain, ~35 % slower)
    integrator: str = 'euler'
    # MuJoCo constraint solver (SOLVERS) for contacts, foot pins, holds and mocap_constraints'
    # connects; all converge to the same constraint forces. auto = pgs for actuator_pd and
    # explicit_pd (a character has 0-10 active rows: ~7 us a step, where newton factors an
    # nv x nv Hessian, ~20 us) and newton for mocap_constraints (60 stiff rows a character, which
    # take pgs many sweeps: 3x slower there)
    solver: str = 'auto'
    # euler: integrate the ball joints' damping implicitly (MuJoCo's Euler default; one more
    # factorisation per step, ~6 us) instead of explicitly like every other force of the paper's
    # scheme. Explicit is used only while it is stable by a wide margin (timestep * joint_damping
    # <= joint_armature / 4: the armature bounds every dof's inertia from below)
    implicit_joint_damping: bool = False
    gains: Gains = field(default_factory=Gains)
    # constraint controller (mocap_constraints): soft connect spring = (time constant, damping ratio)
    track_timeconst: float = 0.02
    track_dampratio: float = 1.0
    track_impedance: float = 0.9    # solimp d (dmin = dmax): share of the constraint force kept
    # character model
    velocity_smoothing: float = 0.7  # p'_target: exponential smoothing of frame differences (0 = raw)
    body_height: float = 0.0        # m; 0 = estimate from the user's first target
    body_mass: float = 75.0         # kg at 1.75 m (scaled with height^3)
    retarget: bool = True           # Eq. 3-4: targets to the character's segment lengths
    joint_damping: float = 2.0
    joint_armature: float = 0.02
    friction: float = 1.0
    # frames
    sensor_height: float = 0.8
    sensor_pitch: float = 0.0
    auto_floor: bool = False        # set the sensor height from the first target's lowest foot
    lift_feet: bool = True          # raise targets by the foot capsule radius
    # virtual joints
    pin_feet: bool = True
    pin_height: float = 0.04        # m above the standing foot height: pin below this
    pin_release_height: float = 0.07
    pin_speed: float = 0.3          # m/s: pin only if the foot target is slower
    pin_release_distance: float = 0.15  # m: release when the target slides this far from the pin
    pin_max_force: float = 3000.0   # N: a virtual joint pulling harder conflicts with the targets
    conflict_tolerance: float = 0.05    # m: a virtual joint stretched more than this = conflict
    conflict_release: float = 0.3       # m: ... and released if stretched more than this
    # interaction
    dodge: bool = False
    dodge_distance: float = 0.45    # m: predicted closest approach to the head
    dodge_time: float = 0.6         # s: look-ahead
    dodge_hold: float = 0.5         # s: arms stay up this long after the last threat
    max_characters: int = 6
    # steps between Python control updates (Eq. 2 twist targets, foot pins; the chunked
    # controllers' targets); 0 = auto: 4 for explicit_pd, the whole advance (<= 50) otherwise
    slow_control_every: int = 0
    # controller 'auto': explicit_pd from this many characters on, actuator_pd below
    auto_explicit_from: int = 3
    twist_scale: Optional[Sequence[float]] = None  # per-segment factor on Eq. 2 gains (19, SEGMENTS)
    # worlds: 'contact' = characters that cannot touch each other are simulated in separate MuJoCo
    # models (actuator_pd's cost in one model grows with the square of its characters), merged into
    # one while their bounding boxes come within contact_margin; 'shared' = one model for all (the
    # default: with explicit_pd's compiled Eq. 1, one model of 6 characters steps faster than 6
    # models, bench_physics --rtf-only). Objects can touch anyone: with objects, one model
    world_split: str = 'shared'
    contact_margin: float = 0.25    # m added to each side of a character's box (a frame of motion)

    def validate(self) -> None:
        if self.controller not in controllers():
            raise ValueError(f'controller must be one of {controllers()}, got {self.controller!r}')
        if self.integrator not in INTEGRATORS:
            raise ValueError(f'integrator must be one of {INTEGRATORS}, got {self.integrator!r}')
        if self.world_split not in WORLD_SPLITS:
            raise ValueError(f'world_split must be one of {WORLD_SPLITS}, got {self.world_split!r}')
        if not (0.0 <= self.contact_margin <= 5.0):
            raise ValueError('contact_margin must be in [0, 5] m')
        if self.solver not in SOLVERS:
            raise ValueError(f'solver must be one of {SOLVERS}, got {self.solver!r}')
        if not (1e-4 <= self.timestep <= 0.02):
            raise ValueError(f'timestep must be in [0.0001, 0.02] s, got {self.timestep}')
        if self.twist_scale is not None:
            ts = np.asarray(self.twist_scale, float)
            if ts.shape != (len(SEGMENTS),) or not np.all(np.isfinite(ts)) or np.any(ts < 0):
                raise ValueError(f'twist_scale needs {len(SEGMENTS)} finite values >= 0')
        if int(self.auto_explicit_from) < 1:
            raise ValueError('auto_explicit_from must be >= 1')
        if not (0 <= int(self.slow_control_every) <= 50):
            raise ValueError('slow_control_every must be in [0, 50] (0 = auto)')
        if not (0.0 <= self.velocity_smoothing < 1.0):
            raise ValueError('velocity_smoothing must be in [0, 1)')
        if not (0.01 <= self.track_impedance <= 0.99):
            raise ValueError('track_impedance must be in [0.01, 0.99]')
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
