"""Reconstruction methods the evaluation runs: the plug-in interface and the registry.

Plug-in interface
-----------------
A method is any object with ``name``, ``reset()`` and ``process(frame: SkeletonFrame) ->
SkeletonFrame`` (streaming, one user, frames in the sensor frame as the driver publishes them;
returning ``None`` means "no output yet" and counts as a missing frame). Factories are registered with
:func:`register_method` (``factory(**params) -> Method``); :func:`available_methods` lists them.
Registered here: the baselines of :mod:`.baselines`, ``raw`` (the Kinect skeleton as is),
``holt`` (Kinect SDK v1 joint filter) and ``one_euro``. ``pose_reconstruction.methods``
registers A, B, C and ``physics_sim.methods`` its physics variants when imported
(:func:`load_plugins`).
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Protocol, Sequence, runtime_checkable

from skeleton_core.conversions import SkeletonFrame
from skeleton_core.filters import HOLT_DEFAULTS, ONE_EURO_DEFAULTS
from .baselines import HoltMethod, OneEuroMethod, RawMethod


@runtime_checkable
class Method(Protocol):
    name: str

    def reset(self) -> None: ...

    def process(self, frame: SkeletonFrame) -> Optional[SkeletonFrame]: ...


@dataclass
class _Entry:
    factory: Callable[..., Method]
    description: str
    defaults: Dict


_REGISTRY: Dict[str, _Entry] = {}


def register_method(name: str, factory: Callable[..., Method], description: str = '',
                    defaults: Optional[Dict] = None) -> None:
    """Register (or replace) a method factory under ``name``."""
    if not name or not callable(factory):
        raise ValueError('register_method needs a name and a callable factory')
    _REGISTRY[name] = _Entry(factory, description, dict(defaults or {}))


def available_methods() -> List[str]:
    return list(_REGISTRY)


def method_info(name: str) -> Dict:
    e = _REGISTRY[name]
    return {'description': e.description, 'defaults': e.defaults}


def make_method(name: str, **params) -> Method:
    if name not in _REGISTRY:
        raise KeyError(f'unknown method {name!r}; available: {", ".join(available_methods())}')
    return _REGISTRY[name].factory(**params)


PLUGIN_MODULES = ('pose_reconstruction.methods', 'physics_sim.methods')


def load_plugins(modules: Sequence[str] = PLUGIN_MODULES) -> Dict[str, str]:
    """Import plug-in modules that register methods; returns {module: 'ok' | reason skipped}."""
    status = {}
    for mod in modules:
        try:
            importlib.import_module(mod)
            status[mod] = 'ok'
        except ImportError as exc:
            status[mod] = f'skipped ({exc})'
        except Exception as exc:  # a broken plug-in must not take the harness down
            status[mod] = f'failed ({type(exc).__name__}: {exc})'
    return status


register_method('raw', RawMethod, 'Kinect skeleton as reported (no processing)')
register_method('holt', HoltMethod, 'Kinect SDK v1 joint filter (Holt double exponential)',
                HOLT_DEFAULTS)
register_method('one_euro', OneEuroMethod, 'One Euro filter (Casiez et al. 2012)',
                ONE_EURO_DEFAULTS)
