"""Frames: where the sensor is in the simulated world (floor at z = 0).

Targets arrive in the *sensor* frame (REP-103: x forward from the sensor, z up) and are moved to the
world with :class:`SensorPose` (sensor height and downward pitch); every state is reported in both.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from skeleton_core.geometry import quat_conjugate, quat_multiply


@dataclass(frozen=True)
class SensorPose:
    """Where the sensor is in the world: ``height`` (m) above the floor and ``pitch`` (rad, positive
    = tilted down). ``lift`` (m) raises every target so the model's foot capsules (whose axis is at
    the Kinect foot joint) rest on the floor instead of sinking by their radius."""

    height: float = 0.8
    pitch: float = 0.0
    lift: float = 0.0

    def __post_init__(self):   # the offset every target and state is moved by, made once
        object.__setattr__(self, '_off', np.array([0.0, 0.0, self.height + self.lift]))
        self._off.flags.writeable = False

    def rotation(self) -> np.ndarray:
        c, s = math.cos(self.pitch), math.sin(self.pitch)
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])

    def quat(self) -> np.ndarray:
        return np.array([0.0, math.sin(self.pitch / 2), 0.0, math.cos(self.pitch / 2)])

    def offset(self) -> np.ndarray:
        return self._off.copy()

    def to_world(self, p: np.ndarray) -> np.ndarray:
        if self.pitch == 0.0:
            return np.asarray(p, float) + self._off
        return np.asarray(p, float) @ self.rotation().T + self._off

    def to_sensor(self, p: np.ndarray) -> np.ndarray:
        if self.pitch == 0.0:
            return np.asarray(p, float) - self._off
        return (np.asarray(p, float) - self._off) @ self.rotation()

    def quat_to_world(self, q: np.ndarray) -> np.ndarray:
        if self.pitch == 0.0:
            return np.array(q, float)
        return quat_multiply(np.broadcast_to(self.quat(), np.shape(q)), q)

    def quat_to_sensor(self, q: np.ndarray) -> np.ndarray:
        if self.pitch == 0.0:
            return np.array(q, float)
        return quat_multiply(np.broadcast_to(quat_conjugate(self.quat()), np.shape(q)), q)


__all__ = ['SensorPose']
