"""Only the Kinect driver (e.g. on the PC the sensor is plugged into; the rest of the graph elsewhere).

    ros2 launch kinect_bringup driver.launch.py source:=live device_uri:=
    ros2 launch kinect_bringup driver.launch.py source:=replay replay_file:=out/demo.mcap
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description():
    config = os.path.join(get_package_share_directory('kinect_bringup'), 'config', 'driver.yaml')
    args = [('source', 'synthetic', 'synthetic | replay | live (or a registered source)'),
            ('replay_file', '', 'bag (.mcap) or CSV for source:=replay'),
            ('scenario', 'b', 'synthetic scenario class a | b | c'),
            ('num_users', '1', 'synthetic users (1-6)'),
            ('device_uri', '', 'live: OpenNI2 device URI or .oni file ("" = first device)'),
            ('nite2_path', '', 'live: NiTE2 Redist directory (libNiTE2.so, NiTE.ini, NiTE2/)')]
    types = {'num_users': int}
    overrides = {name: ParameterValue(LaunchConfiguration(name), value_type=types.get(name, str))
                 for name, _, _ in args}
    return LaunchDescription(
        [DeclareLaunchArgument(n, default_value=d, description=t) for n, d, t in args] + [
            Node(package='kinect_driver', executable='driver', name='driver', output='screen',
                 emulate_tty=True, parameters=[config, overrides]),
        ])
