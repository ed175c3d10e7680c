"""The whole node graph: driver -> reconstruction -> physics -> viz.

    ros2 launch kinect_bringup pipeline.launch.py                      # synthetic source, method C
    ros2 launch kinect_bringup pipeline.launch.py source:=replay replay_file:=out/demo.mcap
    ros2 launch kinect_bringup pipeline.launch.py source:=live method:=A physics:=false rviz:=true
    ros2 launch kinect_bringup pipeline.launch.py control:=true world:=playground   # Ishigaki 2009
    ros2 launch kinect_bringup pipeline.launch.py sensors:=2                      # front + side, fused
    ros2 launch kinect_bringup pipeline.launch.py sensors:=2 drivers:=false       # drivers elsewhere

The reconstruction is one node (`reconstruction`: reliability, completion and optimizer without DDS
hops between them) or, with reconstruction:=split, the three nodes `reliability`, `completion` and
`optimizer`; both publish the same topics. Parameters come from the package's config/<node>.yaml
files (the same files the one-process `pipeline` executable reads); launch arguments override the
few that users change most. The sensor frame is on TF: ``static_tf`` publishes ``world ->
kinect_link`` from ``sensor_pose`` or an ``extrinsics`` file; the physics character is in ``world``.

Several sensors (``sensors:=N``): the drivers of ``driver.launch.py sensors:=N`` (``/kinect_k``,
frames ``kinect_k_link`` on TF) and the ``fusion`` node, which publishes their fused skeletons in
``world`` on ``/kinect/skeletons`` for the reconstruction. ``drivers:=false`` runs the graph
without the drivers and their frames: they run on the sensors' PCs (``driver.launch.py
sensors:=N``, same ROS_DOMAIN_ID), which publish the frames on TF.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, GroupAction, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node, PushRosNamespace
from skeleton_core.tf import DEFAULT_SENSOR_POSE

from kinect_bringup.launch_nodes import managed_node, rviz_node, startup_profile

ARGS = [
    # '' = keep the value from config/<node>.yaml
    ('source', '', 'skeleton source: synthetic | replay | live | azure_kinect (default: driver.yaml)'),
    ('replay_file', '', 'bag (.mcap) or CSV file for source:=replay'),
    ('device_uri', '', 'live: OpenNI2 device URI or .oni recording ("" = first device)'),
    ('nite2_path', '', 'live: NiTE2 Redist directory (never bundled; see docs/live_kinect.md)'),
    ('scenario', '', 'synthetic source scenario class (Shum 2013 Table IV): a | b | c; d: '
     'confident failures, e: small persistent errors of TRACKED joints'),
    ('num_users', '', 'synthetic source: number of users (1-6)'),
    ('seed', '', 'synthetic source: random seed'),
    ('database', '', 'motion database file ("" = cache/motion_db.npz, written by make build-db)'),
    ('method', '', 'reconstruction driving the character: A (completion) | B | C (optimizer); '
     'default: optimizer.yaml'),
    ('reconstruction', 'fused', 'fused: one reconstruction node; split: reliability, completion and '
     'optimizer nodes (same topics)'),
    ('input_tracker', '', 'skeleton tracker of the input, overriding the one the stream declares '
     'on /kinect/tracker (a replayed bag its own, live nite2, synthetic sensor_model): '
     'kinect_v2_sdk | nite2 | kinect_v1_sdk | azure_kinect_bt | sensor_model; the learned sensor correction '
     'for that tracker applies'),
    ('user_profile', '', 'user profile name (cache/profiles/<name>.json, from build_profile)'),
    ('physics', 'true', 'run the MuJoCo physics character'),
    ('control', 'false', 'performance-based control (Ishigaki 2009) between the reconstruction '
     'and the physics: the physics character tracks /control/target'),
    ('world', 'playground', 'control:=true: feature world (name in performance_control/config/'
     'worlds or a YAML path)'),
    ('start_feature', '', 'control:=true: feature a new character starts on ("" = the spawn)'),
    ('viz', 'true', 'run the RViz marker node'),
    ('rep155', 'false', 'publish REP-155 (ROS4HRI) bodies (hri node): /humans/bodies/tracked, per '
     'body its URDF, joint states and TF tree under body_<id> (docs/ros_outputs.md)'),
    ('rep155_source', 'reconstructed', 'whose bodies rep155 and joint_tf publish: reconstructed | '
     'character (the physics character)'),
    ('joint_tf', 'false', "openni2_tracker's TF frames per joint (head_1, left_hand_1, ...) of "
     'those bodies, under their skeleton frame'),
    ('rviz', 'false', 'start RViz with the bundled config'),
    ('record', '', 'record every pipeline topic to this MCAP file ("" = no recording)'),
    ('sensors', '1', 'number of sensors: N > 1 starts N drivers (driver.launch.py sensors:=N: '
     '/kinect_k/skeletons, frames kinect_k_link) and the fusion node, which publishes their fused '
     'skeletons in world on /kinect/skeletons'),
    ('drivers', 'true', 'run the driver(s) and publish their sensor frames here (false: they run '
     'on the sensor PCs, e.g. driver.launch.py sensors:=N, same ROS_DOMAIN_ID)'),
    ('sensor_pose', DEFAULT_SENSOR_POSE, 'the sensor\'s pose in world, on TF as world -> '
     'kinect_link: "x y z yaw pitch roll" (m, deg; positive pitch = tilted down); sensors:=N: ";" '
     'between the N poses (default: as driver.launch.py sensors:=N)'),
    ('extrinsics', '', 'sensor-pose YAML (hand-measured or from calibrate_extrinsics); '
     'overrides sensor_pose'),
    ('static_tf', 'true', 'publish the sensor frame(s) on /tf_static with the drivers (false: '
     'another launch does; with drivers:=false the drivers\' launch on the sensor PC does)'),
    ('record_split_size', '', 'record: start a new piece every this many MB (the recording '
     'becomes a folder of complete bags; "" = the recorder.yaml value, 0 = no size limit)'),
    ('record_split_duration', '', 'record: start a new piece every this many seconds ("" = the '
     'recorder.yaml value, 0 = no duration limit)'),
    ('namespace', '', 'namespace for all nodes'),
    ('config_dir', '', 'directory with <node>.yaml parameter files ("" = the installed config)'),
    ('log_level', 'info', 'log level of all nodes'),
]


def _nodes(context):
    def arg(name):
        return LaunchConfiguration(name).perform(context)

    def _split():
        out = {}
        for a, p in (('record_split_size', 'split_size_mb'),
                     ('record_split_duration', 'split_duration_s')):
            if arg(a):
                try:
                    out[p] = float(arg(a))
                except ValueError:
                    raise RuntimeError(f'{a}:={arg(a)!r} is not a number') from None
        return out

    config_dir = arg('config_dir') or os.path.join(
        get_package_share_directory('kinect_bringup'), 'config')

    def params(name, **overrides):
        out = []
        path = os.path.join(config_dir, f'{name}.yaml')
        if os.path.isfile(path):
            out.append(path)
        if overrides:
            out.append(overrides)
        return out

    method = arg('method').upper()
    if method not in ('', 'A', 'B', 'C'):
        raise RuntimeError(f"method:={arg('method')} is not one of A, B, C")
    common = dict(output='screen', emulate_tty=True,
                  arguments=['--ros-args', '--log-level', arg('log_level')])
    db = arg('database')
    db_over = {'database': db} if db else {}

    from kinect_driver.driver_node import driver_params
    driver_specs = {s.name: s for s in driver_params()}
    driver_over = {}
    for name in ('source', 'scenario', 'replay_file', 'device_uri', 'nite2_path', 'num_users',
                 'seed'):
        if arg(name):   # typed as declared
            driver_over[name] = type(driver_specs[name].default)(arg(name))
    opt_over = dict(db_over)
    # a recording's frames wait in the reconstruction's queues while it is busy, never lost
    from kinect_bringup.graph import QUEUED_READERS, replay_overrides, replays
    queued = replay_overrides(list(QUEUED_READERS)) if replays(arg('source'), config_dir) else {}
    tracker = arg('input_tracker') or {'live': 'nite2', 'synthetic': 'sensor_model'}.get(
        arg('source'), '')
    if tracker:
        opt_over['input_tracker'] = tracker
    if arg('user_profile'):
        opt_over['user_profile'] = arg('user_profile')
    if method in ('B', 'C'):
        opt_over['method'] = method
    # a replay holds its first frame until every node reading /kinect/skeletons is there
    from kinect_bringup.graph import skeleton_subscribers
    readers = ['reconstruction' if arg('reconstruction') == 'fused' else 'reliability']
    if arg('viz').lower() in ('true', '1', 'yes'):
        readers.append('viz')
    if arg('record'):
        readers.append('recorder')
    driver_over['wait_for_subscribers'] = skeleton_subscribers(readers, config_dir)
    try:
        sensors = int(arg('sensors'))
    except ValueError:
        raise RuntimeError(f"sensors:={arg('sensors')} is not a number") from None
    if not 1 <= sensors <= 8:
        raise RuntimeError(f'sensors:={sensors} must be 1 to 8')
    drivers = arg('drivers').lower() in ('true', '1', 'yes')
    nodes = []
    if drivers and sensors == 1:
        nodes.append(managed_node(package='kinect_driver', executable='driver', name='driver',
                                  parameters=params('driver', **driver_over), **common))
    elif drivers:
        nodes.append(_drivers(arg, sensors, config_dir))
    if sensors > 1:
        from skeleton_core.tf import sensor_namespace
        topics = [f'/{sensor_namespace(k, sensors)}/skeletons' for k in range(1, sensors + 1)]
        nodes.append(managed_node(package='pose_reconstruction', executable='fusion',
                                  name='fusion', parameters=params('fusion', input_topics=topics),
                                  **common))
    mode = arg('reconstruction')
    if mode == 'fused':
        from kinect_bringup.graph import load_params
        fused = load_params('reconstruction', config_dir)
        fused.update({f'optimizer.{k}' if k == 'method' else k: v for k, v in opt_over.items()})
        fused.update(queued.get('reconstruction', {}))
        nodes.append(managed_node(package='pose_reconstruction', executable='reconstruction',
                          name='reconstruction', parameters=[fused], **common))
    elif mode == 'split':
        nodes += [
            managed_node(package='pose_reconstruction', executable='reliability', name='reliability',
                 parameters=params('reliability', **queued.get('reliability', {})), **common),
            managed_node(package='pose_reconstruction', executable='completion', name='completion',
                 parameters=params('completion', **db_over, **queued.get('completion', {})),
                 **common),
            managed_node(package='pose_reconstruction', executable='optimizer', name='optimizer',
                 parameters=params('optimizer', **opt_over, **queued.get('optimizer', {})),
                 **common),
        ]
    else:
        raise RuntimeError(f'reconstruction:={mode} is not one of fused, split')
    posture_topic = ''
    if method:
        posture_topic = '/posture/completed' if method == 'A' else '/posture/reconstructed'
    control = arg('control').lower() in ('true', '1', 'yes')
    if control:
        ctl_over = {'world': arg('world'), 'start_feature': arg('start_feature')}
        if posture_topic:
            ctl_over['input_topic'] = posture_topic
        nodes.append(managed_node(package='performance_control', executable='control', name='control',
                          parameters=params('control', **ctl_over), **common))
    if arg('physics').lower() in ('true', '1', 'yes'):
        phys_over = {}
        if control:
            # the physics character gets the same world's features (static geometry) and grips
            # what the control node engages (/control/intention): one world file for both
            from performance_control.features import world_path
            phys_over['input_topic'] = '/control/target'
            phys_over['feature_world'] = str(world_path(arg('world')))
        elif posture_topic:
            phys_over['input_topic'] = posture_topic
        if drivers and sensors == 1 and arg('static_tf').lower() in ('true', '1', 'yes'):
            # its input's frame, published below: the physics takes input once TF has it
            phys_over['wait_for_frames'] = ['kinect_link']
        nodes.append(managed_node(package='physics_sim', executable='physics', name='physics',
                          parameters=params('physics', **phys_over), **common))
    if arg('viz').lower() in ('true', '1', 'yes'):
        nodes.append(managed_node(package='viz', executable='viz', name='viz',
                          parameters=params('viz'), **common))
    rep155, joint_tf = (arg(a).lower() in ('true', '1', 'yes') for a in ('rep155', 'joint_tf'))
    if rep155 or joint_tf:
        if arg('rep155_source') not in ('reconstructed', 'character'):
            raise RuntimeError(f"rep155_source:={arg('rep155_source')} is not one of "
                               'reconstructed, character')
        nodes.append(managed_node(package='viz', executable='hri', name='hri', parameters=params(
            'hri', rep155=rep155, openni_tf=joint_tf, source=arg('rep155_source')), **common))
    if arg('record'):
        # the outputs of the nodes started here: the recorder's input waits for them
        from kinect_bringup.graph import RECONSTRUCTION, TOPICS, load_params, recorded_outputs
        started = RECONSTRUCTION[mode] + [n for n in ('physics', 'viz')
                                          if arg(n).lower() in ('true', '1', 'yes')]
        recorded = load_params('recorder', config_dir).get('topics', list(TOPICS))
        if drivers and sensors == 1:
            # and the driver's topics: the recorder is active once it has met the driver, which
            # is activated last, so the recording holds the driver's first frame
            from kinect_driver.sources import SourceError, source_class
            source = driver_over.get('source') or load_params('driver', config_dir).get(
                'source', driver_specs['source'].default)
            try:
                truth = source_class(source).has_truth
            except SourceError:   # (the driver says so)
                truth = False
            recorded = [t for t in recorded if t != '/kinect/ground_truth' or truth]
            started = ['driver'] + started
        rec_over = dict(output=arg('record'), **_split())
        rec_over['wait_for_publishers'] = recorded_outputs(started, recorded) or ['']
        nodes.append(managed_node(package='kinect_bringup', executable='recorder', name='recorder',
                                  parameters=params('recorder', **rec_over), **common))
    if drivers and sensors == 1 and arg('static_tf').lower() in ('true', '1', 'yes'):
        # the sensor frame on TF (/tf_static is absolute: the namespace does not move it)
        from skeleton_core.tf import parse_pose
        try:
            parse_pose(arg('sensor_pose'))
        except ValueError as e:
            raise RuntimeError(str(e)) from None
        tf_args = ['--pose', arg('sensor_pose'), '--child', 'kinect_link']
        if arg('extrinsics'):
            tf_args += ['--file', arg('extrinsics')]
        nodes.append(Node(package='kinect_driver', executable='static_tf', name='static_tf',
                          arguments=tf_args, output='screen', emulate_tty=True))
    ns = arg('namespace')
    return [GroupAction(([PushRosNamespace(ns)] if ns else []) + nodes)]


def _drivers(arg, sensors: int, config_dir: str):
    """driver.launch.py sensors:=N: the N drivers and their frames on TF.

    Every argument of driver.launch.py is given explicitly: an included launch file's defaults
    do not apply to a name this launch already holds (its own ``sensor_pose`` default, one pose,
    and its ``''`` for the driver arguments it leaves to driver.yaml would reach it)."""
    from launch.actions import IncludeLaunchDescription
    from launch.launch_description_sources import PythonLaunchDescriptionSource
    from kinect_bringup.graph import load_params
    from kinect_driver.driver_node import driver_params
    # the default pose is one sensor's: '' lets driver.launch.py place the N sensors (front +
    # side, docs/multi_sensor.md); extrinsics:= then publishes its poses on TF over those
    pose = arg('sensor_pose')
    over = {'sensors': str(sensors), 'sensor': '', 'calibrate': '', 'static_tf': arg('static_tf'),
            'extrinsics': arg('extrinsics'),
            'sensor_pose': '' if pose.strip() == DEFAULT_SENSOR_POSE else pose}
    yaml_values = load_params('driver', config_dir)
    specs = {s.name: s for s in driver_params()}
    for name in ('source', 'replay_file', 'scenario', 'num_users', 'device_uri', 'nite2_path'):
        # '' = driver.yaml's value (driver.launch.py would take it as the value itself)
        value = arg(name) or yaml_values.get(name, specs[name].default)
        over[name] = str(value)
    path = os.path.join(get_package_share_directory('kinect_bringup'), 'launch', 'driver.launch.py')
    return IncludeLaunchDescription(PythonLaunchDescriptionSource(path),
                                    launch_arguments=over.items())


def generate_launch_description():
    rviz_config = os.path.join(get_package_share_directory('viz'), 'rviz', 'pipeline.rviz')
    return LaunchDescription(
        [startup_profile()] +
        [DeclareLaunchArgument(n, default_value=d, description=t) for n, d, t in ARGS] + [
            OpaqueFunction(function=_nodes),
            rviz_node(rviz_config),
        ])
