"""Physics controllers: how a world realises Eq. 1-2 (:mod:`physics_sim.controller`) on its
characters. Each is a :class:`~physics_sim.controllers.base.Controller` in a file of its own,
registered by name (:mod:`.registry`) (``SimConfig.controller``; ``auto`` picks between two of them).

Adding a controller = one new module with a ``Controller`` subclass decorated ``@register`` and its
import below.
"""
from __future__ import annotations

from .base import Controller
from .registry import controller_names, make_controller, register, unregister

# the built-in controllers (each registers itself)
from . import actuator_pd, explicit_pd, mocap_constraints  # noqa: E402,F401,I001

__all__ = ['Controller', 'register', 'unregister', 'controller_names', 'make_controller']
