"""Only the Kinect driver (e.g. on the PC the sensor is plugged into; the rest of the graph elsewhere).

    ros2 launch kinect_bringup driver.launch.py source:=live device_uri:=
    ros2 launch kinect_bringup driver.launch.py source:=replay replay_file:=out/demo.mcap
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.parameter_descriptions import ParameterValue

from kinect_bringup.launch_nodes import managed_node


def generate_launch_description():
    config = os.path.join(get_package_share_directory('kinect_bringup'), 'config', 'driver.yaml')
    from kinect_driver.driver_node import driver_params
    specs = {s.name: s for s in driver_params()}
    # the driver parameters users change most, as launch arguments (default, type and description
    # from the parameter declarations)
    names = ('source', 'replay_file', 'scenario', 'num_users', 'device_uri', 'nite2_path')
    args = [(n, str(specs[n].default), specs[n].description) for n in names]
    overrides = {n: ParameterValue(LaunchConfiguration(n), value_type=type(specs[n].default))
                 for n in names}
    return LaunchDescription(
        [DeclareLaunchArgument(n, default_value=d, description=t) for n, d, t in args] + [
            managed_node(package='kinect_driver', executable='driver', name='driver', output='screen',
                 emulate_tty=True, parameters=[config, overrides]),
        ])
