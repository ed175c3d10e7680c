"""Trust in the sensor (graceful degradation of the reconstruction's output).

How far the output follows the reliable observed joints rather than the database solution, per
frame in [0, 1] (:mod:`.reconstructor`, ``trust_mode``):

* ``'noise_ratio'`` — the RMS distance per reliable joint of the nearest database posture, smoothed
  over time, divided by the sensor's frame-to-frame noise (an exponential average, rate
  ``noise_alpha``, of the median second difference of the reliable joints); the trust rises
  linearly from 0 at ``ratio`` to 1 at twice it (1 until the noise is known);
* ``'distance'`` — linear from 0 at ``distance`` (RMS m per reliable joint, standard body) to 1 at
  twice it.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Optional

import numpy as np

from skeleton_core.params import check, param

TRUST_MODES = ('noise_ratio', 'distance')


@dataclass
class TrustConfig:
    """Parameters of :class:`SensorTrust` (their reconstruction parameter names)."""

    trust_sensor_distance: float = param(
        0.12, 'nearest database posture farther than this (RMS m per reliable joint): reliable '
        'joints blend towards their observed positions (fully at twice it)', range=(0.0, 100.0),
        public=False)
    trust_mode: str = param(
        'noise_ratio', "trust in the sensor from noise_ratio (database distance / the sensor's "
        'measured noise) or distance (trust_sensor_distance, earlier rule)', choices=TRUST_MODES,
        public=False)
    trust_sensor_ratio: float = param(
        8.0, 'noise_ratio: database distance / sensor noise at which the trust starts to rise '
        '(full at twice it)', range=(1e-3, 1e6), public=False)
    noise_alpha: float = param(0.05, 'noise_ratio: exponential-average rate of the noise '
                               'estimate', range=(1e-4, 1.0), public=False)


class SensorTrust:
    """One user's trust in the sensor; ``update`` once per frame."""

    def __init__(self, config: TrustConfig, reliable_threshold: float):
        check(config)
        self.mode = config.trust_mode
        self.ratio = float(config.trust_sensor_ratio)
        self.noise_alpha = float(config.noise_alpha)
        self.distance = float(config.trust_sensor_distance)
        self.reliable_threshold = float(reliable_threshold)
        self.reset()

    def reset(self) -> None:
        self._hist = deque(maxlen=2)  # previous observed positions (noise estimate)
        self._noise: Optional[float] = None
        self._noise_n = 0
        self._rms_avg: Optional[float] = None
        self.noise = float('nan')

    def update(self, positions: np.ndarray, w: np.ndarray, rms: float) -> float:
        """This frame's trust: ``positions`` (20, 3) observed, ``w`` (20,) reliabilities, ``rms``
        the nearest database posture's RMS distance per reliable joint."""
        if self.mode == 'distance':
            d0 = self.distance  # standard-body metres
            return min(max((rms - d0) / max(d0, 1e-6), 0.0), 1.0)
        if len(self._hist) == 2:
            rel = w >= self.reliable_threshold
            if rel.any():
                a = positions - 2.0 * self._hist[-1] + self._hist[-2]
                a = a[rel]
                an = np.sort(np.sqrt(np.einsum('jk,jk->j', a, a)))
                m = len(an)
                n = 0.5 * float(an[(m - 1) // 2] + an[m // 2])  # the median
                self._noise_n += 1  # running mean first, then exponential
                rate = max(self.noise_alpha, 1.0 / self._noise_n)
                self._noise = n if self._noise is None else (1 - rate) * self._noise + rate * n
        self._hist.append(positions)
        rate = max(2.0 * self.noise_alpha, 1.0 / (self._noise_n + 1))
        self._rms_avg = rms if self._rms_avg is None else (1 - rate) * self._rms_avg + rate * rms
        if self._noise is None:
            return 1.0
        self.noise = self._noise
        r0 = self.ratio
        return min(max((self._rms_avg / max(self._noise, 1e-4) - r0) / r0, 0.0), 1.0)
