"""The launch files' nodes are lifecycle nodes that the launch file configures and activates.

:func:`managed_node` is a ``launch_ros`` ``LifecycleNode`` with ``autostart``: launch emits the
``configure`` transition once the node's lifecycle services are up and ``activate`` once it is
inactive (launch_ros ``LifecycleTransition``, the same in Jazzy and Kilted). The node is started
with ``--managed`` (``skeleton_core.rosnode.MANAGED_FLAG``) so that it waits for these
transitions instead of taking them itself as ``ros2 run`` does. A failed configure (a missing
database: one line naming ``make build-db``) leaves that node unconfigured; fix the parameter and
``ros2 lifecycle set /NODE configure`` (or call its ``~/change_state`` service), then ``activate``.
"""
from __future__ import annotations

from launch_ros.actions import LifecycleNode

from skeleton_core.rosnode import MANAGED_FLAG


def managed_node(**kwargs) -> LifecycleNode:
    """``LifecycleNode(**kwargs)``, configured and activated by launch (``namespace`` defaults
    to '': a surrounding PushRosNamespace applies)."""
    kwargs.setdefault('namespace', '')
    kwargs['arguments'] = [MANAGED_FLAG] + list(kwargs.get('arguments', []))
    return LifecycleNode(autostart=True, **kwargs)
