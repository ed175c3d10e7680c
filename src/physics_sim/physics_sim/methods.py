"""The physics character as an evaluation method: (reconstruction ->) physics tracking.

``PhysicsMethod`` follows the evaluation harness's ``Method`` protocol (``name``, ``reset()``,
``process(frame: SkeletonFrame) -> SkeletonFrame``): every input frame becomes the target of the
character of ``frame.user_id``; the simulation advances by the stamp difference to the previous
frame (1/30 s when unknown) and the simulated joint positions/orientations are returned in the
input's frame, with the input's stamp, user id and frame id.

:func:`register` adds it to ``skeleton_core.evaluation`` (import guarded: this module works
without the harness). The evaluation harness's clips are in a world frame with the floor at z = 0
or in a sensor frame; ``auto_floor`` puts the floor under the first frame's lowest foot in both.
"""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS, TRACKED

from .simulation import SimConfig, Simulation

UPSTREAM_CANDIDATES = ('reconstruction', 'optimizer', 'completion')


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

    def process(self, frame: SkeletonFrame) -> SkeletonFrame:
        target = self.upstream.process(frame) if self.upstream is not None else frame
        uid = int(target.user_id)
        self.sim.set_target(uid, target.positions, target.orientations, target.stamp_ns)
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


def _upstream_factory(evaluation) -> Optional[Callable[[], object]]:
    """A factory of the reconstruction method from the harness's registry, if it has one."""
    for getter in ('make_method', 'create_method', 'get_method'):
        fn = getattr(evaluation, getter, None)
        if fn is None:
            continue
        for name in UPSTREAM_CANDIDATES:
            try:
                m = fn(name)
            except Exception:  # noqa: BLE001 -- unknown name or signature: try the next
                continue
            if m is not None:
                return (lambda fn=fn, name=name: fn(name)) if not callable(m) or hasattr(m, 'process') \
                    else m
    return None


def register() -> bool:
    """Register ``physics`` (reconstruction -> physics) and ``physics_raw`` with the evaluation
    harness. Returns False when the harness is not installed."""
    try:
        from skeleton_core import evaluation
    except ImportError:
        return False
    reg = getattr(evaluation, 'register_method', None)
    if reg is None:
        return False
    up = _upstream_factory(evaluation)

    def physics():
        return PhysicsMethod(upstream=up() if up is not None else None)

    def physics_raw():
        return PhysicsMethod(upstream=None, name='physics_raw')

    for name, factory in (('physics', physics), ('physics_raw', physics_raw)):
        try:
            reg(name, factory)
        except Exception:  # noqa: BLE001 -- already registered / different signature
            pass
    return True


register()

__all__ = ['PhysicsMethod', 'register']
