"""Offline evaluation (no rclpy): sensor model, metrics, harness, paired real data, registration, calibration."""
import skeleton_core  # noqa: F401  (single-threaded BLAS before numpy)
