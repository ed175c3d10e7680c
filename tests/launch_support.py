"""What the launch_pytest modules of this suite share: launch_pytest itself (``make setup`` builds
the launch tooling, so these tests run everywhere and never skip) and :func:`include`, one of
kinect_bringup's launch files as installed, with its arguments (values as strings, as on the
command line)."""
import os

import launch_pytest  # noqa: F401  (re-exported: the modules' fixtures and actions)
from ament_index_python.packages import get_package_share_directory
from launch.actions import IncludeLaunchDescription
from launch.launch_description_sources import PythonLaunchDescriptionSource

SHARE = get_package_share_directory('kinect_bringup')


def include(name: str, **args) -> IncludeLaunchDescription:
    """``ros2 launch kinect_bringup NAME key:=value ...`` as an action of a launch description."""
    return IncludeLaunchDescription(
        PythonLaunchDescriptionSource(os.path.join(SHARE, 'launch', name)),
        launch_arguments={k: str(v) for k, v in args.items()}.items())
