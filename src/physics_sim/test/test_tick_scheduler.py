"""The physics input scheduler (physics_sim.scheduler) on a fake clock: no sleeping, no ROS."""
import heapq

import numpy as np
import pytest

from physics_sim.scheduler import MAX_TICK, MIN_TICK, TickScheduler

RATE = 30.0
P = 1.0 / RATE


class Clock:
    def __init__(self, t=100.0):
        self.t = t

    def __call__(self):
        return self.t


def make(sync=True):
    clock = Clock()
    return TickScheduler(RATE, sync, clock=clock), clock


def test_every_input_at_the_output_rate_ticks_at_once_for_its_frame_time():
    s, clock = make()
    d = s.on_input(5.0)
    assert d.action == 'tick' and d.dt is None          # first: no frame time yet
    for i in range(1, 10):
        clock.t += P + (0.004 if i % 2 else -0.003)     # delivery jitter does not matter,
        d = s.on_input(5.0 + i * P)                      # the stamps do
        assert d.action == 'tick' and d.dt == pytest.approx(P)


def test_a_frame_time_is_bounded_to_half_and_one_and_a_half_periods():
    s, clock = make()
    s.on_input(5.0)
    assert s.on_input(5.0 + 10 * P).dt == pytest.approx(MAX_TICK * P)   # a gap: not 10 periods
    assert s.on_input(4.0 + 10 * P - 0.5).dt == pytest.approx(MIN_TICK * P)   # a bag loop
    # a loop by more than a second ticks at once (a restarted sensor), not deferred
    assert s.on_input(1.0).action == 'tick'


def test_input_faster_than_the_rate_is_deferred_to_three_quarters_of_a_period():
    s, clock = make()
    s.on_input(5.0)
    clock.t += 0.010
    d = s.on_input(5.0 + 0.010)                          # 10 ms after by its stamp
    assert d.action == 'defer' and d.delay_s == pytest.approx(0.75 * P - 0.010)
    clock.t += 0.005
    assert s.on_input(5.0 + 0.015).action == 'wait'     # one deferred tick at a time
    clock.t += d.delay_s - 0.005
    # the deferred tick simulates the frame time up to the newest deferred target (bounded)
    assert s.on_deferred() == pytest.approx(MIN_TICK * P)
    assert s.last_input_stamp == pytest.approx(5.015)
    clock.t += P
    assert s.on_input(5.015 + P).dt == pytest.approx(P)  # and the next input follows it


def test_an_input_tick_cancels_a_deferred_one():
    s, clock = make()
    s.on_input(5.0)
    assert s.on_input(5.01).action == 'defer'
    assert s.on_input(5.0 + P).action == 'tick'          # a later frame came first
    assert not s.deferred and s.pending_stamp is None


def test_the_timer_is_the_fallback_when_input_stops():
    s, clock = make()
    s.on_input(5.0)
    s.tick_time(None)
    clock.t += 0.5 * P
    assert not s.timer_due()                             # input ticking: the timer waits
    clock.t += P
    assert s.timer_due()
    # a timer tick simulates the wall time since the last tick, bounded
    assert s.tick_time() == pytest.approx(MAX_TICK * P)
    clock.t += 0.9 * P
    assert s.tick_time() == pytest.approx(0.9 * P)
    clock.t += 0.1 * P
    assert s.tick_time() == pytest.approx(MIN_TICK * P)


def test_a_late_frame_is_simulated_once_not_by_the_timer_and_again_by_its_own_tick():
    s, clock = make()
    s.tick_time(s.on_input(5.0).dt)
    total = 0.0
    for i in range(1, 31):                               # a loaded machine: every other frame
        clock.t += (1.6 if i % 2 else 0.4) * P           # late, the timer firing before it
        if s.timer_due():
            total += s.tick_time()
        d = s.on_input(5.0 + i * P)
        assert d.action == 'tick'
        total += s.tick_time(d.dt)
        # the simulated time follows the input's (stamps), not the sum of both ticks (the
        # timer's tick, bounded to MAX_TICK periods, is at most half a period ahead of it)
        assert total == pytest.approx(i * P, abs=0.5 * P + 1e-9)
    assert s.ticks['timer'] == 15
    # on time again: each input tick simulates its frame time
    s.tick_time(s.on_input(5.0 + 31 * P).dt)
    clock.t += P
    d = s.on_input(5.0 + 32 * P)
    assert d.dt == pytest.approx(P) and s.tick_time(d.dt) == pytest.approx(P)


def test_a_deferred_tick_pays_off_what_the_timer_simulated():
    s, clock = make()
    s.tick_time(s.on_input(5.0).dt)
    clock.t += 1.2 * P
    assert s.timer_due() and s.tick_time() == pytest.approx(1.2 * P)
    assert s.on_input(5.0 + P).dt == 0.0                 # 1 period of stamps, 1.2 simulated
    s.tick_time(0.0)
    assert s.timer_time == pytest.approx(0.2 * P)        # owed by the next
    clock.t += 0.1 * P
    assert s.on_input(5.0 + 1.5 * P).action == 'defer'
    assert s.on_deferred() == pytest.approx(0.3 * P)    # its frame time less what is owed
    # input stopped for a second, then back: the timer simulated the gap; nothing owed
    clock.t += 0.1 * P
    s.tick_time()
    assert s.on_input(6.6).dt == pytest.approx(MAX_TICK * P)


def test_without_sync_every_tick_is_one_period_and_the_timer_always_ticks():
    s, clock = make(sync=False)
    assert s.timer_due()
    clock.t += 5.0
    assert s.tick_time() == pytest.approx(P)
    clock.t += 5.0
    assert s.tick_time() == pytest.approx(P) and s.timer_due()


def test_whole_steps_carry_the_remainder():
    s, _ = make()
    ts = 0.002
    steps = [s.steps(0.005, ts) for _ in range(4)]       # 2.5 steps per tick
    assert steps == [2, 3, 2, 3] and s.time_debt == pytest.approx(0.0)
    with pytest.raises(ValueError):
        TickScheduler(0.0)


def run(arrivals, stamps, phase=0.0, end=None):
    """The node's executor on a fake clock: inputs at ``arrivals`` (wall s) with capture
    ``stamps``, the output-rate timer firing ``phase`` + k periods after the first arrival, the
    one-shot deferred tick;
    every tick's simulated time through tick_time. Returns the scheduler (its tick counters) and
    the ticks as (wall time, kind)."""
    clock = Clock(0.0)
    s = TickScheduler(RATE, clock=clock)
    end = arrivals[-1] + 0.5 * P if end is None else end
    events = [(a, 0, st) for a, st in zip(arrivals, stamps)]
    events += [(t, 1, None) for t in np.arange(arrivals[0] + phase, end, P)]
    heapq.heapify(events)
    ticks, deferred_at = [], None
    while events:
        clock.t, what, stamp = heapq.heappop(events)
        before = dict(s.ticks)
        if what == 0:
            d = s.on_input(stamp)
            if d.action == 'tick':
                deferred_at = None
                s.tick_time(d.dt)
            elif d.action == 'defer':
                deferred_at = clock.t + d.delay_s
                heapq.heappush(events, (deferred_at, 2, None))
        elif what == 1:
            if s.timer_due():
                s.tick_time()
        elif clock.t == deferred_at:
            deferred_at = None
            s.tick_time(s.on_deferred())
        ticks += [(clock.t, k) for k in s.ticks if s.ticks[k] > before[k]]
    return s, ticks


def jittered(n, jitter_s, seed=0, latency_s=0.02):
    """n frames at the output rate (regular capture stamps), arriving latency_s later +- jitter."""
    stamps = 5.0 + np.arange(n) * P
    rng = np.random.default_rng(seed)
    arrivals = stamps + latency_s + rng.uniform(-jitter_s, jitter_s, n)
    return np.maximum.accumulate(arrivals), stamps   # (delivered in order)


@pytest.mark.parametrize('jitter_ms', [2.0, 5.0, 8.0])
def test_a_jittered_input_at_the_output_rate_ticks_once_per_frame_and_never_on_the_timer(
        jitter_ms):
    """Two sensors fused, six users reconstructed: the input arrives every period +- a few ms.
    Whatever the timer's phase against it, every frame ticks once, at its arrival, for its frame
    time: no timer tick between two frames (a second publish for one frame)."""
    arrivals, stamps = jittered(300, jitter_ms * 1e-3)
    for phase in np.linspace(0.0, P, 10, endpoint=False):
        s, ticks = run(arrivals, stamps, phase=phase, end=arrivals[-1])
        assert s.ticks == {'input': 300, 'deferred': 0, 'timer': 0}, (phase, s.ticks)
        assert sum(s.simulated.values()) == pytest.approx(300 * P)   # the first: one period


def test_an_input_that_stops_is_taken_over_by_the_timer_at_the_output_rate():
    arrivals, stamps = jittered(60, 0.004)
    for phase in np.linspace(0.0, P, 10, endpoint=False):
        s, ticks = run(arrivals, stamps, phase=phase, end=arrivals[-1] + 1.0)
        timer = [t for t, k in ticks if k == 'timer']
        assert arrivals[-1] + MAX_TICK * P <= timer[0] < arrivals[-1] + (MAX_TICK + 1) * P
        assert np.diff(timer) == pytest.approx(P)            # then every period
        assert len(timer) >= 30 - (MAX_TICK + 1)


@pytest.mark.parametrize('input_hz', [15.0, 20.0, 10.0])
def test_an_input_slower_than_the_output_rate_keeps_the_output_rate(input_hz):
    n = int(2 * input_hz)                                    # two seconds
    stamps = 5.0 + np.arange(n) / input_hz
    arrivals = stamps + 0.02 + np.random.default_rng(1).uniform(-0.003, 0.003, n)
    for phase in np.linspace(0.0, P, 10, endpoint=False):
        s, ticks = run(arrivals, stamps, phase=phase, end=arrivals[-1])
        assert s.ticks['input'] == n
        assert abs(len(ticks) - 2.0 * RATE) <= 2, (phase, s.ticks)


def test_frames_bunched_after_a_stall_tick_each_for_their_own_frame_time():
    """The node stalled (a loaded machine) for five periods: its timer and the five frames that
    waited in the input queue are delivered at once. Each frame ticks (its stamp published),
    the timer's tick included the time is simulated once: five frames, five periods."""
    s, clock = make()
    s.tick_time(s.on_input(5.0).dt)
    clock.t += 5.2 * P
    assert s.timer_due()
    total = s.tick_time()                                    # the timer's callback came first
    for i in range(1, 6):
        d = s.on_input(5.0 + i * P)
        assert d.action == 'tick'
        total += s.tick_time(d.dt)
    assert s.ticks == {'input': 6, 'deferred': 0, 'timer': 1}
    assert total == pytest.approx(5 * P)


@pytest.mark.parametrize('lost', [1, 2, 5])
def test_a_lost_frame_is_simulated_once_by_the_timer_or_the_next_frame(lost):
    """Frames lost upstream (``lost`` in a row): the timer fills the gap, and the next frame's
    tick simulates only what the timer did not, so the simulated time follows the input's
    stamps, not the gap twice."""
    arrivals, stamps = jittered(60, 0.003)
    keep = np.ones(60, bool)
    keep[30:30 + lost] = False
    for phase in np.linspace(0.0, P, 10, endpoint=False):
        s, ticks = run(arrivals[keep], stamps[keep], phase=phase, end=arrivals[-1])
        assert s.ticks['input'] == 60 - lost
        # the first tick simulates one period; then the stamps' span, within the carried part
        assert sum(s.simulated.values()) == pytest.approx(60 * P, abs=0.5 * P), (phase, lost)
