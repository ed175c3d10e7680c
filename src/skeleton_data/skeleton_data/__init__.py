"""Offline data import (no rclpy): mocap/BVH clips, built-in motions, the motion database, UI-PRMD and Vicon readers."""
import skeleton_core  # noqa: F401  (single-threaded BLAS before numpy)
