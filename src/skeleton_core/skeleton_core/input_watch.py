"""A stream input that is matched but receives nothing (pure Python, no rclpy).

A subscriber restarted after a crash can be matched with its publisher (the graph and the
subscription's match count both say so) and still receive nothing, for the rest of its life: with
Fast DDS's shared-memory transport the other processes may go on writing into the dead process's
segment (docs/recovery.md, "A restarted node receives nothing"). It cannot be repaired from the
subscriber's side; it can be seen. :class:`InputWatch` is fed, about once a second, with the time,
the input's matched publisher count and the messages received so far, and says when the input has
had a publisher continuously for ``silent_after_s`` without one message since the match began (once
per episode), and when that ends. For stream inputs only: a latched topic is silent by design.
"""
from __future__ import annotations

from typing import Optional

# how long a matched stream input may go without its first message before it is reported (s):
# a stream publishes at 30 Hz; a replay waits 1-3 s for its subscribers' acknowledgement
SILENT_AFTER_S = 10.0

SILENT = 'silent'          # matched for silent_after_s, nothing received since the match began
RECOVERED = 'recovered'    # a silent input received a message
UNMATCHED = 'unmatched'    # a silent input's publishers went away (a new match is a new episode)


class InputWatch:
    """The state of one watched input. ``count`` is the input callback's counter (one integer
    increment per message, the only cost on the hot path); :meth:`check` takes the count
    explicitly, so that it is tested with a fake clock and fake counts.

    An episode begins when the input has a matched publisher after it had none (or at the first
    check); the messages counted since the last check without a publisher belong to it. An
    episode in which a message arrived is healthy for as long as it lasts (a publisher that stops
    after sending is not this fault: the node's rate in its diagnostics shows a stall); one
    without a message for ``silent_after_s`` is reported once (:data:`SILENT`), and again when a
    message arrives (:data:`RECOVERED`) or the publishers go (:data:`UNMATCHED`)."""

    def __init__(self, topic: str, silent_after_s: Optional[float] = None):
        self.topic = topic
        self.silent_after_s = SILENT_AFTER_S if silent_after_s is None else float(silent_after_s)
        self.count = 0
        self.silent = False
        self.publishers = 0
        self._since: Optional[float] = None   # when the current episode began
        self._base = 0                        # the count when no publisher was last seen
        self._settled = False                 # a message arrived in this episode

    def check(self, now: float, publishers: int, received: Optional[int] = None) -> Optional[str]:
        """One look at the input: ``publishers`` matched now, ``received`` messages so far
        (default: :attr:`count`). Returns :data:`SILENT`, :data:`RECOVERED`, :data:`UNMATCHED`
        when the state changes, else None."""
        received = self.count if received is None else int(received)
        self.publishers = int(publishers)
        if publishers <= 0:
            self._since, self._settled, self._base = None, False, received
            if self.silent:
                self.silent = False
                return UNMATCHED
            return None
        if self._since is None:
            self._since = now
        if received > self._base:
            self._settled = True
            if self.silent:
                self.silent = False
                return RECOVERED
            return None
        if not self._settled and not self.silent and now - self._since >= self.silent_after_s:
            self.silent = True
            return SILENT
        return None

    def silent_for(self, now: float) -> float:
        """Seconds since the current episode began (0 without a publisher)."""
        return 0.0 if self._since is None else now - self._since

    def message(self, event: str, now: float) -> str:
        """The log line of ``event`` (one of the values :meth:`check` returns)."""
        if event == SILENT:
            n = self.publishers
            return (f'input {self.topic}: {n} publisher{"s" if n != 1 else ""} matched for '
                    f'{self.silent_for(now):.0f} s, nothing received (a paused publisher, or a '
                    'DDS delivery fault after a crash: restart the publisher; docs/recovery.md)')
        if event == RECOVERED:
            return f'input {self.topic}: receiving now (after {self.silent_for(now):.0f} s silent)'
        return f'input {self.topic}: no publisher matched any more (was silent)'

    def status(self) -> str:
        """The diagnostics value of a silent input."""
        return f'{self.publishers} matched, nothing received'
