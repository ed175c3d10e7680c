"""Skeleton sources of the driver node (no rclpy): synthetic, replay, live (OpenNI2/NiTE2) and
azure_kinect (the Azure Kinect ROS driver's body markers),
and the registry the node picks its ``source`` parameter's value from.

Adding a source = one module with a :class:`~.base.Source` subclass (its parameters on a
``config_class`` dataclass declared with ``skeleton_core.params.param``) and its registration:
a line in :data:`BUILTIN` (a source of this package), an entry point of the group
``kinect_driver.sources`` (``name = package.module:Class``, a source of another package), or
:func:`register_source` (in-process, e.g. tests). The driver node, its parameters (each source's
become read-only ``driver`` parameters), the YAML file and docs/parameters.md follow from it.
"""
from __future__ import annotations

import functools
import importlib
from typing import Dict, List, Union

from .base import NoConfig, Source, SourceError, SourceOutput  # noqa: F401

ENTRY_POINT_GROUP = 'kinect_driver.sources'
# name -> 'module:Class' of the sources of this package (imported when used)
BUILTIN: Dict[str, str] = {
    'synthetic': 'kinect_driver.sources.synthetic:SyntheticSource',
    'replay': 'kinect_driver.sources.replay:ReplaySource',
    'live': 'kinect_driver.sources.openni_live:LiveSource',
    'azure_kinect': 'kinect_driver.sources.azure_kinect:AzureKinectSource',
}
_registered: Dict[str, Union[str, type]] = {}


def register_source(name: str, target: Union[str, type]) -> None:
    """Register (or replace) a source: a Source subclass or its ``'module:Class'`` path."""
    if not name or not isinstance(name, str):
        raise ValueError('a source needs a name')
    _registered[name] = target


@functools.lru_cache(maxsize=None)
def _entry_points() -> Dict[str, str]:
    """The installed packages' sources, read once per process (a scan of every installed
    distribution's metadata: ~40 ms, and the node's start asks for the table several times)."""
    from importlib.metadata import entry_points
    try:
        return {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)}
    except Exception:  # noqa: BLE001 - broken metadata must not stop the built-in sources
        return {}


def _table() -> Dict[str, Union[str, type]]:
    return {**BUILTIN, **_entry_points(), **_registered}


def source_names() -> List[str]:
    return list(_table())


def source_class(name: str) -> type:
    """The Source subclass registered as ``name`` (SourceError when there is none)."""
    target = _table().get(name)
    if target is None:
        raise SourceError(f'unknown source {name!r} (use one of {", ".join(source_names())})')
    if isinstance(target, str):
        module, _, attr = target.partition(':')
        try:
            target = getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError) as e:
            raise SourceError(f'source {name!r} ({module}:{attr}) cannot be loaded: {e}') from None
    if not (isinstance(target, type) and issubclass(target, Source)):
        raise SourceError(f'source {name!r} is not a Source subclass')
    return target
