"""The Kinect driver(s) and the sensor frames on TF (e.g. on the PC the sensors are plugged into;
the rest of the graph elsewhere).

    ros2 launch kinect_bringup driver.launch.py source:=live device_uri:=
    ros2 launch kinect_bringup driver.launch.py source:=replay replay_file:=out/demo.mcap
    ros2 launch kinect_bringup driver.launch.py sensor_pose:="0 0 1.1 0 10 0"      # 1.1 m, tilted
    ros2 launch kinect_bringup driver.launch.py sensors:=2                          # front + side
    ros2 launch kinect_bringup driver.launch.py sensors:=2 calibrate:=cache/extrinsics.yaml
    ros2 launch kinect_bringup driver.launch.py sensors:=2 extrinsics:=cache/extrinsics.yaml
    ros2 launch kinect_bringup driver.launch.py sensors:=2 sensor:=2   # only sensor 2 (its PC)

One sensor (``sensors:=1``, the default): node ``/driver`` on ``/kinect/skeletons``, frame
``kinect_link``. N sensors: node ``/kinect_k/driver`` on ``/kinect_k/skeletons`` (and
``/kinect_k/ground_truth``), frame ``kinect_k_link``, for k = 1..N. A ``static_tf`` node publishes
``world -> <sensor frame>`` for every sensor in one latched ``/tf_static`` message, from
``sensor_pose`` (``x y z yaw pitch roll``, m and degrees, ``;`` between sensors) or, overriding
it, a sensor-pose YAML (``extrinsics``: hand-measured or written by ``calibrate_extrinsics``).
With the synthetic source every driver simulates the same people seen from its own pose (the
``sensor_pose`` poses: the simulated truth even when ``extrinsics`` publishes an estimate).
``replay_file`` takes one file per sensor, ``;``-separated. Docs: docs/multi_sensor.md.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from kinect_bringup.launch_nodes import managed_node, startup_profile

DRIVER_ARGS = ('source', 'replay_file', 'scenario', 'num_users', 'device_uri', 'nite2_path')
FRAME_ARGS = [
    ('sensors', '1', 'number of sensors (one driver each; 1 keeps /kinect/skeletons and '
     'kinect_link, N puts driver k in namespace /kinect_k with frame kinect_k_link)'),
    ('sensor', '', 'sensors:=N: run only sensor k of the N (its driver and its frame on TF), e.g. '
     'one per PC: sensor:=1 on the first sensor PC, sensor:=2 on the second ("" = all N)'),
    ('sensor_pose', '', 'pose of each sensor in world: "x y z yaw pitch roll" (m, deg; positive '
     'pitch = tilted down), ";" between sensors; "" = 0.8 m above the floor at the origin, and '
     'for N sensors the others 90 deg apart around the play space (front + side)'),
    ('extrinsics', '', 'sensor-pose YAML (hand-measured or from calibrate_extrinsics); its frames '
     'override sensor_pose on TF'),
    ('static_tf', 'true', 'publish the sensor frames on /tf_static (false: another launch does)'),
    ('calibrate', '', 'sensors:=N: record 12 s of one person walking round a loop in the shared '
     'view and write the calibrated sensor poses to this YAML (calibrate_extrinsics --live); '
     'relaunch with extrinsics:=THAT_FILE'),
]


def _sensors(context):
    from kinect_driver.driver_node import driver_params
    from skeleton_core.tf import (default_sensor_poses, format_pose, parse_pose, sensor_frame,
                                  sensor_namespace)

    def arg(name):
        return LaunchConfiguration(name).perform(context)

    try:
        n = int(arg('sensors'))
    except ValueError:
        raise RuntimeError(f"sensors:={arg('sensors')} is not a number") from None
    if not 1 <= n <= 8:
        raise RuntimeError(f'sensors:={n} must be 1 to 8')
    mine = list(range(1, n + 1))
    if arg('sensor'):
        try:
            mine = [int(arg('sensor'))]
        except ValueError:
            raise RuntimeError(f"sensor:={arg('sensor')} is not a number") from None
        if not 1 <= mine[0] <= n:
            raise RuntimeError(f'sensor:={mine[0]} must be 1 to sensors:={n}')
    text = arg('sensor_pose').strip()
    if text:
        parts = [p for p in text.split(';') if p.strip()]
        if len(parts) != n:
            raise RuntimeError(f'sensor_pose has {len(parts)} pose(s) for sensors:={n}')
        try:
            poses = [parse_pose(p) for p in parts]
        except ValueError as e:
            raise RuntimeError(str(e)) from None
    else:
        poses = default_sensor_poses(n)
    config = os.path.join(get_package_share_directory('kinect_bringup'), 'config', 'driver.yaml')
    specs = {s.name: s for s in driver_params()}
    over = {}
    for name in DRIVER_ARGS:   # typed as declared
        if name != 'replay_file':
            over[name] = type(specs[name].default)(arg(name))
    replays = [p.strip() for p in arg('replay_file').split(';')]
    if over['source'] == 'replay' and n > 1 and len(replays) != n:
        raise RuntimeError(f'replay_file needs {n} files (";"-separated) for sensors:={n}')
    actions = []
    first_inv = poses[0].inverse()
    for k in mine:
        frame = sensor_frame(k, n)
        params = dict(over, frame_id=frame,
                      replay_file=replays[k - 1] if len(replays) >= k else replays[0])
        ns = sensor_namespace(k, n)
        remap = []
        if ns:
            # this sensor's pose relative to the first: the synthetic people face the first
            params['view_pose'] = format_pose(first_inv * poses[k - 1])
            remap = [('/kinect/skeletons', f'/{ns}/skeletons'),
                     ('/kinect/ground_truth', f'/{ns}/ground_truth')]
        actions.append(managed_node(package='kinect_driver', executable='driver', name='driver',
                                    namespace=ns or '', output='screen', emulate_tty=True,
                                    parameters=[config, params], remappings=remap))
    if arg('calibrate'):
        if n < 2:
            raise RuntimeError('calibrate:= needs sensors:=2 or more')
        actions.append(Node(package='kinect_bringup', executable='calibrate_extrinsics',
                            name='calibrate_extrinsics', output='screen', emulate_tty=True,
                            arguments=['--live', str(n), '--duration', '12',
                                       '--out', arg('calibrate')]))
    if arg('static_tf').lower() in ('true', '1', 'yes'):
        tf_args = []
        for k in mine:
            tf_args += ['--pose', format_pose(poses[k - 1]), '--child', sensor_frame(k, n)]
        if arg('extrinsics'):
            tf_args += ['--file', arg('extrinsics')]
        # (one per PC with sensor:=k: a name of its own)
        name = f'static_tf_{mine[0]}' if arg('sensor') else 'static_tf'
        actions.append(Node(package='kinect_driver', executable='static_tf', name=name,
                            output='screen', emulate_tty=True, arguments=tf_args))
    return actions


def generate_launch_description():
    from kinect_driver.driver_node import driver_params
    specs = {s.name: s for s in driver_params()}
    # the driver parameters users change most, as launch arguments (default, type and description
    # from the parameter declarations)
    args = [(n, str(specs[n].default), specs[n].description) for n in DRIVER_ARGS]
    return LaunchDescription(
        [startup_profile()] +
        [DeclareLaunchArgument(n, default_value=d, description=t)
         for n, d, t in args + FRAME_ARGS] + [OpaqueFunction(function=_sensors)])
