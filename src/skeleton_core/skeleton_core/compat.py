"""What differs between the ROS 2 distributions the project runs on, on the Python side, in one
place (the shell side: scripts/distro.sh). Tested on Jazzy (the default) and Kilted, each in CI;
Humble runs by hand on a system install.

- DDS discovery on this machine only: ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` from Iron on,
  ``ROS_LOCALHOST_ONLY=1`` on Humble (Jazzy and later deprecate it and warn when it is set).
- ``rclpy.experimental.EventsExecutor``: Jazzy and later; Humble has none.

The rclpy API the nodes use (nodes, parameters with descriptors, raw subscriptions, serialization,
the single- and multi-threaded executors, ``rclpy.init(domain_id=)``) is the same on Jazzy 7.1 and
Kilted 9.1, which tests/test_compat.py checks on whichever distro runs the suite.
Imports rclpy only inside the functions that need it (a library module never does at import).
"""
from __future__ import annotations

import os
from typing import Dict, MutableMapping, Optional

LEGACY_LOCALHOST_DISTROS = ('foxy', 'galactic', 'humble')   # no ROS_AUTOMATIC_DISCOVERY_RANGE


def ros_distro(environ: Optional[MutableMapping[str, str]] = None) -> str:
    """The ROS 2 distro of this environment (``ROS_DISTRO``, set by scripts/env.sh and by every
    system ROS 2), lower case; '' when unknown."""
    env = os.environ if environ is None else environ
    return env.get('ROS_DISTRO', '').strip().lower()


def localhost_discovery_env(distro: str) -> Dict[str, Optional[str]]:
    """The environment that keeps DDS discovery on this machine on ``distro``: variable -> value,
    ``None`` meaning "unset it" (a deprecated variable that would only warn)."""
    if distro in LEGACY_LOCALHOST_DISTROS:
        return {'ROS_LOCALHOST_ONLY': '1', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}
    return {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_LOCALHOST_ONLY': None}


def apply_localhost_discovery(environ: Optional[MutableMapping[str, str]] = None) -> None:
    """Set :func:`localhost_discovery_env` for this environment's distro in ``environ`` (default
    ``os.environ``): call before rclpy is initialised or a ROS process is started."""
    env = os.environ if environ is None else environ
    for key, value in localhost_discovery_env(ros_distro(env)).items():
        if value is None:
            env.pop(key, None)
        else:
            env[key] = value


def events_executor(**kwargs):
    """A new ``rclpy.experimental.EventsExecutor(**kwargs)`` (e.g. ``context=``); RuntimeError
    with the reason on a distro without one (Humble)."""
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError as e:
        raise RuntimeError('the events executor needs rclpy.experimental.EventsExecutor '
                           f'(ROS 2 Jazzy or newer; this is {ros_distro() or "an unknown distro"})') from e
    return EventsExecutor(**kwargs)
