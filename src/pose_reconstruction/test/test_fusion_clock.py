"""When the fusion node publishes (pose_reconstruction.fusion_clock), on a fake wall clock: one
output per capture of the reference sensor, as soon as the others caught up, at most one frame
period late, no wait for a sensor that stopped."""
import pytest

from pose_reconstruction.fusion_clock import ABSENT_PERIODS, FRAME_PERIOD_S, FusionClock

P = FRAME_PERIOD_S
NS = 1_000_000_000


def ns(t):
    return int(round(t * NS))


def test_output_at_the_reference_stamps_once_the_other_sensor_caught_up():
    c = FusionClock(['a', 'b'])
    out = []
    # b captures 10 ms after a, every frame; each message arrives 2 ms after its capture
    for k in range(30):
        t = k * P
        out += [(s, t + 0.002) for s in c.on_frame('a', ns(t), t + 0.002)]
        out += [(s, t + 0.012) for s in c.on_frame('b', ns(t + 0.010), t + 0.012)]
    # the first frame of a is published on b's first frame (b was not heard before: not waited
    # for: a alone), then every frame of a once b's next frame arrived: 30 outputs, a's stamps
    assert [s for s, _ in out] == [ns(k * P) for k in range(30)]
    assert all(abs(w - (s / NS + 0.002)) < 1e-9 for s, w in out[:1])
    assert all(abs(w - (s / NS + 0.012)) < 1e-9 for s, w in out[1:])   # 10 ms wait: b's phase
    assert c.forced == 0 and c.deadline() is None


def test_a_late_sensor_is_waited_for_at_most_one_frame_period():
    c = FusionClock(['a', 'b'])
    assert c.on_frame('b', ns(0.0), 0.0) == [ns(0.0)]   # b alone: the reference
    assert c.on_frame('a', ns(0.0), 0.001) == []          # a is now, b has caught up: the
    assert c.last_out == ns(0.0)                          # stamp was published already
    assert c.on_frame('a', ns(P), P + 0.001) == []       # b's next frame is late
    assert c.deadline() == pytest.approx(2 * P + 0.001)
    assert c.on_timer(2 * P) == []                       # not yet
    assert c.on_timer(2 * P + 0.001) == [ns(P)]          # one period: published without b
    assert c.forced == 1
    assert c.on_frame('b', ns(P + 0.005), 2 * P + 0.01) == []   # late frame: nothing more
    # the next reference frame is not held for the stale one either
    assert c.on_frame('a', ns(2 * P), 2 * P + 0.011) == []
    assert c.on_frame('b', ns(2 * P + 0.005), 2 * P + 0.012) == [ns(2 * P)]


def test_a_missed_frame_is_published_when_the_next_reference_frame_comes():
    c = FusionClock(['a', 'b'])
    c.on_frame('b', ns(0.0), 0.0)
    c.on_frame('a', ns(0.0), 0.0)
    c.on_frame('a', ns(P), P)                            # b silent; the timer did not run
    assert c.on_frame('a', ns(2 * P), 2 * P) == [ns(P)]  # the older one goes out, unwaited
    assert c.pending == ns(2 * P)


def test_a_sensor_that_stopped_is_not_waited_for():
    c = FusionClock(['a', 'b'])
    c.on_frame('b', ns(0.0), 0.0)
    t = (ABSENT_PERIODS + 1) * P                          # b silent for longer than that
    assert c.on_frame('a', ns(t), t) == [ns(t)]          # at once
    assert c.present(t) == ['a']


def test_the_next_sensor_is_the_reference_when_the_first_stops():
    c = FusionClock(['a', 'b'])
    out = []
    for k in range(10):
        t = k * P
        out += c.on_frame('b', ns(t + 0.01), t + 0.011)   # a never delivers
    assert out == [ns(k * P + 0.01) for k in range(10)]


def test_old_or_repeated_reference_stamps_are_not_published_twice():
    c = FusionClock(['a'])
    assert c.on_frame('a', ns(1.0), 0.0) == [ns(1.0)]
    assert c.on_frame('a', ns(1.0), 0.01) == []
    assert c.on_frame('a', ns(0.9), 0.02) == []
    with pytest.raises(KeyError, match="unknown sensor 'x'"):
        c.on_frame('x', 0, 0.0)
    with pytest.raises(ValueError):
        FusionClock([])
