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
"""
from __future__ import annotations

from typing import Dict, List, Optional, Sequence

FRAME_PERIOD_S = 1.0 / 30.0
ABSENT_PERIODS = 10.0  # a sensor silent this many frame periods (1/3 s) is not waited for: an
#                        unplugged sensor delays the others' frames (by at most one period each)
#                        for 1/3 s only; a shorter gap (a loaded machine delivered nothing for
#                        100 ms: seen on 2 shared cores) does not yet hand the reference over


class FusionClock:
    """Decides the output stamps of the fusion (see the module docstring). ``sensors``: the sensor
    names in reference order. Call :meth:`on_frame` per received message and :meth:`on_timer`
    when :meth:`deadline` has passed; both return the stamps (ns) to fuse and publish, oldest
    first (usually none or one)."""

    def __init__(self, sensors: Sequence[str], period_s: float = FRAME_PERIOD_S):
        if not sensors:
            raise ValueError('the fusion clock needs at least one sensor')
        self.sensors = list(sensors)
        self.period_s = float(period_s)
        self.reset()

    def reset(self) -> None:
        self.latest: Dict[str, int] = {}       # newest capture stamp per sensor
        self.heard: Dict[str, float] = {}      # wall time of its last message
        self.last_out: Optional[int] = None    # the last stamp published
        self.pending: Optional[int] = None     # the reference stamp waiting for the others
        self.pending_wall = 0.0
        self.forced = 0                        # stamps published without a late sensor

    def present(self, wall: float) -> List[str]:
        """The sensors heard within :data:`ABSENT_PERIODS` frame periods, in reference order."""
        limit = ABSENT_PERIODS * self.period_s
        return [s for s in self.sensors if s in self.heard and wall - self.heard[s] <= limit]

    def reference(self, wall: float) -> Optional[str]:
        present = self.present(wall)
        return present[0] if present else None

    def deadline(self) -> Optional[float]:
        """Wall time at which the pending stamp is published whoever is late (None: nothing)."""
        return None if self.pending is None else self.pending_wall + self.period_s

    def on_frame(self, sensor: str, stamp_ns: int, wall: float) -> List[int]:
        if sensor not in self.sensors:
            raise KeyError(f'unknown sensor {sensor!r} (known: {self.sensors})')
        stamp_ns = int(stamp_ns)
        self.latest[sensor] = max(stamp_ns, self.latest.get(sensor, stamp_ns))
        self.heard[sensor] = wall
        out: List[int] = []
        if sensor == self.reference(wall) and (self.last_out is None or stamp_ns > self.last_out) \
                and (self.pending is None or stamp_ns > self.pending):
            if self.pending is not None:     # the others missed a whole frame: it goes out now
                out.append(self._emit(forced=True))
            self.pending, self.pending_wall = stamp_ns, wall
        if self.pending is not None and self._caught_up(wall):
            out.append(self._emit())
        return out

    def on_timer(self, wall: float) -> List[int]:
        if self.pending is None or wall < self.pending_wall + self.period_s - 1e-4:
            return []
        return [self._emit(forced=not self._caught_up(wall))]

    def _caught_up(self, wall: float) -> bool:
        return all(self.latest.get(s, -1) >= self.pending for s in self.present(wall))

    def _emit(self, forced: bool = False) -> int:
        stamp = self.pending
        self.pending = None
        self.last_out = stamp
        self.forced += bool(forced)
        return stamp


__all__ = ['FusionClock', 'FRAME_PERIOD_S', 'ABSENT_PERIODS']
