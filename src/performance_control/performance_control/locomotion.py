"""Walking on the floor (Ishigaki et al. 2009, Sec. 8.3): the user walks in place, the character
walks in the virtual world.

The paper treats the user's feet as constrained and the character's as free: while both arms
imitate the walk example, the character walks -- "full control over the speed, direction, size of
stride, and style". Here, per frame while the floor's recognizer says "imitating":

* cadence: the user's arm swing, the fore-aft distance between the hands in the body frame
  (``s = x_left - x_right``), whose zero crossings (with a hysteresis of a quarter of the
  example's amplitude) give the half cycles; the last two half cycles give the period;
* stride: the amplitude of ``s`` (its RMS over the last cycle) against the example's, clipped to
  [0.5, 1.5] (a bigger swing, a longer stride);
* speed = the example's speed x (example period / user period) x stride ratio: the example's own
  speed is its COM's horizontal displacement over its duration (the real CMU walk, or the
  generated one);
* direction: the character's heading (the user's facing, relative to their first frame), so the
  character turns when the user turns.

Plain numpy; the controller moves the simplified model by this velocity (the feet re-engage the
floor where they come down) and composes the example's legs (the style of the arms is the user's).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from skeleton_core.geometry import facing_yaw
from skeleton_core.model import HAND_LEFT, HAND_RIGHT

from .intention import center_of_mass, yaw_rotation


def swing_signal(positions: np.ndarray, yaw) -> np.ndarray:
    """Fore-aft distance between the left and right hand in the body frame (..., ) of poses
    (..., 20, 3) with headings ``yaw`` (rad)."""
    p = np.asarray(positions, float)
    d = p[..., HAND_LEFT, :] - p[..., HAND_RIGHT, :]
    return np.einsum('...ij,...j->...i', yaw_rotation(yaw), d)[..., 0]


def example_gait(positions: np.ndarray, fps: float) -> tuple:
    """(speed m/s, period s, swing amplitude (RMS of :func:`swing_signal`)) of a walk example
    (T, 20, 3)."""
    p = np.asarray(positions, float)
    com = center_of_mass(p)
    dur = (len(p) - 1) / fps
    speed = float(np.linalg.norm(com[-1, :2] - com[0, :2]) / max(dur, 1e-6))
    s = swing_signal(p, facing_yaw(p))
    s = s - s.mean()
    amp = float(np.sqrt(np.mean(s * s)))
    sign = np.signbit(s)
    cross = np.nonzero(sign[1:] != sign[:-1])[0]
    period = float(2.0 * np.mean(np.diff(cross)) / fps) if len(cross) >= 2 else 1.1
    return speed, period, amp


class Walker:
    """Per user: :meth:`update` every frame with the user's pose; :meth:`velocity` the
    character's horizontal walking velocity (world, m/s) while walking."""

    def __init__(self, speed: float, period: float, amplitude: float, fps: float = 30.0):
        self.ex_speed, self.ex_period, self.ex_amp = float(speed), float(period), float(amplitude)
        self.fps = fps
        self._t: Optional[float] = None
        self._sign = 0
        self._crossings: list = []
        self._buf: list = []
        self._mean = 0.0

    def reset(self) -> None:
        self.__init__(self.ex_speed, self.ex_period, self.ex_amp, self.fps)

    def update(self, positions: np.ndarray, yaw: float, t: float) -> None:
        s = float(swing_signal(positions, yaw))
        self._buf.append(s)
        n = int(round(1.5 * self.ex_period * self.fps))
        if len(self._buf) > n:
            self._buf.pop(0)
        self._mean += (s - self._mean) * (1.0 - math.exp(-1.0 / (self.ex_period * self.fps)))
        h = 0.25 * self.ex_amp
        x = s - self._mean
        sign = 1 if x > h else (-1 if x < -h else self._sign)
        if sign != self._sign and self._sign != 0:
            self._crossings.append(t)
            self._crossings = self._crossings[-3:]
        self._sign = sign
        self._t = t

    def period(self) -> Optional[float]:
        """The user's swing period (s) from the last two half cycles; None before two."""
        c = self._crossings
        if len(c) < 3 or self._t is None:
            return None
        half = 0.5 * (c[-1] - c[-3])
        # a swing that stopped: the time since the last crossing counts as a half cycle
        half = max(half, self._t - c[-1])
        return 2.0 * half

    def stride_ratio(self) -> float:
        b = np.asarray(self._buf)
        if len(b) < 3:
            return 1.0
        amp = float(np.sqrt(np.mean((b - b.mean()) ** 2)))
        return float(np.clip(amp / max(self.ex_amp, 1e-6), 0.5, 1.5))

    def speed(self) -> float:
        """The walking speed (m/s): the example's, scaled by cadence and stride; the example's
        speed until the user's period is known."""
        per = self.period()
        cad = 1.0 if per is None else float(np.clip(self.ex_period / per, 0.3, 2.0))
        return self.ex_speed * cad * self.stride_ratio()

    def velocity(self, heading: float) -> np.ndarray:
        v = self.speed()
        return np.array([v * math.cos(heading), v * math.sin(heading), 0.0])


__all__ = ['Walker', 'example_gait', 'swing_signal']
