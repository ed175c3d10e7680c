"""The registry of physics controllers by name (see :mod:`physics_sim.controllers`)."""
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


__all__ = ['register', 'unregister', 'controller_names', 'make_controller']
