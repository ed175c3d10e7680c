"""Which users are present in a skeleton stream, in the stream's own time (no rclpy).

One mechanism for the live nodes and the offline ``process_bag``: a user is present until the
input's clock has gone ``timeout_s`` past the last message that held them.

* Offline (a bag), the input's clock is the messages' time: a user who leaves mid-recording is
  gone ``timeout_s`` of *recorded* time later, however fast the bag is processed.
* Live, the input's clock also runs while nothing arrives: between messages it advances with the
  wall clock from the last message (``wall`` argument), so when the input stops altogether (driver
  killed, a gap in a replayed bag) every user ages out after ``timeout_s`` instead of being kept
  forever. A message whose stamp is behind the clock (a bag loop, a restarted sensor, clock
  skew) does not move it back: the clock is the later of the newest stamp and the extrapolation.

    p = Presence(timeout_s=1.0)
    p.observe(stamp_ns, [1, 2], wall=time.monotonic())   # a message holding users 1 and 2
    for uid in p.expired(wall=time.monotonic()):          # users gone by now (forgotten)
        remove_character(uid)
"""
from __future__ import annotations

import math
from typing import Dict, Iterable, List, Optional


class Presence:
    """Users of a stream and when they were last seen, on the stream's clock."""

    def __init__(self, timeout_s: float):
        self.timeout_s = float(timeout_s)
        if not (self.timeout_s > 0 and math.isfinite(self.timeout_s)):
            raise ValueError(f'timeout must be a positive number of seconds, got {timeout_s}')
        self._last_seen: Dict[int, int] = {}   # user -> input clock (ns) of the last sighting
        self._t_ns: Optional[int] = None         # input clock at the last message
        self._wall: Optional[float] = None       # wall clock (s) of the last message

    def now_ns(self, wall: Optional[float] = None) -> Optional[int]:
        """The input's clock: the last message's time, plus the wall time since it when ``wall``
        (seconds, monotonic) is given. None before the first message."""
        if self._t_ns is None:
            return None
        if wall is None or self._wall is None:
            return self._t_ns
        return self._t_ns + int(max(0.0, wall - self._wall) * 1e9)

    def observe(self, stamp_ns: int, users: Iterable[int], wall: Optional[float] = None) -> None:
        """A message at ``stamp_ns`` (0 = unstamped: the current clock) holding ``users``."""
        now = self.now_ns(wall)
        t = int(stamp_ns) if stamp_ns else (now or 0)
        self._t_ns = t if now is None else max(t, now)
        self._wall = wall
        for uid in users:
            self._last_seen[int(uid)] = self._t_ns

    def seen(self, user_id: int) -> bool:
        return int(user_id) in self._last_seen

    @property
    def users(self) -> List[int]:
        return list(self._last_seen)

    def expired(self, wall: Optional[float] = None) -> List[int]:
        """Users unseen for more than ``timeout_s`` on the input's clock; they are forgotten (a
        later sighting is a new arrival)."""
        now = self.now_ns(wall)
        if now is None:
            return []
        limit = now - int(self.timeout_s * 1e9)
        gone = [u for u, t in self._last_seen.items() if t < limit]
        for u in gone:
            del self._last_seen[u]
        return gone

    def forget(self, user_id: int) -> None:
        self._last_seen.pop(int(user_id), None)

    def clear(self) -> None:
        self._last_seen.clear()
        self._t_ns = None
        self._wall = None
