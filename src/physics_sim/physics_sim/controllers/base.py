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
    # MuJoCo constraint solver for SimConfig.solver == 'auto'
    solver: ClassVar[str] = 'pgs'

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
