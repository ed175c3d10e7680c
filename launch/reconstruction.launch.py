"""Only the reconstruction nodes (reliability, completion, optimizer), e.g. behind a live driver.

    ros2 launch kinect_bringup reconstruction.launch.py method:=C database:=cache/db.npz
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.parameter_descriptions import ParameterValue

from kinect_bringup.launch_nodes import managed_node


def generate_launch_description():
    config = os.path.join(get_package_share_directory('kinect_bringup'), 'config')
    db = {'database': ParameterValue(LaunchConfiguration('database'), value_type=str)}
    return LaunchDescription([
        DeclareLaunchArgument('method', default_value='C', description='optimizer method: B | C'),
        DeclareLaunchArgument('database', default_value='', description='database file ("" = default)'),
        managed_node(package='pose_reconstruction', executable='reliability', name='reliability',
             output='screen', parameters=[os.path.join(config, 'reliability.yaml')]),
        managed_node(package='pose_reconstruction', executable='completion', name='completion',
             output='screen', parameters=[os.path.join(config, 'completion.yaml'), db]),
        managed_node(package='pose_reconstruction', executable='optimizer', name='optimizer',
             output='screen', parameters=[os.path.join(config, 'optimizer.yaml'), db,
                                          {'method': ParameterValue(LaunchConfiguration('method'), value_type=str)}]),
    ])
