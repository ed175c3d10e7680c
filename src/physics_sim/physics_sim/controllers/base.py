"""The interface every physics controller implements (see :mod:`physics_sim.controllers`)."""
from __future__ import annotations

from typing import ClassVar


class Controller:
    """Drives the characters of one :class:`~physics_sim.world.World` towards their targets.

    A world calls :meth:`character_params` when it builds its MJCF (what the controller needs in
    the model: actuators, mocap bodies ...), :meth:`bind` after every (re)build, and
    :meth:`advance` to simulate ``nsteps`` time steps. The world offers what a controller needs:
    ``model`` / ``data``, ``config``, ``time``, the packed targets ``tg`` and their
    interpolation (``frame_shares``, ``targets_at``), the joint points (``joint_points``), Eq. 2
    (``twist_torques``), the foot pins (``pins.update``) and the pushes (``apply_pushes``)."""

    name: ClassVar[str] = ''
    # MuJoCo constraint solver for SimConfig.solver == 'auto': newton. pgs is as fast for one
    # character (a few floor contacts), but characters touching each other (users side by side)
    # give it tens of contacts a step: 2-3x the CPU per frame at 2-6 characters 0.8 m apart
    # (newton 3.4-5.5 against pgs 7.8-8.2 ms at two; 11 against 25-31 ms at six)
    solver: ClassVar[str] = 'newton'

    def character_params(self, config, params):
        """The MJCF parameters (``mjcf_body.CharacterParams``) of every character with this
        controller's features switched on, for ``config`` (``SimConfig``)."""
        return params

    def bind(self, world) -> None:
        """Look up this controller's ids in the world's freshly built model."""

    def targets_changed(self, world) -> None:
        """The world repacked its targets (every advance, a pin set by hand): forget what was
        derived from the old ones."""

    def advance(self, world, nsteps: int) -> None:
        """Simulate ``nsteps`` steps of ``world.model.opt.timestep``, setting ``world.time``."""
        raise NotImplementedError


__all__ = ['Controller']
