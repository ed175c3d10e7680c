"""Physics controllers: how a world realises Eq. 1-2 (:mod:`physics_sim.controller`) on its
characters. Each is a :class:`~physics_sim.controllers.base.Controller` in a file of its own,
registered here by name (``SimConfig.controller``; ``auto`` picks between two of them).

Adding a controller = one new module with a ``Controller`` subclass decorated ``@register`` and its
import below.
"""
from __future__ import annotations

from typing import Dict, Type

from .base import Controller

_REGISTRY: Dict[str, Type[Controller]] = {}


def register(cls: Type[Controller]) -> Type[Controller]:
    """Class decorator: make ``cls`` available as ``SimConfig(controller=cls.name)``."""
    name = getattr(cls, 'name', '')
    if not name or name == 'auto':
        raise ValueError(f'a controller needs a name other than "auto", got {name!r}')
    if not (isinstance(cls, type) and issubclass(cls, Controller)):
        raise TypeError(f'{cls!r} is not a Controller')
    _REGISTRY[name] = cls
    return cls


def unregister(name: str) -> None:
    """Remove a registered controller (tests registering their own)."""
    _REGISTRY.pop(name, None)


def controller_names() -> tuple:
    return tuple(_REGISTRY)


def make_controller(name: str) -> Controller:
    try:
        return _REGISTRY[name]()
    except KeyError:
        raise ValueError(f'unknown controller {name!r} (registered: {controller_names()})') from None


# the built-in controllers (each registers itself)
from . import explicit_pd, actuator_pd, mocap_constraints  # noqa: E402,F401

__all__ = ['Controller', 'register', 'unregister', 'controller_names', 'make_controller']
