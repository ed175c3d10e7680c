"""The launch files' nodes are lifecycle nodes that the launch file configures and activates.

:func:`managed_node` is a ``launch_ros`` ``LifecycleNode`` started with ``--managed``
(``skeleton_core.rosnode.MANAGED_FLAG``), so that it waits for its transitions instead of taking
them itself as ``ros2 run`` does; launch then takes it to ``active`` through its lifecycle
services with :func:`skeleton_core.lifecycle_client.drive_to_active` (state queried, the next
transition requested, until active). That replaces launch_ros's ``autostart``, which waits for
the node's ``transition_event`` message before it sends ``activate``: on a loaded machine that
message or a service reply can be lost while DDS is still matching, and the node then stayed
inactive. A failed configure (a missing database: one line naming ``make build-db``) leaves that
node unconfigured; fix the parameter and ``ros2 lifecycle set /NODE configure`` (or call its
``~/change_state`` service), then ``activate``.
"""
from __future__ import annotations

import threading

import launch
from launch_ros.actions import LifecycleNode
from launch_ros.ros_adapters import get_ros_node

from skeleton_core.lifecycle_client import drive_to_active
from skeleton_core.rosnode import MANAGED_FLAG


class _ManagedNode(LifecycleNode):
    """A LifecycleNode whose launch drives it to active (see the module's text)."""

    def execute(self, context: launch.LaunchContext):
        actions = super().execute(context)
        name = self.node_name
        logger = launch.logging.get_logger('kinect_bringup.lifecycle')
        threading.Thread(target=drive_to_active, name=f'bring-up {name}', daemon=True,
                         args=(get_ros_node(context), name, lambda: context.is_shutdown,
                               logger.warning)).start()
        return actions


def managed_node(**kwargs) -> LifecycleNode:
    """``LifecycleNode(**kwargs)``, configured and activated by launch (``namespace`` defaults
    to '': a surrounding PushRosNamespace applies)."""
    kwargs.setdefault('namespace', '')
    kwargs['arguments'] = [MANAGED_FLAG] + list(kwargs.get('arguments', []))
    return _ManagedNode(**kwargs)
