"""Pure-Python core of the Kinect posture pipeline (no rclpy). See :mod:`skeleton_core.model`."""
