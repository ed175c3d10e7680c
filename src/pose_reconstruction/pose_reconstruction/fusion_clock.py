"""When the fusion node publishes: one fused frame per capture of the reference sensor, as soon as
every other sensor has caught up with it, never later than one frame period. No rclpy; the wall
clock is passed in (tested on a fake clock, as ``physics_sim.scheduler``).

Unsynchronised sensors capture at the same rate with different phases: sensor 2's frames may
come 10 ms after sensor 1's. :class:`FusionClock` takes the *reference* sensor's capture stamps as
the output stamps (the first sensor in order that is still delivering: sensor 1, else the next),
so the output runs at the sensors' rate and the fusion interpolates every other sensor between
its frames around that stamp (:class:`.fusion.MultiSensorFusion` steps 2). A stamp of the
reference is *pending* until every other present sensor has delivered a frame at or after it
(then it is published at once) or one frame period of wall time has passed since it arrived
(then it is published without the late ones: the fusion holds or leaves them out). A sensor not
heard for :data:`ABSENT_PERIODS` frame periods is not waited for at all, so a sensor that stops
costs no delay on the others' frames.

How long to wait adapts to each sensor's phase. For every reference stamp the clock notes when
each other sensor delivered its first frame at or after it (its *lag*, wall time after the
reference frame's arrival, whether or not the stamp waited for it). A sensor whose recent lags
(their :data:`LAG_QUANTILE` quantile over the last :data:`LAG_WINDOW` stamps) fit in
``max_wait_s`` is waited for that long plus :data:`LAG_MARGIN_S`; one whose lag does not (its
phase trails the reference's by more than the bound) is not waited for at all: the stamp is
published as soon as the sensors that can make it have delivered, and the fusion holds the late
sensor's newest frame (at most one period old). Before :data:`LAG_MIN_SAMPLES` lags are known, a
sensor is waited for up to ``max_wait_s``. ``max_wait_s`` = one period (the default) waits for
every sensor whose frame comes within the period, as before the adaptation.
"""
from __future__ import annotations

import collections
from typing import Deque, Dict, List, Optional, Sequence

from .quantile import sorted_quantile


FRAME_PERIOD_S = 1.0 / 30.0
ABSENT_PERIODS = 10.0  # a sensor silent this many frame periods (1/3 s) is not waited for: an
#                        unplugged sensor delays the others' frames (by at most one period each)
#                        for 1/3 s only; a shorter gap (a loaded machine delivered nothing for
#                        100 ms: seen on 2 shared cores) does not yet hand the reference over


LAG_WINDOW = 30          # reference stamps whose lags are remembered per sensor (1 s)
LAG_QUANTILE = 90        # the lag a wait must cover (per cent of the recent stamps)
LAG_MIN_SAMPLES = 5      # lags known before a sensor's wait is adapted
LAG_MARGIN_S = 0.003     # added to the expected lag: delivery jitter


def _quantile(values, q: float) -> float:
    """``np.quantile(values, q)``, the same value."""
    return sorted_quantile(sorted(values), q)


class FusionClock:
    """Decides the output stamps of the fusion (see the module docstring). ``sensors``: the sensor
    names in reference order. Call :meth:`on_frame` per received message and :meth:`on_timer`
    when :meth:`deadline` has passed; both return the stamps (ns) to fuse and publish, oldest
    first (usually none or one)."""

    def __init__(self, sensors: Sequence[str], period_s: float = FRAME_PERIOD_S,
                 max_wait_s: Optional[float] = None):
        if not sensors:
            raise ValueError('the fusion clock needs at least one sensor')
        self.sensors = list(sensors)
        self.period_s = float(period_s)
        self.max_wait_s = self.period_s if max_wait_s is None else float(max_wait_s)
        if not 0.0 <= self.max_wait_s <= self.period_s + 1e-9:
            raise ValueError(f'max_wait_s must be in [0, {self.period_s:.3f}] s (one frame '
                             f'period), got {self.max_wait_s}')
        self.reset()

    def reset(self) -> None:
        self.latest: Dict[str, int] = {}       # newest capture stamp per sensor
        self.heard: Dict[str, float] = {}      # wall time of its last message
        self.last_out: Optional[int] = None    # the last stamp published
        self.pending: Optional[int] = None     # the reference stamp waiting for the others
        self.pending_wall = 0.0
        self.forced = 0                        # stamps published without a late sensor
        self.early = 0                         # ... of them not waited for (lag beyond the bound)
        self.lags: Dict[str, Deque[float]] = {s: collections.deque(maxlen=LAG_WINDOW)
                                              for s in self.sensors}
        # expected_lag per sensor while its lags do not change (it is asked several times per
        # frame: each arrival and each deadline; the lags change once per reference stamp)
        self._expected: Dict[str, Optional[float]] = {}
        # recent reference stamps -> (arrival wall time, sensors whose lag is noted)
        self._recent: Dict[int, tuple] = {}

    def present(self, wall: float) -> List[str]:
        """The sensors heard within :data:`ABSENT_PERIODS` frame periods, in reference order."""
        limit = ABSENT_PERIODS * self.period_s
        return [s for s in self.sensors if s in self.heard and wall - self.heard[s] <= limit]

    def reference(self, wall: float) -> Optional[str]:
        present = self.present(wall)
        return present[0] if present else None

    def expected_lag(self, sensor: str) -> Optional[float]:
        """The lag (s) that covers :data:`LAG_QUANTILE` % of ``sensor``'s recent frames; None
        while fewer than :data:`LAG_MIN_SAMPLES` are known."""
        if sensor in self._expected:
            return self._expected[sensor]
        lags = self.lags.get(sensor)
        if lags is None or len(lags) < LAG_MIN_SAMPLES:
            return None
        lag = self._expected[sensor] = _quantile(lags, LAG_QUANTILE / 100.0)
        return lag

    def wait_for(self, sensor: str) -> float:
        """How long (s) after a reference frame's arrival its stamp waits for ``sensor``."""
        lag = self.expected_lag(sensor)
        if lag is None:
            return self.max_wait_s
        if lag > self.max_wait_s:
            return 0.0                       # would not come within the bound: not waited for
        return min(self.max_wait_s, lag + LAG_MARGIN_S)

    def deadline(self) -> Optional[float]:
        """Wall time at which the pending stamp is published whoever is late (None: nothing)."""
        if self.pending is None:
            return None
        waits = [self.wait_for(s) for s in self._missing(self.pending_wall)]
        return self.pending_wall + max(waits, default=0.0)

    def on_frame(self, sensor: str, stamp_ns: int, wall: float) -> List[int]:
        if sensor not in self.sensors:
            raise KeyError(f'unknown sensor {sensor!r} (known: {self.sensors})')
        stamp_ns = int(stamp_ns)
        self.latest[sensor] = max(stamp_ns, self.latest.get(sensor, stamp_ns))
        self.heard[sensor] = wall
        self._note_lag(sensor, stamp_ns, wall)
        out: List[int] = []
        if sensor == self.reference(wall) and (self.last_out is None or stamp_ns > self.last_out) \
                and (self.pending is None or stamp_ns > self.pending):
            if self.pending is not None:     # the others missed a whole frame: it goes out now
                out.append(self._emit(forced=True))
            self.pending, self.pending_wall = stamp_ns, wall
            self._recent[stamp_ns] = (wall, {sensor})
            while len(self._recent) > 4:
                del self._recent[next(iter(self._recent))]
            self._note_lag_of_earlier(stamp_ns, wall)
        if self.pending is not None:
            if self._caught_up(wall):
                out.append(self._emit())
            elif self.deadline() <= wall:    # every late sensor's lag is beyond the bound
                self.early += 1
                out.append(self._emit(forced=True))
        return out

    def on_timer(self, wall: float) -> List[int]:
        deadline = self.deadline()
        if deadline is None or wall < deadline - 1e-4:
            return []
        return [self._emit(forced=not self._caught_up(wall))]

    def _missing(self, wall: float) -> List[str]:
        """The present sensors without a frame at or after the pending stamp."""
        return [s for s in self.present(wall) if self.latest.get(s, -1) < self.pending]

    def _caught_up(self, wall: float) -> bool:
        return not self._missing(wall)

    def _note_lag(self, sensor: str, stamp_ns: int, wall: float) -> None:
        """``sensor``'s first frame at or after a recent reference stamp: its lag."""
        for st, (w, noted) in self._recent.items():
            if sensor not in noted and stamp_ns >= st:
                noted.add(sensor)
                self.lags[sensor].append(min(max(wall - w, 0.0), 2 * self.period_s))
                self._expected.pop(sensor, None)

    def _note_lag_of_earlier(self, stamp_ns: int, wall: float) -> None:
        """A sensor whose frame at or after this reference stamp came before it: lag 0."""
        noted = self._recent[stamp_ns][1]
        for s, latest in self.latest.items():
            if s not in noted and latest >= stamp_ns:
                noted.add(s)
                self.lags[s].append(0.0)
                self._expected.pop(s, None)

    def _emit(self, forced: bool = False) -> int:
        stamp = self.pending
        self.pending = None
        self.last_out = stamp
        self.forced += bool(forced)
        return stamp


__all__ = ['FusionClock', 'FRAME_PERIOD_S', 'ABSENT_PERIODS']
