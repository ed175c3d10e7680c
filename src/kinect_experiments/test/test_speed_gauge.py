"""kinect_experiments.speed_gauge: the reference workload is deterministic, the factor is a
positive finite reading against the nominal time, twice the work reads about twice as slow, and
the bench's guard waits for a fast minute then refuses."""
import math

import pytest

from kinect_experiments import speed_gauge as sg


def test_the_workload_is_deterministic_and_checked():
    assert sg.workload() == sg.workload() == sg.CHECKSUM
    with pytest.raises(RuntimeError, match='no longer does the same work'):
        sg.measure(1, work=lambda: 1, checksum=2)


def test_a_reading_is_a_positive_finite_factor_against_the_nominal_time():
    r = sg.measure(2)
    assert len(r.runs_cpu_ms) == 2 and r.cpu_ms > 0 and r.wall_ms > 0
    assert math.isfinite(r.factor) and r.factor > 0
    assert r.factor == pytest.approx(r.cpu_ms / sg.NOMINAL_MS)
    d = r.as_dict()
    assert d['nominal_ms'] == sg.NOMINAL_MS and d['factor'] == round(r.factor, 3)
    assert sg.label(d, None) == f"machine speed x{r.factor:.2f} before / - after"
    with pytest.raises(ValueError):
        sg.measure(0)


def test_twice_the_work_reads_about_twice_as_slow():
    def twice():
        return sg.workload() + sg.workload()
    # interleaved, and the fastest reading of each: this host's speed can change from one second
    # to the next, and each side's fastest reading is most likely taken at the fast speed
    single, double = [], []
    for _ in range(4):
        single.append(sg.measure(3).factor)
        double.append(sg.measure(3, work=twice, checksum=2 * sg.CHECKSUM).factor)
    assert 1.5 < min(double) / min(single) < 2.7


def test_the_guard_waits_for_a_fast_minute_then_refuses():
    t = [0.0]

    def gauge_of(factors):
        it = iter(factors)

        def gauge():
            t[0] += 1.0
            return sg.Reading(next(it), 0.0, 0.0)
        return gauge

    def sleep(s):
        t[0] += s
    chk = sg.wait_for_speed(1.3, 60.0, gauge_of([1.8, 1.5, 1.1]), lambda: t[0], sleep)
    assert chk.ok and chk.tries == 3 and chk.reading.factor == 1.1 and chk.waited_s == 23.0
    t[0] = 0.0
    chk = sg.wait_for_speed(1.3, 30.0, gauge_of([1.8] * 10), lambda: t[0], sleep)
    assert not chk.ok and chk.reading.factor == 1.8 and chk.waited_s >= 30.0 and chk.tries == 4
