"""Kinect skeleton sources: OpenNI2/NiTE2 live tracking, bag/CSV replay and a synthetic sensor-model source."""
import skeleton_core  # noqa: E402,F401  (first: single-threaded BLAS, see there)
