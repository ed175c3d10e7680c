"""The physics character as an evaluation method: (reconstruction ->) physics tracking.

``PhysicsMethod`` follows the evaluation harness's ``Method`` protocol (``name``, ``reset()``,
``process(frame: SkeletonFrame) -> SkeletonFrame``): every input frame becomes the target of the
character of ``frame.user_id``; the simulation advances by the stamp difference to the previous
frame (1/30 s when unknown) and the simulated joint positions/orientations are returned in the
input's frame, with the input's stamp, user id and frame id.

:func:`register` adds it to ``skeleton_eval.registry`` (import guarded: this module works
without the harness). The evaluation harness's
frames arrive in the sensor frame (sensor 0.8 m above the floor, ``sensor_model.yaml``);
``auto_floor`` instead puts the floor under the first frame's lowest foot.
"""
from __future__ import annotations

import collections
from typing import Dict, List, Optional, Sequence

import numpy as np
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NOT_TRACKED, NUM_JOINTS, TRACKED
from skeleton_core.params import build, defaults, split

from .simulation import SimConfig, Simulation
import functools


class PhysicsMethod:
    """Physics tracking of the frames given by ``upstream`` (a Method; None = the raw input)."""

    def __init__(self, upstream=None, config: Optional[SimConfig] = None, name: str = 'physics'):
        self.name = name
        self.upstream = upstream
        self._config = config or SimConfig(auto_floor=True)
        self.sim: Optional[Simulation] = None
        self._last_stamp: dict = {}
        self._last_frame_stamp: Optional[int] = None
        # frames refused per reason, and the users concerned (process_bag's summary)
        self.refused: Dict[str, int] = collections.Counter()
        self.refused_users: Dict[str, set] = collections.defaultdict(set)
        self.reset()

    def reset(self) -> None:
        if self.upstream is not None and hasattr(self.upstream, 'reset'):
            self.upstream.reset()
        self.sim = Simulation(self._config)
        self._last_stamp = {}
        self._last_frame_stamp = None
        self.refused = collections.Counter()
        self.refused_users = collections.defaultdict(set)

    def _refuse(self, uid: int, reason: str) -> None:
        self.refused[reason] += 1
        self.refused_users[reason].add(uid)

    def remove(self, user_id: int) -> bool:
        """The user left: remove its character (True if it had one)."""
        self._last_stamp.pop(int(user_id), None)
        return self.sim.remove_character(int(user_id))

    def _target(self, target: SkeletonFrame) -> bool:
        """Set ``target`` as its user's target; False (counted per reason) if refused."""
        uid = int(target.user_id)
        pos = np.array(target.positions, dtype=float)
        missing = np.asarray(target.tracking_state) == NOT_TRACKED
        if missing.any():
            if uid not in self.sim.characters:
                self._refuse(uid, 'incomplete skeleton (a character spawns from a complete one)')
                return False
            # no target for a joint the sensor lost: hold it where the character has it
            pos[missing] = self.sim.state(uid).positions_sensor[missing]
        try:
            self.sim.set_target(uid, pos, target.orientations, target.stamp_ns)
        except ValueError as e:
            reason = (f'too many users (max_characters {self.sim.config.max_characters})'
                      if 'max_characters' in str(e) else 'invalid target')
            self._refuse(uid, reason)
            return False
        return True

    def _output(self, uid: int, target: SkeletonFrame) -> SkeletonFrame:
        st = self.sim.state(uid)
        return SkeletonFrame(positions=st.positions_sensor.copy(),
                             tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                             reliability=np.asarray(target.reliability, np.float32).copy(),
                             orientations=st.orientations_sensor.copy(), user_id=uid,
                             stamp_ns=target.stamp_ns, frame_id=target.frame_id)

    def process_frames(self, targets: Sequence[SkeletonFrame], stamp_ns: int
                       ) -> List[SkeletonFrame]:
        """One sensor frame of every user (already reconstructed): every target set, then the
        world advanced once by the time since the previous frame (1/30 s when unknown, bounded to
        [2, 200] ms), then every character's state. Refused users have no output (counted in
        ``refused``)."""
        ok = [t for t in targets if self._target(t)]
        dt = 1.0 / 30.0
        last = self._last_frame_stamp
        if last is not None and stamp_ns > last:
            dt = float(np.clip((stamp_ns - last) * 1e-9, 0.002, 0.2))
        if stamp_ns and (last is None or stamp_ns > last):
            self._last_frame_stamp = stamp_ns
        if self.sim.characters:
            self.sim.advance(dt)
        return [self._output(int(t.user_id), t) for t in ok]

    def process(self, frame: SkeletonFrame) -> Optional[SkeletonFrame]:
        target = self.upstream.process(frame) if self.upstream is not None else frame
        if target is None:
            return None
        uid = int(target.user_id)
        if not self._target(target):
            return None  # refused (incomplete first skeleton, NaN, too many users): counted
        last = self._last_stamp.get(uid)
        dt = 1.0 / 30.0
        if last is not None and target.stamp_ns > last:
            dt = float(np.clip((target.stamp_ns - last) * 1e-9, 0.002, 0.2))
        self._last_stamp[uid] = target.stamp_ns
        self.sim.advance(dt)
        return self._output(uid, target)


# the evaluation's controller: the papers' external PD forces (the reference the others match)
EVAL_CONTROLLER = 'explicit_pd'
# what the evaluation reports with each physics method (read from SimConfig's declarations)
EVAL_DEFAULTS = {'controller': EVAL_CONTROLLER,
                 **defaults(SimConfig, only=('auto_floor',))}


def make_physics(upstream: Optional[str] = 'C', **params) -> PhysicsMethod:
    """Factory for the harness: ``upstream`` is a registered method name ('C' = the full
    reconstruction; None = physics on the raw stream). ``params``: physics node parameters
    (SimConfig's ROS names: ``controller``, ``kp``, ``kd``, ``auto_floor``, ...; controller
    default :data:`EVAL_CONTROLLER`; the sensor at ``frames.DEFAULT_SENSOR_POSE``, where the
    sensor model puts it), the others pass through to the upstream method."""
    sim_values, upstream_params = split(params, SimConfig)
    cfg = build(SimConfig, {'controller': EVAL_CONTROLLER, **sim_values})
    up = None
    if upstream:
        from skeleton_eval.registry import available_methods, load_plugins, make_method
        if upstream not in available_methods():
            load_plugins(('pose_reconstruction.methods',))
        up = make_method(upstream, **upstream_params)
    name = 'physics' if upstream == 'C' else (f'physics_{upstream}' if upstream else 'physics_raw')
    return PhysicsMethod(upstream=up, config=cfg, name=name)


def register() -> bool:
    """Register ``physics`` (method C -> physics), ``physics_A`` (A -> physics) and
    ``physics_raw`` (raw stream -> physics) with the evaluation harness; False without it."""
    try:
        from skeleton_eval.registry import register_method
    except ImportError:
        return False
    register_method('physics', functools.partial(make_physics, 'C'),
                    'Shum et al. 2013 Sec. VII: method C, then the PD-tracked MuJoCo character',
                    EVAL_DEFAULTS)
    register_method('physics_A', functools.partial(make_physics, 'A'),
                    'Shum & Ho 2012: method A (PCA completion), then the PD-tracked character',
                    EVAL_DEFAULTS)
    register_method('physics_raw', functools.partial(make_physics, None),
                    'the PD-tracked MuJoCo character on the raw Kinect stream', EVAL_DEFAULTS)
    return True


register()

__all__ = ['PhysicsMethod', 'make_physics', 'register']
