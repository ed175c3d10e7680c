"""The replay's start handshake, ROS-free with an injected clock (tests drive it with a fake clock,
without sleeping): nothing of a recording is lost while the graph comes up.

1. Before the first frame the replay waits until ``/kinect/skeletons`` has the expected number of
   subscribers (the graph's readers) and, for at most :data:`OTHERS_GRACE_S` more, until every
   other replayed topic has one; after ``timeout_s`` it plays anyway (with a warning).
2. After the first frame the replay's clock is held (without blocking the node) until every
   reliable subscriber acknowledged it, at most ``timeout_s``: a subscription counted by the
   publisher may not have discovered the publisher yet (discovery is two-way; on a loaded machine
   one direction lagged 2.4 s, and the frames sent meanwhile were lost beyond the queue depth).
   Acknowledgements follow DDS heartbeats (1-3 s). The time held is handed back (``on_release``)
   so the source delays its clock by it: nothing is released in a burst afterwards.
"""
from __future__ import annotations

import time
from typing import Callable, Optional, Sequence

OTHERS_GRACE_S = 0.5   # how long the other replayed topics may lag the skeletons' subscribers


class ReplayGate:
    """``may_poll(...)`` before each poll of the source; ``published(n)`` after it.

    States: ``subscribers`` (waiting before the first frame), ``acks`` (first frame out, waiting
    for its acknowledgements), ``playing``. ``want`` 0: playing at once. ``hold_first`` False (a
    live source, which cannot be held): only step 1, then playing from the first frame on;
    ``label`` names the source in the log lines.
    """

    def __init__(self, want: int, timeout_s: float, clock: Callable[[], float] = time.monotonic,
                 info: Callable[[str], None] = lambda m: None,
                 warn: Callable[[str], None] = lambda m: None,
                 on_release: Callable[[float], None] = lambda held_s: None,
                 topic: str = '/kinect/skeletons', hold_first: bool = True,
                 label: str = 'replay'):
        self.want = int(want)
        self.timeout_s = float(timeout_s)
        self.clock = clock
        self.info, self.warn, self.on_release = info, warn, on_release
        self.topic = topic
        self.hold_first = bool(hold_first)
        self.label = label
        self.state = 'subscribers' if self.want > 0 else 'playing'
        self._waiting_since: Optional[float] = None
        self._main_ready_at: Optional[float] = None
        self._first_at: Optional[float] = None
        self._first_pending = False

    @property
    def playing(self) -> bool:
        return self.state == 'playing'

    def may_poll(self, subscribers: Callable[[], int],
                 others_without_subscriber: Callable[[], Sequence[str]] = lambda: (),
                 acked: Callable[[], bool] = lambda: True) -> bool:
        """Whether the source may be polled now (the callables are only asked when needed)."""
        if self.state == 'subscribers':
            if self._subscribers_ready(subscribers(), others_without_subscriber):
                self.state = 'first'
                return True
            return False
        if self.state == 'acks':
            return not self._acks_pending(acked())
        return True

    def published(self, n_outputs: int) -> None:
        """The poll allowed by :meth:`may_poll` published ``n_outputs`` messages (a first poll
        with nothing due plays on without holding)."""
        if self.state == 'first':
            self._first_at = self.clock()
            self.state = 'acks' if n_outputs and self.hold_first else 'playing'

    def _subscribers_ready(self, have: int, others: Callable[[], Sequence[str]]) -> bool:
        now = self.clock()
        if self._waiting_since is None:
            self._waiting_since = now
            self.info(f'{self.label}: waiting for {self.want} subscriber(s) on {self.topic} before '
                      'the first frame')
        if have >= self.want:
            if self._main_ready_at is None:
                self._main_ready_at = now
            if others() and now - self._main_ready_at < OTHERS_GRACE_S:
                return False
            self.info(f'{self.label}: {have} subscriber(s) after {now - self._waiting_since:.1f} s: '
                      'playing')
            return True
        if now - self._waiting_since >= self.timeout_s:
            self.warn(f'{self.label}: only {have} of {self.want} subscriber(s) on {self.topic} after '
                      f'{self.timeout_s:g} s: playing anyway (frames may be lost)')
            return True
        return False

    def _acks_pending(self, acked: bool) -> bool:
        held = self.clock() - self._first_at
        if not acked and held < self.timeout_s:
            return True
        self.state = 'playing'
        self.on_release(held)
        if acked:
            self.info(f'replay: the first frame acknowledged by every subscriber after '
                      f'{held:.2f} s: playing on')
        else:
            self.warn(f'replay: the first frame not acknowledged by every subscriber after '
                      f'{held:.1f} s: playing on')
        return False
