"""Node ``static_tf``: publishes the sensors' poses (``world -> kinect_link``, or
``world -> kinect_k_link`` for sensor k) as static transforms on ``/tf_static``, all in one latched
message as tf2's ``static_transform_publisher`` does. No tf2_ros needed.

    ros2 run kinect_driver static_tf --pose "0 0 0.8 0 0 0"                     # world -> kinect_link
    ros2 run kinect_driver static_tf --pose "0 0 0.8 0 0 0" --child kinect_1_link \\
                                     --pose "2.5 2.5 0.8 -90 0 0" --child kinect_2_link
    ros2 run kinect_driver static_tf --file cache/extrinsics.yaml               # calibration file

A pose is ``x y z yaw pitch roll`` (m, degrees; tf2's intrinsic z-y-x angles; positive pitch =
tilted down). ``--file`` takes the sensor-pose YAML of :mod:`skeleton_core.tf` (hand-measured or
written by ``calibrate_extrinsics``); its frames override the ``--pose`` ones (a calibration
replaces the launch file's defaults). A bad pose or file is one clear line and exit code 1.
"""
from __future__ import annotations

import argparse
import sys
from typing import List, Optional, Tuple

from rclpy.node import Node

from skeleton_core.rosnode import run_node
from skeleton_core.tf import WORLD_FRAME, Transform, format_pose, load_transforms, parse_pose
from skeleton_core.tf_ros import StaticTfBroadcaster


def parse_args(argv: Optional[List[str]] = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog='static_tf', description=__doc__.split('\n\n')[0])
    ap.add_argument('--file', action='append', default=[],
                    help='sensor-pose YAML (repeatable; overrides --pose for its frames, a later file an earlier one)')
    ap.add_argument('--pose', action='append', default=[],
                    help='"x y z yaw pitch roll" (m, deg) of the next --child (default '
                         'kinect_link) in --parent')
    ap.add_argument('--child', action='append', default=[],
                    help='child frame of the --pose with the same position (default kinect_link)')
    ap.add_argument('--parent', default=WORLD_FRAME, help='parent frame of every --pose')
    return ap.parse_args(argv)


def transforms_from_args(args: argparse.Namespace) -> List[Tuple[str, str, Transform]]:
    """The transforms the arguments name, in order, a later one replacing an earlier child.
    Raises ``ValueError`` with a one-line reason."""
    items = {}
    if len(args.child) > len(args.pose):
        raise ValueError(f'{len(args.child)} --child but {len(args.pose)} --pose')
    for i, pose in enumerate(args.pose):
        child = args.child[i] if i < len(args.child) else 'kinect_link'
        items[child] = (args.parent, child, parse_pose(pose))
    for path in args.file:
        for parent, child, t in load_transforms(path):
            items[child] = (parent, child, t)
    if not items:
        raise ValueError('nothing to publish: give --pose or --file')
    return list(items.values())


class StaticTfNode(Node):
    def __init__(self, items: List[Tuple[str, str, Transform]]):
        super().__init__('static_tf')
        self.items = items
        self.broadcaster = StaticTfBroadcaster(self)
        self.broadcaster.send(items)
        for parent, child, t in items:
            self.get_logger().info(f'{parent} -> {child}: {format_pose(t)} (x y z m, yaw pitch '
                                   'roll deg)')


def main(args=None) -> int:
    from rclpy.utilities import remove_ros_args
    argv = remove_ros_args(sys.argv if args is None else args)[1:]
    ns = parse_args(argv)
    try:
        items = transforms_from_args(ns)
    except ValueError as e:
        print(f'[ERROR] static_tf: {e}', file=sys.stderr)
        return 1
    return run_node(lambda: StaticTfNode(items), args=args)


if __name__ == '__main__':
    sys.exit(main())
