"""``pipeline``: the whole node graph in one process (one executor), configured from the
same ``config/<node>.yaml`` files as ``pipeline.launch.py`` — for machines without ``ros2 launch``.

    ros2 run kinect_bringup pipeline                       # synthetic source, method C, physics, viz
    ros2 run kinect_bringup pipeline --source replay --replay-file out/demo.mcap --duration 20
    ros2 run kinect_bringup pipeline --method A --no-physics --record out/run.mcap
"""
from __future__ import annotations

import argparse
import signal
import sys
import threading
from pathlib import Path
from typing import Dict, List, Optional

from skeleton_core.tf import DEFAULT_SENSOR_POSE

from .graph import (RECONSTRUCTION, config_dir, graph_nodes, load_params, node_class, params_file,
                    replay_overrides, replays, skeleton_subscribers)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='pipeline', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--source', choices=['synthetic', 'replay', 'live'], default=None)
    p.add_argument('--replay-file', default=None)
    p.add_argument('--scenario', choices=['a', 'b', 'c', 'd', 'e'], default=None)
    p.add_argument('--num-users', type=int, default=None)
    p.add_argument('--seed', type=int, default=None)
    p.add_argument('--database', default=None, help='motion database file ("" = default)')
    p.add_argument('--method', choices=['A', 'B', 'C'], default=None,
                   help='A drives the character from completion; B/C set the optimizer (default: YAML)')
    p.add_argument('--reconstruction', choices=sorted(RECONSTRUCTION), default='fused',
                   help='fused: one reconstruction node (default); split: reliability, completion '
                        'and optimizer nodes')
    p.add_argument('--no-physics', action='store_true')
    p.add_argument('--no-viz', action='store_true')
    p.add_argument('--record', default='', help='record the pipeline topics to this MCAP file')
    p.add_argument('--record-split-size', type=float, default=None,
                   help='with --record: a new piece every this many MB (a folder of bags)')
    p.add_argument('--record-split-duration', type=float, default=None,
                   help='with --record: a new piece every this many seconds')
    p.add_argument('--duration', type=float, default=0.0, help='stop after this many seconds (0 = run)')
    p.add_argument('--config-dir', default=None, help='directory of <node>.yaml files')
    p.add_argument('--sensor-pose', default=DEFAULT_SENSOR_POSE,
                   help='the sensor\'s pose in world (TF world -> kinect_link): "x y z yaw pitch '
                        f'roll" (m, deg; default "{DEFAULT_SENSOR_POSE}")')
    p.add_argument('--extrinsics', default='',
                   help='sensor-pose YAML (hand-measured or from calibrate_extrinsics; overrides '
                        '--sensor-pose)')
    p.add_argument('--executor', choices=EXECUTORS, default='auto',
                   help='rclpy executor: auto (default: events where rclpy has it, Jazzy and '
                        'newer; single otherwise), events (rclpy.experimental.EventsExecutor: '
                        'about a third less CPU than single for the same graph), single, multi '
                        '(the nodes share one interpreter lock: threads add overhead, not '
                        'parallelism)')
    p.add_argument('--threads', type=int, default=None,
                   help='--executor multi: executor threads (default: cores)')
    return p


EXECUTORS = ('auto', 'events', 'single', 'multi')


def make_executor(kind: str, threads: Optional[int] = None):
    """``(executor, kind)``: the executor that spins every node of the one-process graph, and
    which one it is (``auto``: events where rclpy has it, else single)."""
    if kind == 'multi':
        from rclpy.executors import MultiThreadedExecutor
        return MultiThreadedExecutor(num_threads=threads), kind
    if kind in ('events', 'auto'):
        from skeleton_core.compat import events_executor
        try:
            return events_executor(), 'events'
        except RuntimeError:   # (Humble: no events executor)
            if kind == 'events':
                raise          # asked for by name: the one line says why not
    from rclpy.executors import SingleThreadedExecutor
    return SingleThreadedExecutor(), 'single'


def node_overrides(args) -> Dict[str, Dict]:
    """Per-node parameter overrides from the command line (same meaning as the launch arguments)."""
    over: Dict[str, Dict] = {n: {} for n in ('driver', 'completion', 'optimizer', 'reconstruction',
                                             'physics', 'recorder')}
    for key, attr in (('source', 'source'), ('replay_file', 'replay_file'), ('scenario', 'scenario'),
                      ('num_users', 'num_users'), ('seed', 'seed')):
        v = getattr(args, attr)
        if v is not None:
            over['driver'][key] = v
    if args.database is not None:
        over['completion']['database'] = args.database
        over['optimizer']['database'] = args.database
        over['reconstruction']['database'] = args.database
    if args.method in ('B', 'C'):
        over['optimizer']['method'] = args.method
        over['reconstruction']['optimizer.method'] = args.method
    if args.method:
        over['physics']['input_topic'] = ('/posture/completed' if args.method == 'A'
                                          else '/posture/reconstructed')
    if args.record:
        over['recorder']['output'] = str(Path(args.record).resolve())
        if args.record_split_size is not None:
            over['recorder']['split_size_mb'] = args.record_split_size
        if args.record_split_duration is not None:
            over['recorder']['split_duration_s'] = args.record_split_duration
    return over


def create_nodes(names: List[str], overrides: Dict[str, Dict], directory: Optional[Path] = None,
                 context=None, activate: bool = True):
    """Instantiate the graph's nodes in this process, each with its YAML file and overrides, and
    (``activate``) configure, then activate them (lifecycle nodes: ``skeleton_core.rosnode.
    bring_up``; a failed configure raises TransitionFailed with the node's one line, the nodes
    destroyed)."""
    from rclpy.parameter import Parameter
    nodes = []
    for name in names:
        cls = node_class(name)
        cli = []
        values = dict(overrides.get(name, {}))
        pf = params_file(name, directory)
        if pf is not None:
            cli = ['--ros-args', '--params-file', str(pf)]
        else:  # a node without a file of its own (the fused reconstruction)
            values = {**load_params(name, directory), **values}
        po = [Parameter(k, value=v) for k, v in values.items()]
        kwargs = dict(cli_args=cli, parameter_overrides=po)
        if context is not None:
            kwargs['context'] = context
        try:
            nodes.append(cls(**kwargs))
        except Exception:
            for n in nodes:
                n.destroy_node()
            raise
    if activate:
        from skeleton_core.rosnode import bring_up
        try:
            bring_up(*nodes)
        except Exception:
            for n in nodes:
                n.destroy_node()
            raise
    return nodes


def spin(executor, kind: str) -> None:
    """Spin until shut down; Ctrl-C (and ``--duration``'s SIGINT) raises KeyboardInterrupt here.
    The events executor's ``spin`` runs in C++ and does not return to Python, where signal
    handlers run (nor does its ``shutdown`` from another thread end it): it is spun in slices
    and SIGINT only asks it to stop (raised inside a callback, the C++ layer would log the
    KeyboardInterrupt as a fatal callback error)."""
    if kind != 'events':
        from skeleton_core.rosnode import spin_until_shutdown
        spin_until_shutdown(executor)
        return
    import rclpy
    stop = threading.Event()
    previous = signal.signal(signal.SIGINT, lambda *_: stop.set())
    try:
        while rclpy.ok() and not stop.is_set():
            executor.spin_once(timeout_sec=0.1)
    finally:
        signal.signal(signal.SIGINT, previous)


def main(argv=None) -> int:
    args = build_parser().parse_args(argv if argv is not None else sys.argv[1:])
    import rclpy
    from rclpy.executors import ExternalShutdownException

    from skeleton_core.rosnode import TransitionFailed, ignore_further_interrupts

    directory = Path(args.config_dir) if args.config_dir else config_dir()
    names = graph_nodes(args.method, physics=not args.no_physics, viz=not args.no_viz,
                        record=bool(args.record), reconstruction=args.reconstruction)
    from rclpy.signals import SignalHandlerOptions
    # Ctrl-C raises KeyboardInterrupt here; the executor is stopped and waited for before the
    # nodes are destroyed (rclpy's own handler would shut the context down under running callbacks).
    rclpy.init(args=None, signal_handler_options=SignalHandlerOptions.NO)
    # a process started in the background by a shell inherits SIGINT ignored: Ctrl-C, the
    # --duration timer and a supervisor's SIGINT must still stop the graph cleanly
    signal.signal(signal.SIGINT, signal.default_int_handler)
    nodes = []
    try:
        over = node_overrides(args)
        # a replay holds its first frame until every node reading /kinect/skeletons is there
        over['driver'].setdefault('wait_for_subscribers', skeleton_subscribers(names, directory))
        if replays(over['driver'].get('source', ''), directory):
            # a recording's frames wait in the reconstruction's queues while it is busy
            for name, values in replay_overrides(names).items():
                over.setdefault(name, {}).update(values)
        from kinect_driver.static_tf_node import StaticTfNode, parse_args, transforms_from_args
        tf_args = ['--pose', args.sensor_pose] + (['--file', args.extrinsics]
                                                  if args.extrinsics else [])
        frames = transforms_from_args(parse_args(tf_args))   # the sensor frame on TF
        if 'physics' in names:   # its input's frame: taken once TF has it (as the launch files)
            over['physics'].setdefault('wait_for_frames', ['kinect_link'])
        nodes = [StaticTfNode(frames)]
        nodes += create_nodes(names, over, directory)
        executor, kind = make_executor(args.executor, args.threads)
    except (ValueError, FileNotFoundError, RuntimeError, OSError, ImportError) as e:
        if not isinstance(e, TransitionFailed):   # (the node has logged its one line)
            print(f'[pipeline] ERROR: {e}', file=sys.stderr)
        for n in nodes:
            n.destroy_node()
        rclpy.try_shutdown()
        return 1
    for n in nodes:
        executor.add_node(n)
    nodes[0].get_logger().info(
        f'pipeline: {len(nodes)} nodes in one process ({", ".join(names)}), {kind} executor, '
        f'config {directory}')
    if args.duration > 0:
        timer = threading.Timer(args.duration, lambda: signal.raise_signal(signal.SIGINT))
        timer.daemon = True
        timer.start()
    try:
        spin(executor, kind)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        ignore_further_interrupts()
        executor.shutdown(timeout_sec=5.0)
        for n in reversed(nodes):  # recorder is last in the list: closes its file first
            n.destroy_node()
        rclpy.try_shutdown()
    print('[pipeline] stopped', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
