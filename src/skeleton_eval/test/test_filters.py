"""Baseline joint filters: Kinect SDK v1 Holt double exponential and One Euro, on hand cases."""
import numpy as np
import pytest

from skeleton_core.filters import HOLT_DEFAULTS, HoltFilter, OneEuroFilter
from skeleton_core.model import INFERRED, NOT_TRACKED, NUM_JOINTS, TRACKED


def _frame(x):
    p = np.zeros((NUM_JOINTS, 3))
    p[:, 0] = x
    return p


def test_holt_defaults_are_the_sdk_defaults():
    assert HOLT_DEFAULTS == dict(smoothing=0.5, correction=0.5, prediction=0.5,
                                 jitter_radius=0.05, max_deviation_radius=0.04)


def test_holt_second_frame_hand_computed_and_clamped():
    f = HoltFilter()
    assert np.allclose(f.update(_frame(0.0)), 0.0)  # first frame: raw, trend 0
    # second frame: filtered = mean(0, 1) = 0.5, trend = 0.5 * 0.5 = 0.25,
    # predicted = 0.5 + 0.25 * 0.5 = 0.625; |0.625 - 1| = 0.375 > 0.04 -> pulled to 1 - 0.04
    y = f.update(_frame(1.0))
    assert np.allclose(y[:, 0], 0.96)


def test_holt_third_frame_jitter_stage_hand_computed():
    f = HoltFilter(max_deviation_radius=10.0)  # no clamp: check the Holt recursion itself
    f.update(_frame(0.0))
    f.update(_frame(0.02))   # filtered 0.01, trend 0.005
    y = f.update(_frame(0.03))
    # jitter: d = 0.02 <= 0.05 -> x' = 0.03*0.4 + 0.01*0.6 = 0.018
    # holt: f = 0.018*0.5 + (0.01 + 0.005)*0.5 = 0.0165; b = 0.0065*0.5 + 0.005*0.5 = 0.00575
    # predicted = 0.0165 + 0.5*0.00575 = 0.019375
    assert np.allclose(y[:, 0], 0.019375)


def test_holt_converges_to_a_step():
    f = HoltFilter()
    for _ in range(5):
        f.update(_frame(0.0))
    ys = [f.update(_frame(1.0))[0, 0] for _ in range(60)]
    assert abs(ys[-1] - 1.0) < 1e-3
    assert max(ys) < 1.2  # bounded overshoot
    assert all(abs(y - 1.0) <= 0.04 + 1e-12 for y in ys)  # never farther than the deviation radius


def test_holt_not_tracked_passes_raw_and_restarts():
    f = HoltFilter()
    for _ in range(10):
        f.update(_frame(0.0))
    st = np.full(NUM_JOINTS, TRACKED, np.uint8)
    st[3] = NOT_TRACKED
    y = f.update(_frame(2.0), st)
    assert y[3, 0] == 2.0
    # after the gap joint 3 restarts from the raw value, the others are still filtered
    y = f.update(_frame(2.0))
    assert y[3, 0] == 2.0 and abs(y[0, 0] - 2.0) > 1e-3


def test_holt_inferred_uses_larger_radii():
    a, b = HoltFilter(), HoltFilter()
    for f in (a, b):
        f.update(_frame(0.0))
    st = np.full(NUM_JOINTS, INFERRED, np.uint8)
    ya = a.update(_frame(1.0))
    yb = b.update(_frame(1.0), st)
    assert np.allclose(ya[:, 0], 0.96) and np.allclose(yb[:, 0], 0.92)


def test_one_euro_passes_a_slow_ramp():
    f = OneEuroFilter()
    fps, v = 30.0, 0.1  # 10 cm/s
    xs = np.arange(150) / fps * v
    ys = np.array([f.update(_frame(x), stamp_ns=int(i * 1e9 / fps))[0, 0]
                   for i, x in enumerate(xs)])
    # steady-state lag of a first-order low-pass = v * tau, tau = 1/(2 pi (1 + beta v)), beta = 3
    tau = 1.0 / (2 * np.pi * (1.0 + 3.0 * v))
    assert abs((xs[-1] - ys[-1]) - v * tau) < 2e-3
    assert np.allclose(np.diff(ys[-30:]) * fps, v, rtol=0.02)


def test_one_euro_smooths_noise_at_rest():
    rng = np.random.default_rng(0)
    f = OneEuroFilter()
    noise = rng.normal(0.0, 0.01, 600)
    ys = np.array([f.update(_frame(n), stamp_ns=int(i * 1e9 / 30))[0, 0]
                   for i, n in enumerate(noise)])
    assert ys[60:].std() < 0.5 * noise[60:].std()


def test_one_euro_rejects_bad_parameters():
    with pytest.raises(ValueError):
        OneEuroFilter(min_cutoff=0.0)
    with pytest.raises(ValueError):
        HoltFilter(smoothing=1.0)


def test_one_euro_speed_scale_scales_the_minimum_cutoff_only():
    # cutoff_scale with speed_scale = 1 is a filter with min_cutoff * scale and the same speed term
    rng = np.random.default_rng(5)
    a = OneEuroFilter(2.0, 10.0, 1.0, num_joints=4)
    b = OneEuroFilter(0.5, 10.0, 1.0, num_joints=4)
    scale = np.full(4, 0.25)
    for t in range(40):
        x = rng.normal(0, 0.05, (4, 3)) + 0.02 * t
        stamp = t * 33_333_333
        assert np.allclose(a.update(x, None, stamp, scale, np.ones(4)), b.update(x, None, stamp),
                           atol=1e-12)


def _lead_filter(accel, num_joints=1):
    # the segment output's smoothing defaults (pose_reconstruction.segment_output)
    return OneEuroFilter(1.3, 3.0, 2.0, num_joints=num_joints, lead_accel=accel)


def _run(f, xs, lead=None):
    lead = np.ones(1) if lead is None else lead
    return np.array([f.update(x, None, int(i * 1e9 / 30), lead=lead) for i, x in enumerate(xs)])


def test_lead_with_acceleration_term_has_no_lag_on_a_ramp():
    from skeleton_eval.metrics import added_latency_ms, velocity_xcorr, xcorr_latency_ms
    t = np.arange(150) / 30.0
    ramp = np.zeros((150, 1, 3))
    ramp[:, 0, 0] = 0.5 * t                    # 0.5 m/s
    out = _run(_lead_filter(0.75), ramp)
    assert added_latency_ms(out[30:], ramp[30:]) <= 5.0
    assert abs(xcorr_latency_ms(velocity_xcorr(out[30:], ramp[30:]))) <= 5.0
    assert np.abs(out[60:] - ramp[60:]).max() < 0.002


def test_acceleration_term_removes_the_lag_when_the_motion_accelerates():
    from skeleton_eval.metrics import velocity_xcorr, xcorr_latency_ms
    # constant acceleration x = a t^2 / 2 from rest: the delay at the end (error / speed) is small
    t = np.arange(90) / 30.0
    acc = np.zeros((90, 1, 3))
    acc[:, 0, 0] = 0.5 * 0.05 * t ** 2          # 0.05 m/s^2
    lag_ms = lambda out: (acc[-1, 0, 0] - out[-1, 0, 0]) / (0.05 * t[-1]) * 1000.0  # noqa: E731
    assert abs(lag_ms(_run(_lead_filter(0.75), acc))) <= 5.0
    # a 1 Hz swing (the acceleration changes all the time): the velocity the lead uses trails by
    # its own low-pass lag, so the lead alone falls short; the acceleration term adds it back
    t = np.arange(300) / 30.0
    sw = np.zeros((300, 1, 3))
    sw[:, 0, 0] = 0.2 * np.sin(2 * np.pi * 1.0 * t)
    plain = _run(_lead_filter(0.0), sw)
    led = _run(_lead_filter(0.75), sw)
    assert xcorr_latency_ms(velocity_xcorr(plain[60:], sw[60:])) > 8.0
    assert abs(xcorr_latency_ms(velocity_xcorr(led[60:], sw[60:]))) <= 5.0
    assert np.abs(led[60:] - sw[60:]).max() < 0.5 * np.abs(plain[60:] - sw[60:]).max()
    # the numpy fast path (every row valid) and the masked path agree
    f1, f2 = _lead_filter(0.75, 2), _lead_filter(0.75, 2)
    xs = np.repeat(sw, 2, axis=1)
    a = np.array([f1.update(x, None, int(i * 1e9 / 30), lead=np.ones(2)) for i, x in enumerate(xs)])
    st = np.full(2, TRACKED)
    b = np.array([f2.update(x, st, int(i * 1e9 / 30), lead=np.ones(2)) for i, x in enumerate(xs)])
    assert np.allclose(a, b)


def test_acceleration_stage_keeps_the_rest_quiet_and_the_swing_on_time():
    # the lead's acceleration (a second derivative) is where its noise is: at rest the lead with
    # the full acceleration term nearly doubles the jitter of the plain low-pass; the acceleration
    # passed through its own One Euro stage (segment_output defaults: gain 1, 0.25 Hz + 3 Hz per
    # m/s^2) keeps the rest as quiet as the plain low-pass and the 1 Hz swing not behind
    from skeleton_eval.metrics import velocity_xcorr, xcorr_latency_ms
    rng = np.random.default_rng(0)
    rest = rng.normal(0.0, 0.004, (300, 1, 3))                 # 4 mm sensor noise, no motion
    t = np.arange(300) / 30.0
    sw = np.zeros((300, 1, 3))
    sw[:, 0, 0] = 0.2 * np.sin(2 * np.pi * 1.0 * t)

    def jitter(p):
        return np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=-1).mean() * 30.0 ** 2

    def make(num_joints=1, **kw):
        return OneEuroFilter(1.3, 3.0, 2.0, num_joints=num_joints, lead_accel=1.0, **kw)

    plain = jitter(_run(OneEuroFilter(1.3, 3.0, 2.0, num_joints=1), rest)[30:])
    bare = jitter(_run(make(), rest)[30:])
    staged = make(accel_cutoff=0.25, accel_beta=3.0)
    assert bare > 1.6 * plain
    assert jitter(_run(staged, rest)[30:]) <= 1.15 * plain
    staged.reset()
    lag = xcorr_latency_ms(velocity_xcorr(_run(staged, sw)[60:], sw[60:]))
    assert -10.0 <= lag <= 5.0
    # a fixed heavy cutoff (no acceleration-dependent term) would give the lag back
    fixed = _run(make(accel_cutoff=0.25), sw)
    assert xcorr_latency_ms(velocity_xcorr(fixed[60:], sw[60:])) > 8.0
    # the ramp (no acceleration) is untouched by the stage
    ramp = np.zeros((150, 1, 3))
    ramp[:, 0, 0] = 0.5 * np.arange(150) / 30.0
    out = _run(make(accel_cutoff=0.25, accel_beta=3.0), ramp)
    assert abs(xcorr_latency_ms(velocity_xcorr(out[30:], ramp[30:]))) <= 5.0
    # the numpy fast path (every row valid) and the masked path agree
    f1, f2 = (make(accel_cutoff=0.25, accel_beta=3.0, num_joints=2) for _ in range(2))
    xs = np.repeat(sw + rng.normal(0.0, 0.004, sw.shape), 2, axis=1)
    a = np.array([f1.update(x, None, int(i * 1e9 / 30), lead=np.ones(2)) for i, x in enumerate(xs)])
    st = np.full(2, TRACKED)
    b = np.array([f2.update(x, st, int(i * 1e9 / 30), lead=np.ones(2)) for i, x in enumerate(xs)])
    assert np.allclose(a, b)


def test_lead_parameters_are_validated():
    with pytest.raises(ValueError):
        OneEuroFilter(lead_accel=-0.5)
    with pytest.raises(ValueError):
        OneEuroFilter(accel_cutoff=-1.0)
    with pytest.raises(ValueError):
        OneEuroFilter(accel_beta=-1.0)


def _trusted_lead(**kw):
    # the segment output's smoothing of a segment it takes from the sensor (the cutoff times
    # smooth_trusted_scale 4, the acceleration stage on)
    return OneEuroFilter(1.3 * 4, 3.0, 2.0, num_joints=kw.pop('num_joints', 1), lead_accel=1.0,
                         accel_cutoff=0.25, accel_beta=3.0, **kw)


def test_lead_speed_fades_the_lead_on_slow_noise_and_bounds_the_lag_it_leaves():
    from skeleton_eval.metrics import velocity_xcorr, xcorr_latency_ms
    # a joint at rest with the sensor's slow wander (4 mm, correlated over 0.3 s) and 2 mm white
    # noise: the full lead adds the wander's velocity back (further from the truth than the plain
    # low-pass); faded below 0.1 m/s it is not
    rng = np.random.default_rng(1)
    n = 900
    phi = np.exp(-1.0 / (30 * 0.3))
    wander = np.zeros((n, 1, 3))
    for i in range(1, n):
        wander[i] = phi * wander[i - 1] + np.sqrt(1 - phi ** 2) * rng.normal(0.0, 0.004, (1, 3))
    rest = wander + rng.normal(0.0, 0.002, (n, 1, 3))

    def err(out):
        return np.linalg.norm(out[30:], axis=-1).mean()

    plain = err(_run(OneEuroFilter(1.3 * 4, 3.0, 2.0, num_joints=1), rest))
    full = err(_run(_trusted_lead(), rest))
    faded = err(_run(_trusted_lead(lead_speed=0.1), rest))
    assert full > plain
    assert faded < plain
    # on a ramp the lag left is at most tau * lead_speed / 2 (tau = 1 / (2 pi 5.2 Hz)); the full
    # lead leaves none
    tau = 1.0 / (2 * np.pi * 1.3 * 4)
    for v in (0.05, 0.1, 0.2, 1.0):
        ramp = np.zeros((150, 1, 3))
        ramp[:, 0, 0] = v * np.arange(150) / 30.0
        gap = np.abs(_run(_trusted_lead(lead_speed=0.1), ramp)[90:] - ramp[90:]).max()
        assert gap <= tau * 0.1 / 2 * 1.05
        assert np.abs(_run(_trusted_lead(), ramp)[90:] - ramp[90:]).max() < 1e-4
    # a 1 Hz swing of 0.2 m (up to 1.3 m/s) keeps its lead: not behind
    t = np.arange(300) / 30.0
    sw = np.zeros((300, 1, 3))
    sw[:, 0, 0] = 0.2 * np.sin(2 * np.pi * 1.0 * t)
    assert abs(xcorr_latency_ms(velocity_xcorr(_run(_trusted_lead(lead_speed=0.1), sw)[60:],
                                               sw[60:]))) <= 5.0
    # the numpy fast path (every row valid) and the masked path agree
    f1, f2 = (_trusted_lead(lead_speed=0.1, num_joints=2) for _ in range(2))
    xs = np.repeat(sw + rest[:300], 2, axis=1)
    a = np.array([f1.update(x, None, int(i * 1e9 / 30), lead=np.ones(2)) for i, x in enumerate(xs)])
    st = np.full(2, TRACKED)
    b = np.array([f2.update(x, st, int(i * 1e9 / 30), lead=np.ones(2)) for i, x in enumerate(xs)])
    assert np.allclose(a, b)
    with pytest.raises(ValueError):
        OneEuroFilter(lead_speed=-0.1)


def test_one_euro_update_many_equals_each_filters_update(monkeypatch):
    """Several users' filters updated together (stacked) give each filter's own numbers and
    state, with the lead, the acceleration stage and per-row scales; a filter that has not
    started every row, or has other settings, is updated alone."""
    rng = np.random.default_rng(1)
    stacks, stack = [], OneEuroFilter._update_stacked
    monkeypatch.setattr(OneEuroFilter, '_update_stacked',
                        staticmethod(lambda fs, *a: stacks.append(len(fs)) or stack(fs, *a)))
    for cfg in (dict(lead_accel=1.0, accel_cutoff=2.0, accel_beta=0.5, lead_speed=0.3),
                dict(lead_accel=1.0, accel_cutoff=2.0), dict(), dict(lead_accel=1.0)):
        alone, many = ([OneEuroFilter(m, 3.0, 2.0, num_joints=20, **cfg)
                        for m in (1.0, 1.0, 1.0, 1.0, 0.5)] for _ in range(2))
        stacked = 0
        for t in range(40):
            xs = [rng.normal(size=(20, 3)) * 0.1 + 0.01 * t for _ in range(5)]
            stamps = [(t + 1) * 33_333_333 + u * (t % 3) * 1_000_000 for u in range(5)]
            cs = [rng.uniform(0.2, 1.5, 20) for _ in range(5)]
            ss = [rng.uniform(0.5, 1.5, 20) if t % 2 else None for _ in range(5)]
            lead = [rng.uniform(0.0, 1.0, 20) for _ in range(5)]
            stacked += all(f.all_started for f in many[:4])
            want = [f.update(x, None, s, c, sp, ld)
                    for f, x, s, c, sp, ld in zip(alone, xs, stamps, cs, ss, lead)]
            got = OneEuroFilter.update_many(many, xs, stamps, cs, ss, lead)
            for a, b, fa, fb in zip(want, got, alone, many):
                assert np.array_equal(a, b)
                for name in ('x', 'raw', 'dx', 'fdx', 'fdd', 'fdd2'):
                    assert np.array_equal(getattr(fa, name), getattr(fb, name))
                assert fa.t_ns == fb.t_ns
        assert stacked >= 30 and stacks == [4] * stacked   # the four alike, stacked
        stacks.clear()
