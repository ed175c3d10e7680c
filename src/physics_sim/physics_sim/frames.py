"""Frames: where the sensor is in the simulated world (floor at z = 0).

Targets arrive in the *sensor* frame (REP-103: x forward from the sensor, z up) and are moved to the
world with :class:`SensorPose`: the sensor's pose in ``world`` (the TF transform ``world ->
kinect_link``, which the physics node looks up; offline the default below) plus the ``lift`` of
the simulated floor. Every state is reported in both frames.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np
from skeleton_core.tf import Transform

# Where the sensor is when nothing says otherwise (offline: the evaluation, process_bag without a
# /tf_static): 0.8 m above the floor, level -- the sensor model's placement
# (config/sensor_model.yaml placement.sensor_height_m) and the launch files' default sensor pose.
DEFAULT_SENSOR_HEIGHT = 0.8
DEFAULT_SENSOR_POSE = Transform.from_xyz_ypr(0.0, 0.0, DEFAULT_SENSOR_HEIGHT)


@dataclass(frozen=True)
class SensorPose:
    """Where the sensor is in the simulated world: ``height`` (m) above the floor and ``pitch``
    (rad, positive = tilted down), or any rigid ``transform`` (world <- sensor, e.g. from TF;
    overrides height and pitch). ``lift`` (m) raises every target so the model's foot capsules
    (whose axis is at the Kinect foot joint) rest on the floor instead of sinking by their
    radius."""

    height: float = DEFAULT_SENSOR_HEIGHT
    pitch: float = 0.0
    lift: float = 0.0
    transform: Optional[Transform] = field(default=None, compare=False)

    def __post_init__(self):   # the rotation and offset every target and state is moved by
        t = self.transform
        if t is None:
            t = Transform.from_xyz_ypr(0.0, 0.0, self.height, 0.0, self.pitch, 0.0, degrees=False)
            object.__setattr__(self, 'transform', t)
        else:
            object.__setattr__(self, 'height', float(t.translation[2]))
            object.__setattr__(self, 'pitch', float(t.ypr(degrees=False)[1]))
        off = t.translation + np.array([0.0, 0.0, self.lift])
        off.flags.writeable = False
        object.__setattr__(self, '_off', off)
        object.__setattr__(self, '_rot', t.matrix)
        object.__setattr__(self, '_level', abs(1.0 - float(t.rotation[3])) < 1e-15)

    @classmethod
    def from_transform(cls, transform: Transform, lift: float = 0.0) -> 'SensorPose':
        return cls(lift=lift, transform=transform)

    def with_lift(self, lift: float) -> 'SensorPose':
        return SensorPose(lift=lift, transform=self.transform)

    def rotation(self) -> np.ndarray:
        return self._rot.copy()

    def quat(self) -> np.ndarray:
        return self.transform.rotation.copy()

    def offset(self) -> np.ndarray:
        return self._off.copy()

    def to_world(self, p: np.ndarray) -> np.ndarray:
        if self._level:
            return np.asarray(p, float) + self._off
        return np.asarray(p, float) @ self._rot.T + self._off

    def to_sensor(self, p: np.ndarray) -> np.ndarray:
        if self._level:
            return np.asarray(p, float) - self._off
        return (np.asarray(p, float) - self._off) @ self._rot

    def quat_to_world(self, q: np.ndarray) -> np.ndarray:
        if self._level:
            return np.array(q, float)
        return self.transform.apply_quat(q)

    def quat_to_sensor(self, q: np.ndarray) -> np.ndarray:
        if self._level:
            return np.array(q, float)
        return self.transform.inverse().apply_quat(q)


__all__ = ['SensorPose', 'DEFAULT_SENSOR_POSE', 'DEFAULT_SENSOR_HEIGHT']
