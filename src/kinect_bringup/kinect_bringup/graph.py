"""The node graph as data, shared by the launch file's users, the one-process ``pipeline``, the demo
and the benchmark: which nodes exist, where their parameter files are, and the topics between them.
No rclpy at import time.

The reconstruction runs either as one ``reconstruction`` node (default: no DDS hops inside it) or
as the three nodes ``reliability``, ``completion`` and ``optimizer`` (``split``); the fused node has
no YAML file of its own: its parameters are the three files' values, prefixed (see
:func:`load_params`)."""
from __future__ import annotations

import importlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional

import yaml


@dataclass(frozen=True)
class NodeInfo:
    name: str          # node name (also the config file stem)
    package: str
    executable: str
    module: str        # python module holding the Node subclass


NODES: Dict[str, NodeInfo] = {n.name: n for n in (
    NodeInfo('driver', 'kinect_driver', 'driver', 'kinect_driver.driver_node'),
    NodeInfo('fusion', 'pose_reconstruction', 'fusion', 'pose_reconstruction.fusion_node'),
    NodeInfo('reliability', 'pose_reconstruction', 'reliability', 'pose_reconstruction.reliability_node'),
    NodeInfo('completion', 'pose_reconstruction', 'completion', 'pose_reconstruction.completion_node'),
    NodeInfo('optimizer', 'pose_reconstruction', 'optimizer', 'pose_reconstruction.optimizer_node'),
    NodeInfo('reconstruction', 'pose_reconstruction', 'reconstruction',
             'pose_reconstruction.reconstruction_node'),
    NodeInfo('control', 'performance_control', 'control', 'performance_control.control_node'),
    NodeInfo('physics', 'physics_sim', 'physics', 'physics_sim.physics_node'),
    NodeInfo('viz', 'viz', 'viz', 'viz.viz_node'),
    NodeInfo('hri', 'viz', 'hri', 'viz.hri_node'),
    NodeInfo('recorder', 'kinect_bringup', 'recorder', 'kinect_bringup.recorder'),
)}

# Topics of the graph and their types (the recorder's default list)
TOPICS: Dict[str, str] = {
    '/kinect/skeletons': 'skeleton_msgs/msg/SkeletonArray',
    '/kinect/ground_truth': 'skeleton_msgs/msg/SkeletonArray',
    '/kinect/tracker': 'std_msgs/msg/String',   # latched: the stream's skeleton tracker
    '/kinect/skeletons_reliability': 'skeleton_msgs/msg/SkeletonArray',
    '/posture/completed': 'skeleton_msgs/msg/SkeletonArray',
    '/posture/reconstructed': 'skeleton_msgs/msg/SkeletonArray',
    '/character/skeletons': 'skeleton_msgs/msg/SkeletonArray',
    '/viz/markers': 'visualization_msgs/msg/MarkerArray',
    '/tf_static': 'tf2_msgs/msg/TFMessage',   # the sensor frames (the character is in world)
}


# The graph's input, the driver's topics: the recorder subscribes to them last (once the outputs'
# publishers are there), and a recording holds them from the driver's first frame
INPUTS = ('/kinect/skeletons', '/kinect/ground_truth')

# The recorded topics each node publishes (the recorder waits for them before its input, and for
# the driver's before it is active)
OUTPUTS: Dict[str, List[str]] = {
    'driver': list(INPUTS),
    'reliability': ['/kinect/skeletons_reliability'],
    'completion': ['/posture/completed'],
    'optimizer': ['/posture/reconstructed'],
    'reconstruction': ['/kinect/skeletons_reliability', '/posture/completed',
                       '/posture/reconstructed'],
    'physics': ['/character/skeletons'],
    'viz': ['/viz/markers'],
}


def recorded_outputs(names: List[str], recorded_topics: List[str]) -> List[str]:
    """The topics of ``recorded_topics`` that the graph's nodes ``names`` publish, in the
    recorder's order: its subscriptions to the outputs match before it subscribes to the input
    (:data:`INPUTS`), and those to the input before it is active."""
    published = {t for n in names for t in OUTPUTS.get(n, [])}
    return [t for t in recorded_topics if t in published]


def repo_root() -> Optional[Path]:
    env = os.environ.get('KINECT_POSTURE_ROOT')
    if env and (Path(env) / 'config').is_dir():
        return Path(env)
    here = Path(__file__).resolve()
    for parent in here.parents:
        if (parent / 'config').is_dir() and (parent / 'src').is_dir():
            return parent
    return None


def config_dir() -> Path:
    """The YAML parameter files: the installed share/kinect_bringup/config, else the repo's."""
    try:
        from ament_index_python.packages import get_package_share_directory
        d = Path(get_package_share_directory('kinect_bringup')) / 'config'
        if d.is_dir():
            return d
    except Exception:  # noqa: BLE001 - not installed: fall back to the source tree
        pass
    root = repo_root()
    if root is None:
        raise FileNotFoundError('cannot find the config/ directory (run scripts/setup.sh)')
    return root / 'config'


def preset_path(name: str) -> Path:
    """The preset file ``name``: a path, or a name in config/presets (``shum2013``). Raises
    FileNotFoundError (one line, with the presets there are) when there is none."""
    p = Path(name).expanduser()
    if p.suffix in ('.yaml', '.yml') and p.is_file():
        return p
    d = config_dir() / 'presets'
    p = d / f'{name}.yaml'
    if p.is_file():
        return p
    have = sorted(f.stem for f in d.glob('*.yaml')) if d.is_dir() else []
    raise FileNotFoundError(f'no preset {name!r} (a .yaml path or one of {have} in {d})')


def params_file(node: str, directory: Optional[Path] = None) -> Optional[Path]:
    p = Path(directory or config_dir()) / f'{node}.yaml'
    return p if p.is_file() else None


def load_params(node: str, directory: Optional[Path] = None) -> Dict:
    """The ros__parameters of ``node`` as the launch file would apply them (``/**`` and the node's
    own key merged, the node's key winning). For ``reconstruction`` (no file of its own): the
    reliability, completion and optimizer files mapped onto its prefixed names."""
    if node == 'reconstruction' and params_file(node, directory) is None:
        from pose_reconstruction.reconstruction_node import fused_parameters
        return fused_parameters(*(load_params(n, directory)
                                  for n in ('reliability', 'completion', 'optimizer')))
    path = params_file(node, directory)
    if path is None:
        return {}
    with open(path) as f:
        data = yaml.safe_load(f) or {}
    out: Dict = {}
    for key in ('/**', node, f'/{node}', f'/**/{node}'):
        section = data.get(key) or {}
        out.update(section.get('ros__parameters') or {})
    return out


def node_class(name: str):
    """The rclpy Node subclass implemented in the node's module."""
    from rclpy.node import Node
    mod = importlib.import_module(NODES[name].module)
    found = [v for v in vars(mod).values()
             if isinstance(v, type) and issubclass(v, Node) and v is not Node
             and v.__module__ == mod.__name__]
    if len(found) != 1:
        raise RuntimeError(f'{mod.__name__} must define exactly one Node subclass, found {found}')
    return found[0]


def skeleton_subscribers(names: List[str], directory: Optional[Path] = None,
                         recorded_topics: Optional[List[str]] = None) -> int:
    """How many of the graph's nodes ``names`` subscribe to /kinect/skeletons: the driver's replay
    waits for that many before its first frame (nothing lost while the graph comes up)."""
    n = 0
    for name in names:
        if name in ('reconstruction', 'reliability'):
            n += 1
        elif name == 'viz':
            n += bool(load_params('viz', directory).get('show_raw', True))
        elif name == 'recorder':
            topics = recorded_topics if recorded_topics is not None else \
                load_params('recorder', directory).get('topics', list(TOPICS))
            n += '/kinect/skeletons' in topics
    return n


# A replayed recording is played at its recorded speed, whatever its readers can take: the
# reconstruction's input queue (qos_depth 10) holds a third of a second, so a node held up for
# longer (a loaded machine) lost the frames behind it. A recording's readers queue its frames
# instead (the ROS QoS override of their input's depth): they fall behind and catch up, and every
# frame of the file is reconstructed. 33 s of frames at 30 Hz
REPLAY_QUEUE_DEPTH = 1000
# the reconstruction nodes' input topics (their input_topic defaults)
QUEUED_READERS = {'reconstruction': '/kinect/skeletons', 'reliability': '/kinect/skeletons',
                  'completion': '/kinect/skeletons_reliability', 'optimizer': '/posture/completed'}


def replay_overrides(names: List[str]) -> Dict[str, Dict]:
    """Per-node parameter overrides of the graph ``names`` when the source is a recording (the
    driver's ``source`` replay): the reconstruction nodes' input queues deep enough that a busy
    node delays the recording's frames instead of losing them."""
    return {n: {f'qos_overrides.{QUEUED_READERS[n]}.subscription.depth': REPLAY_QUEUE_DEPTH}
            for n in names if n in QUEUED_READERS}


def replays(source: str, directory: Optional[Path] = None) -> bool:
    """Whether the driver plays a recording: ``source`` (a launch argument; '' = the driver's
    YAML value) is replay."""
    if not source:
        source = str(load_params('driver', directory).get('source', ''))
    return source == 'replay'


RECONSTRUCTION = {'fused': ['reconstruction'],
                  'split': ['reliability', 'completion', 'optimizer']}


def graph_nodes(method: str = 'C', physics: bool = True, viz: bool = True,
                record: bool = False, reconstruction: str = 'fused') -> List[str]:
    if reconstruction not in RECONSTRUCTION:
        raise ValueError(f'reconstruction must be one of {list(RECONSTRUCTION)}')
    names = ['driver'] + RECONSTRUCTION[reconstruction]
    if physics:
        names.append('physics')
    if viz:
        names.append('viz')
    if record:
        names.append('recorder')
    return names
