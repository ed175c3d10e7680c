"""A fake Azure Kinect ROS driver for the DDS and launch tests: publishes the simulated bodies of
``azure_fake`` on ``body_tracking_data`` (relative: start it in a namespace with ``--ros-args -r
__ns:=/kinect_1``) as the driver does, stamped with the current time, once the graph is there.

    python tests/fake_azure_driver.py [--pose "x y z yaw pitch roll"] [--wait-topic T --wait N]
        [--tf-prefix P] [--ros-args ...]

``--pose``: the camera's pose in world (the people stand where ``azure_fake`` puts them in front
of a camera 0.8 m high at the origin); ``--wait-topic``/``--wait``: publish only once T has N
subscribers (the graph's readers of the skeletons), then 2 s more. Exits after the last frame
(and a few empty messages: nobody seen)."""
import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


def main(argv=None):
    import rclpy
    from rclpy.utilities import remove_ros_args
    from visualization_msgs.msg import MarkerArray

    import azure_fake as A
    from skeleton_core.tf import Transform, parse_pose
    from skeleton_data import k4abt as K4

    args = remove_ros_args(sys.argv if argv is None else argv)[1:]
    p = argparse.ArgumentParser()
    p.add_argument('--pose', default='0 0 0.8 0 0 0')
    p.add_argument('--wait-topic', default='')
    p.add_argument('--wait', type=int, default=0)
    p.add_argument('--tf-prefix', default='')
    p.add_argument('--timeout', type=float, default=90.0)
    a = p.parse_args(args)
    rclpy.init()
    node = rclpy.create_node('fake_azure_driver')
    pub = node.create_publisher(MarkerArray, 'body_tracking_data', 10)
    deadline = time.monotonic() + a.timeout
    while time.monotonic() < deadline and (
            pub.get_subscription_count() < 1 or
            (a.wait and node.count_subscribers(
                node.resolve_topic_name(a.wait_topic)) < a.wait)):
        rclpy.spin_once(node, timeout_sec=0.1)
    time.sleep(2.0)
    # the people are placed for a camera 0.8 m high at the origin: move them into this camera
    first = Transform.from_xyz_ypr(0.0, 0.0, A.SENSOR_HEIGHT)
    to_cam = parse_pose(a.pose).inverse() * first
    cam = K4.camera_to_sensor()
    frame = a.tf_prefix + 'depth_camera_link'
    period = 1.0 / A.FPS
    t_next = time.monotonic()
    for bodies in A.captures() + [[]] * 5:
        moved = [(b, to_cam.apply(pos @ cam.T) @ cam, present) for b, pos, present in bodies]
        stamp = node.get_clock().now().nanoseconds
        pub.publish(A.marker_array(moved, stamp, frame))
        t_next += period
        time.sleep(max(0.0, t_next - time.monotonic()))
    time.sleep(1.0)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
