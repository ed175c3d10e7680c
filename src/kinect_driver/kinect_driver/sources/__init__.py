"""Skeleton sources of the driver node (no rclpy): synthetic, replay and live (OpenNI2/NiTE2)."""
from .base import Source, SourceError, SourceOutput  # noqa: F401

SOURCE_NAMES = ('synthetic', 'replay', 'live')
