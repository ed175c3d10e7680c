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

The sources (``kinect_driver``'s ``driver``) are configured beside the other nodes but activated
last: each waits until every other managed node of the same launch is active (or has failed, or
``SOURCE_WAIT_S`` passed), so the reconstruction, physics and recorder take the first frame the
source publishes, and a recording holds every output from its first input frame. A launch of the
drivers alone (``driver.launch.py``) has nothing to wait for.

:func:`startup_profile`, first in a launch file's description, gives the launch and the processes
it starts the Fast DDS profile of the start (``kinect_bringup.dds_profile``) unless the user has
their own.
"""
from __future__ import annotations

import threading
import time
import weakref

import launch
from launch_ros.actions import LifecycleNode
from launch_ros.ros_adapters import get_ros_node

from skeleton_core.lifecycle_client import drive_to_active
from skeleton_core.rosnode import MANAGED_FLAG


# the nodes whose input is the sensor: activated once every other node of their launch is up
SOURCES = {('kinect_driver', 'driver')}
# a source waits at most this long for the others (a node stuck in a transition must not keep
# the sensor off for good); it is logged
SOURCE_WAIT_S = 60.0
# per launch context: {node name: Event set once that non-source node is active or has failed}
_CONSUMERS: 'weakref.WeakKeyDictionary' = weakref.WeakKeyDictionary()


def _wait_for_consumers(context, name: str, log) -> None:
    """Block until every non-source node of ``context`` is up (see the module's text)."""
    deadline = time.monotonic() + SOURCE_WAIT_S
    consumers = dict(_CONSUMERS.get(context, {}))
    for up in consumers.values():
        # woken as the node comes up (no poll interval added to the start); the shutdown and
        # the deadline checked every half second meanwhile
        while not up.wait(min(0.5, max(deadline - time.monotonic(), 0.0) + 0.01)):
            if context.is_shutdown:
                return
            if time.monotonic() > deadline:
                pending = sorted(n for n, e in consumers.items() if not e.is_set())
                log(f'{name}: activated although {", ".join(pending)} not active after '
                    f'{SOURCE_WAIT_S:.0f} s')
                return


class _ManagedNode(LifecycleNode):
    """A LifecycleNode whose launch drives it to active (see the module's text)."""

    def __init__(self, **kwargs):
        self._source = (kwargs.get('package'), kwargs.get('executable')) in SOURCES
        super().__init__(**kwargs)

    def execute(self, context: launch.LaunchContext):
        actions = super().execute(context)
        name = self.node_name
        logger = launch.logging.get_logger('kinect_bringup.lifecycle')
        ros_node = get_ros_node(context)
        stopped = lambda: context.is_shutdown  # noqa: E731
        start = time.monotonic()
        configured = []   # s after the start when the node was seen configured (inactive)

        def inactive() -> bool:
            configured.append(time.monotonic() - start)
            return False   # (did not wait: activated without asking the state again)

        def report(active: bool) -> None:
            if active:   # one line per node: the graph log says when the graph was up, and
                #          how long its configure and its activation took
                logger.info(f'{name} active {time.monotonic() - start:.1f} s after its start'
                            + (f' (configured after {configured[0]:.1f} s)' if configured
                               else ''))

        if self._source:
            def before_activate():
                inactive()
                _wait_for_consumers(context, name, logger.warning)

            def bring_up():
                report(drive_to_active(ros_node, name, stopped, logger.warning,
                                       before_activate=before_activate))
        else:
            up = _CONSUMERS.setdefault(context, {}).setdefault(name, threading.Event())

            def bring_up():
                try:
                    report(drive_to_active(ros_node, name, stopped, logger.warning,
                                           before_activate=inactive))
                finally:
                    up.set()   # active, or failed (logged): the sources do not wait for it
        threading.Thread(target=bring_up, name=f'bring-up {name}', daemon=True).start()
        return actions


def startup_profile() -> launch.actions.OpaqueFunction:
    """The Fast DDS profile of the start (:mod:`kinect_bringup.dds_profile`) set in the launch's
    environment (``context.environment`` is the launch process's: its own participant, made
    after this, and every process it starts get it), unless the user has their own profile."""
    def apply(context):
        from kinect_bringup.dds_profile import startup_profile_env
        return [launch.actions.SetEnvironmentVariable(name, value)
                for name, value in startup_profile_env(context.environment).items()]
    return launch.actions.OpaqueFunction(function=apply)


def managed_node(**kwargs) -> LifecycleNode:
    """``LifecycleNode(**kwargs)``, configured and activated by launch (``namespace`` defaults
    to '': a surrounding PushRosNamespace applies)."""
    kwargs.setdefault('namespace', '')
    kwargs['arguments'] = [MANAGED_FLAG] + list(kwargs.get('arguments', []))
    return _ManagedNode(**kwargs)


def rviz_node(config: str) -> launch.actions.OpaqueFunction:
    """RViz with ``config`` when the launch argument ``rviz`` is true: where RViz (``rviz2``) is
    not installed, one warning line and the graph runs without it (launch_ros would stop the
    whole launch on the missing package)."""
    def start(context):
        if launch.substitutions.LaunchConfiguration('rviz').perform(context).lower() \
                not in ('true', '1', 'yes'):
            return []
        from ament_index_python.packages import PackageNotFoundError, get_package_prefix
        try:
            get_package_prefix('rviz2')
        except PackageNotFoundError:
            launch.logging.get_logger('kinect_bringup').warning(
                'rviz:=true: RViz (rviz2) is not installed here; the graph runs without it '
                '(install ros-<distro>-rviz2, or run RViz on another PC of the same ROS_DOMAIN_ID)')
            return []
        from launch_ros.actions import Node
        return [Node(package='rviz2', executable='rviz2', name='rviz2', arguments=['-d', config],
                     output='screen')]
    return launch.actions.OpaqueFunction(function=start)
