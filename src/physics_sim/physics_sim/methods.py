"""The physics character as an evaluation method: (reconstruction ->) physics tracking.

``PhysicsMethod`` follows the evaluation harness's ``Method`` protocol (``name``, ``reset()``,
``process(frame: SkeletonFrame) -> SkeletonFrame``): every input frame becomes the target of the
character of ``frame.user_id``; the simulation advances by the stamp difference to the previous
frame (1/30 s when unknown) and the simulated joint positions/orientations are returned in the
input's frame, with the input's stamp, user id and frame id.

:func:`register` adds it to ``skeleton_eval.evaluation`` (import guarded: this module works
without the harness). The evaluation harness's
frames arrive in the sensor frame (sensor 0.8 m above the floor, ``sensor_model.yaml``);
``auto_floor`` instead puts the floor under the first frame's lowest foot.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NOT_TRACKED, NUM_JOINTS, TRACKED

from .simulation import SimConfig, Simulation

class PhysicsMethod:
    """Physics tracking of the frames given by ``upstream`` (a Method; None = the raw input)."""

    def __init__(self, upstream=None, config: Optional[SimConfig] = None, name: str = 'physics'):
        self.name = name
        self.upstream = upstream
        self._config = config or SimConfig(auto_floor=True)
        self.sim: Optional[Simulation] = None
        self._last_stamp: dict = {}
        self.reset()

    def reset(self) -> None:
        if self.upstream is not None and hasattr(self.upstream, 'reset'):
            self.upstream.reset()
        self.sim = Simulation(self._config)
        self._last_stamp = {}

    def process(self, frame: SkeletonFrame) -> Optional[SkeletonFrame]:
        target = self.upstream.process(frame) if self.upstream is not None else frame
        if target is None:
            return None
        uid = int(target.user_id)
        pos = np.array(target.positions, dtype=float)
        missing = np.asarray(target.tracking_state) == NOT_TRACKED
        if missing.any():
            if uid not in self.sim.characters:
                return None  # spawn only from a complete skeleton
            # no target for a joint the sensor lost: hold it where the character has it
            pos[missing] = self.sim.state(uid).positions_sensor[missing]
        try:
            self.sim.set_target(uid, pos, target.orientations, target.stamp_ns)
        except ValueError:
            return None  # refused (NaN, too many users): no output for this frame
        last = self._last_stamp.get(uid)
        dt = 1.0 / 30.0
        if last is not None and target.stamp_ns > last:
            dt = float(np.clip((target.stamp_ns - last) * 1e-9, 0.002, 0.2))
        self._last_stamp[uid] = target.stamp_ns
        self.sim.advance(dt)
        st = self.sim.state(uid)
        return SkeletonFrame(positions=st.positions_sensor.copy(),
                             tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                             reliability=np.asarray(target.reliability, np.float32).copy(),
                             orientations=st.orientations_sensor.copy(), user_id=uid,
                             stamp_ns=target.stamp_ns, frame_id=target.frame_id)


def make_physics(upstream: Optional[str] = 'C', controller: str = 'explicit_pd',
                 sensor_height: float = 0.8, sensor_pitch: float = 0.0, auto_floor: bool = False,
                 kp: Optional[float] = None, kd: Optional[float] = None, **upstream_params
                 ) -> PhysicsMethod:
    """Factory for the harness: ``upstream`` is a registered method name ('C' = the full
    reconstruction; None = physics on the raw stream), its parameters pass through."""
    from .controller import Gains
    g = Gains()
    if kp is not None:
        g.ke = float(kp)
    if kd is not None:
        g.kd = float(kd)
    cfg = SimConfig(controller=controller, gains=g, sensor_height=sensor_height,
                    sensor_pitch=sensor_pitch, auto_floor=auto_floor)
    up = None
    if upstream:
        from skeleton_eval import evaluation
        if upstream not in evaluation.available_methods():
            evaluation.load_plugins(('pose_reconstruction.methods',))
        up = evaluation.make_method(upstream, **upstream_params)
    name = 'physics' if upstream == 'C' else (f'physics_{upstream}' if upstream else 'physics_raw')
    return PhysicsMethod(upstream=up, config=cfg, name=name)


def register() -> bool:
    """Register ``physics`` (method C -> physics), ``physics_A`` (A -> physics) and
    ``physics_raw`` (raw stream -> physics) with the evaluation harness; False without it."""
    try:
        from skeleton_eval.evaluation import register_method
    except ImportError:
        return False
    import functools
    defaults = {'controller': 'explicit_pd', 'sensor_height': 0.8, 'auto_floor': False}
    register_method('physics', functools.partial(make_physics, 'C'),
                    'Shum et al. 2013 Sec. VII: method C, then the PD-tracked MuJoCo character',
                    defaults)
    register_method('physics_A', functools.partial(make_physics, 'A'),
                    'Shum & Ho 2012: method A (PCA completion), then the PD-tracked character',
                    defaults)
    register_method('physics_raw', functools.partial(make_physics, None),
                    'the PD-tracked MuJoCo character on the raw Kinect stream', defaults)
    return True


register()

__all__ = ['PhysicsMethod', 'make_physics', 'register']
