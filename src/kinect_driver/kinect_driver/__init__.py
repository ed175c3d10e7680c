"""Kinect skeleton sources: OpenNI2/NiTE2 live tracking, bag/CSV replay and a synthetic sensor-model source."""
