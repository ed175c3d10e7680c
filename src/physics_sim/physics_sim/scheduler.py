"""When the physics node ticks and how much simulated time each tick covers: the input scheduler,
ROS-free, with an injected clock (tests drive it with a fake one, without sleeping).

With ``sync_to_input`` the node ticks as soon as a target arrives (phase-locked to the sensor: the
output leaves right after its input instead of up to one period later); its timer is only the
fallback that keeps the output rate when the input is slower or stops.

* An input tick simulates the frame time since the previous input tick, judged by the capture
  stamps and bounded to [0.5, 1.5] periods: frames delivered in a burst after a delay (a loaded
  machine) are each simulated for their own frame time and published at once.
* A target sooner than 0.75 period after the last input tick (by its stamp) is not ticked at once:
  one tick is deferred to 0.75 period after the last one (wall time), and simulates the frame time
  up to the newest target deferred meanwhile (input faster than the output rate).
* A timer tick (no input tick for a period) simulates the wall time since the last tick, bounded
  to [0.5, 1.5] periods: an overloaded machine gets a slower simulation at a kept output rate, not
  ever longer (costlier) ticks. Without ``sync_to_input`` every tick is one period.
* An input at the output rate (its frames at most ``ON_RATE`` periods apart by their stamps) is
  waited for ``MAX_TICK`` periods, not one, before the timer ticks: its arrival jitters by a few ms
  (two sensors fused, the reconstruction's varying time), and a timer firing just over a period
  after one input tick, a moment before the next input, would tick the simulation twice for one
  frame (two publishes, the second queued behind the first). A slower input (frames further
  apart) keeps the one-period wait, so the timer fills in at the output rate; an input that stops
  is taken over after at most ``MAX_TICK`` periods plus one timer period.
* The input's time is simulated once: what timer ticks simulated since the last input tick (input
  late, not stopped: a loaded machine) is taken off the next input tick's frame time (down to 0:
  that tick publishes the new target's stamp without stepping). Otherwise a late frame's time
  would be simulated twice, by the timer and by its own tick: more work exactly when the machine
  has least to give, and a character running ahead of its input.
* Each tick's time is spent in whole physics steps; the remainder is carried to the next tick
  (simulated time = the time ticked).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Optional

# the bounds of one tick's simulated time, in periods, and the shortest input-tick spacing
MIN_TICK = 0.5      # shorter ticks would publish nearly the same state again
MAX_TICK = 1.5      # longer ones cost more than a period of compute: the node would fall behind
DEFER_AFTER = 0.75  # a target closer than this (periods) to the last input tick waits for it
ON_RATE = 1.25      # frames at most this far apart (periods, by stamp): an input at the output
#                     rate, whose arrival jitter the timer allows for (it waits MAX_TICK periods)
TICK_KINDS = ('input', 'deferred', 'timer')
# a stamp this far (s) before the last input tick's is a bag loop or a restarted sensor: ticked
STAMP_JUMP_S = 1.0


@dataclass
class InputDecision:
    """What the node does with an arriving target: ``tick`` now simulating ``dt`` (None: the
    wall time, see :meth:`TickScheduler.tick_time`), or ``defer`` one tick by ``delay_s`` (arm a
    one-shot timer), or nothing (a deferred tick is armed already)."""

    action: str                  # 'tick' | 'defer' | 'wait'
    dt: Optional[float] = None
    delay_s: float = 0.0


class TickScheduler:
    def __init__(self, rate_hz: float, sync_to_input: bool = True,
                 clock: Callable[[], float] = time.monotonic):
        if rate_hz <= 0:
            raise ValueError(f'rate must be > 0 Hz, got {rate_hz}')
        self.period = 1.0 / rate_hz
        self.sync = bool(sync_to_input)
        self.clock = clock
        # ticks of each kind and the time they simulated (s), since construction (not reset);
        # timer ticks once an input has ticked (a timer tick beside the input is an extra publish)
        self.ticks = {k: 0 for k in TICK_KINDS}
        self.simulated = {k: 0.0 for k in TICK_KINDS}
        self.reset()

    def reset(self) -> None:
        self.last_tick: Optional[float] = None          # wall time of the last tick
        self.last_input_tick: Optional[float] = None    # ... of the last input (or deferred) tick
        self.last_input_stamp: Optional[float] = None   # capture stamp (s) of the last input tick
        self.pending_stamp: Optional[float] = None      # newest target waiting for a deferred tick
        self.deferred = False
        self.time_debt = 0.0
        self.timer_time = 0.0       # simulated by timer ticks since the last input tick (s)
        self._input_tick = False    # the next tick_time is an input (or deferred) tick's
        self._kind = 'timer'        # ... and which (counted)
        self.input_gap: Optional[float] = None   # stamp gap (s) of the last input tick's frame

    def _bounded(self, dt: float) -> float:
        return min(max(dt, MIN_TICK * self.period), MAX_TICK * self.period)

    # -- events ----------------------------------------------------------------------------------
    def on_input(self, stamp_s: float) -> InputDecision:
        """A target with capture stamp ``stamp_s`` arrived (sync_to_input)."""
        now = self.clock()
        last = self.last_input_stamp
        if last is None or stamp_s - last >= DEFER_AFTER * self.period \
                or stamp_s < last - STAMP_JUMP_S:
            self.deferred = False
            self.pending_stamp = None
            self.last_input_tick = now
            self.last_input_stamp = stamp_s
            self._input_tick = True
            self._kind = 'input'
            self.input_gap = None if last is None else stamp_s - last
            return InputDecision('tick', None if last is None
                                 else self._input_time(stamp_s - last))
        self.pending_stamp = stamp_s if self.pending_stamp is None else max(self.pending_stamp,
                                                                             stamp_s)
        if self.deferred:
            return InputDecision('wait')
        self.deferred = True
        delay = max(DEFER_AFTER * self.period - (now - self.last_input_tick), 1e-4)
        return InputDecision('defer', delay_s=delay)

    def on_deferred(self) -> Optional[float]:
        """The deferred tick is due: its simulated time (the frame time up to the newest target
        deferred; None when there is none: the wall time)."""
        self.deferred = False
        self.last_input_tick = self.clock()
        self._kind = 'deferred'
        stamp, self.pending_stamp = self.pending_stamp, None
        if stamp is None or self.last_input_stamp is None:
            return None
        self.input_gap = stamp - self.last_input_stamp
        dt = self._input_time(self.input_gap)
        self.last_input_stamp = stamp
        return dt

    def _input_time(self, stamp_gap: float) -> float:
        """An input tick's simulated time: its frame time (bounded) less what timer ticks
        simulated of it; what they simulated beyond it is owed by the next input tick (at most
        one period). After a gap in the input (stamps more than MAX_TICK periods apart: frames
        lost, or the input stopped) the timer simulated the gap: the tick simulates what it did
        not (at most MAX_TICK periods) and nothing is carried. A stamp going back (a bag loop)
        simulates one bounded frame time."""
        frame_time = self._bounded(stamp_gap)
        owed, self.timer_time = self.timer_time, 0.0
        self._input_tick = True
        if stamp_gap < 0:
            return frame_time
        if stamp_gap > MAX_TICK * self.period:
            return min(max(stamp_gap - owed, 0.0), MAX_TICK * self.period)
        if owed > frame_time:
            self.timer_time = min(owed - frame_time, self.period)
            return 0.0
        return frame_time - owed

    def timer_due(self) -> bool:
        """The timer fired: tick unless input ticked less than a period ago (``MAX_TICK`` periods
        for an input at the output rate: its arrival jitter is no reason to tick)."""
        if not self.sync or self.last_input_tick is None:
            return True
        wait = self.period
        if self.input_gap is not None and 0 <= self.input_gap <= ON_RATE * self.period:
            wait = MAX_TICK * self.period
        return self.clock() - self.last_input_tick >= wait - 1e-9

    def tick_time(self, dt: Optional[float] = None) -> float:
        """A tick happens now: its simulated time (``dt``, else the bounded wall time since the
        last tick with sync_to_input, else one period)."""
        now = self.clock()
        if dt is None and self.sync and self.last_tick is not None:
            dt = self._bounded(now - self.last_tick)
        elif dt is None:
            dt = self.period
        if self.sync and not self._input_tick and self.last_input_stamp is not None:
            self.timer_time += dt   # a timer tick while input is expected: owed by the next
        if self._kind != 'timer' or self.last_input_stamp is not None:   # (not before any input)
            self.ticks[self._kind] += 1
            self.simulated[self._kind] += dt
        self._input_tick = False
        self._kind = 'timer'
        self.last_tick = now
        return dt

    def steps(self, dt: float, timestep: float) -> int:
        """Whole physics steps of ``timestep`` for ``dt`` more seconds; the rest is carried."""
        self.time_debt += dt
        n = int(self.time_debt / timestep + 1e-9)
        self.time_debt -= n * timestep
        return n
