"""When the fusion node publishes (pose_reconstruction.fusion_clock), on a fake wall clock: one
output per capture of the reference sensor, as soon as the others caught up, at most one frame
period late, no wait for a sensor that stopped."""
import numpy as np
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


def _run(c, lags, start=0, deliver=0.002, timer=True):
    """Sensor a every period (arriving ``deliver`` after capture), b ``lag`` s after a's arrival
    with a stamp at or after a's; the node's deadline timer fired when due. Returns (stamp,
    wall time published) in order."""
    out = []
    for k, lag in enumerate(lags, start):
        t = k * P
        wa = t + deliver
        out += [(s, wa) for s in c.on_frame('a', ns(t), wa)]
        d = c.deadline()
        if timer and d is not None and (lag is None or d < wa + lag):
            out += [(s, d) for s in c.on_timer(d)]
        if lag is not None:
            out += [(s, wa + lag) for s in c.on_frame('b', ns(t + lag), wa + lag)]
    return out


def test_a_sensor_trailing_beyond_the_bound_is_not_waited_for_once_its_lag_is_known():
    c = FusionClock(['a', 'b'], max_wait_s=0.005)
    out = _run(c, [0.020] * 40)
    assert [s for s, _ in out] == [ns(k * P) for k in range(40)]    # every stamp, once
    waits = [w - (s / NS + 0.002) for s, w in out]
    # b unheard at first (not waited for), then unknown lag: waited for up to the bound, 5 ms
    assert max(waits[1:6]) == pytest.approx(0.005)
    # from then on its 20 ms lag is known to exceed the bound: published on a's arrival
    assert all(abs(w) < 1e-9 for w in waits[7:])
    assert c.expected_lag('b') == pytest.approx(0.020) and c.wait_for('b') == 0.0
    assert c.early >= 30


def test_a_sensor_close_in_phase_is_waited_for_and_a_late_frame_costs_its_lag_not_a_period():
    c = FusionClock(['a', 'b'], max_wait_s=0.005)
    out = _run(c, [0.0015] * 20)
    assert c.forced == 0                                   # every stamp had b's frame
    assert all(w - (s / NS + 0.002) == pytest.approx(0.0015) for s, w in out[1:])
    assert c.wait_for('b') == pytest.approx(0.0015 + 0.003)
    # b's next frame does not come: published 4.5 ms after a's arrival, not one period
    out = _run(c, [None], start=20)
    assert out == [(ns(20 * P), pytest.approx(20 * P + 0.002 + 0.0045))]
    assert c.forced == 1


def test_the_wait_follows_a_sensor_whose_phase_changes():
    c = FusionClock(['a', 'b'], max_wait_s=0.005)
    _run(c, [0.020] * 30)
    assert c.wait_for('b') == 0.0
    _run(c, [0.001] * 30, start=30)      # b re-phased (restarted): 1 ms after a
    assert c.wait_for('b') == pytest.approx(0.004)
    out = _run(c, [0.001] * 3, start=60)
    assert [w - (s / NS + 0.002) for s, w in out] == [pytest.approx(0.001)] * 3


def test_the_default_bound_waits_up_to_a_period_and_the_bound_is_checked():
    c = FusionClock(['a', 'b'])
    out = _run(c, [0.020] * 20)
    assert c.forced == 0 and all(w - (s / NS + 0.002) == pytest.approx(0.020) for s, w in out[1:])
    with pytest.raises(ValueError, match='max_wait_s'):
        FusionClock(['a', 'b'], max_wait_s=0.05)
    with pytest.raises(ValueError, match='max_wait_s'):
        FusionClock(['a', 'b'], max_wait_s=-0.001)


def test_the_expected_lag_is_numpys_percentile_of_the_recent_lags_after_every_frame():
    """The lag a wait covers: np.percentile (linear) of the sensor's last LAG_WINDOW lags, the
    same value after every new lag (it is kept between them, not recomputed per arrival)."""
    import numpy as np
    from pose_reconstruction.fusion_clock import LAG_MIN_SAMPLES, LAG_QUANTILE
    rng = np.random.default_rng(3)
    c = FusionClock(['a', 'b'], max_wait_s=0.005)
    lags = np.concatenate([rng.random(40) * 0.008, np.full(10, 0.003), rng.random(30) * 0.03])
    for k, lag in enumerate(lags.tolist()):
        _run(c, [lag], start=k)
        want = (None if len(c.lags['b']) < LAG_MIN_SAMPLES
                else float(np.percentile(np.array(c.lags['b']), LAG_QUANTILE)))
        assert c.expected_lag('b') == want
        assert c.expected_lag('b') == want   # asked again: the kept value


def test_sorted_quantile_is_numpys_linear_quantile_to_the_bit():
    """The window quantile the fusion clock and the plausibility floor use equals np.quantile
    ('linear') bit for bit: odd and even lengths, ties, negative values, q at 0, 1 and between."""
    from pose_reconstruction.quantile import sorted_quantile
    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 7, 30, 31):
        v = np.sort(np.round(rng.normal(0.0, 0.01, n), 4))   # rounded: ties happen
        for q in (0.0, 0.05, 0.25, 0.5, 0.9, 0.95, 1.0, rng.uniform()):
            assert sorted_quantile(list(v), q) == float(np.quantile(v, q))
