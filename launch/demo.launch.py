"""`make demo`'s graph: pipeline.launch.py (every argument passes through), stopped cleanly on SIGUSR1.

    ros2 launch kinect_bringup demo.launch.py record:=out/demo.mcap scenario:=b

`kinect_bringup.demo` sends SIGUSR1 when it has recorded enough: launch shuts the graph down as on
Ctrl-C (SIGINT to every node, which closes its files), without the Ctrl-C notice in the graph
log. Anything else (Ctrl-C, another launch argument) behaves as with pipeline.launch.py.
"""
import asyncio
import os
import signal

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import IncludeLaunchDescription, OpaqueFunction
from launch.events import Shutdown
from launch.launch_description_sources import PythonLaunchDescriptionSource


def _stop_on_sigusr1(context):
    loop = asyncio.get_event_loop()
    loop.add_signal_handler(signal.SIGUSR1, lambda: context.emit_event_sync(
        Shutdown(reason='the demo has recorded enough')))
    return []


def generate_launch_description():
    pipeline = os.path.join(get_package_share_directory('kinect_bringup'), 'launch',
                            'pipeline.launch.py')
    return LaunchDescription([
        OpaqueFunction(function=_stop_on_sigusr1),
        IncludeLaunchDescription(PythonLaunchDescriptionSource(pipeline)),
    ])
