"""``passthrough``: the benchmark's floor -- a node that subscribes to a topic and republishes the
same serialized bytes on another, doing nothing else. Its latency is what one DDS hop and one
Python callback cost on this machine at this moment; the graph's outputs are judged against it.

    python -m kinect_experiments.passthrough [--input /kinect/skeletons] [--output /bench/passthrough]
"""
from __future__ import annotations

import argparse
import sys


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog='passthrough', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--input', default='/kinect/skeletons')
    p.add_argument('--output', default='/bench/passthrough')
    p.add_argument('--depth', type=int, default=10, help='queue depth (the graph nodes use 10)')
    args, ros_args = p.parse_known_args(argv if argv is not None else sys.argv[1:])
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile
    from skeleton_core.rosnode import spin_until_shutdown
    from skeleton_msgs.msg import SkeletonArray
    rclpy.init(args=[sys.argv[0]] + ros_args)
    node = Node('passthrough')
    pub = node.create_publisher(SkeletonArray, args.output, QoSProfile(depth=args.depth))
    node.create_subscription(SkeletonArray, args.input, pub.publish, QoSProfile(depth=args.depth),
                             raw=True)
    try:
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        spin_until_shutdown(executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
