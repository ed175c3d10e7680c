"""Walking on the floor (Ishigaki 2009, Sec. 8.3): walking in place is recognised on the arms, the
character walks in the virtual world -- speed from the user's cadence and swing, direction from
the user's facing -- and arrives at the features (the continuous performance: floor -> water)."""
import numpy as np

from performance_control.controller import ControlParams, PerformanceController
from performance_control.features import load_world
from performance_control.locomotion import Walker
from performance_control.performances import (SENSOR_HEIGHT, imitation_stream, to_sensor,
                                              watched_performance)
from skeleton_core.model import HAND_LEFT, HAND_RIGHT

WORLD = load_world('playground')


def _swinging(period, amp=0.3, seconds=4.0, yaw=0.0):
    """Poses whose hands swing fore-aft in anti-phase (only the hands matter to the Walker)."""
    n = int(seconds * 30)
    p = np.zeros((n, 20, 3))
    t = np.arange(n) / 30
    x = amp * np.sin(2 * np.pi * t / period)
    c, s = np.cos(yaw), np.sin(yaw)
    for j, sign in ((HAND_LEFT, 1.0), (HAND_RIGHT, -1.0)):
        p[:, j, 0] = c * sign * x / 2
        p[:, j, 1] = s * sign * x / 2
    return p, t


def test_walker_speed_follows_the_users_cadence_and_stride():
    speeds = {}
    for period, amp in ((1.1, 0.3), (0.8, 0.3), (1.1, 0.45)):
        w = Walker(1.2, 1.1, 0.3 / np.sqrt(2))
        p, t = _swinging(period, amp)
        for i in range(len(p)):
            w.update(p[i], 0.0, t[i])
        assert abs(w.period() - period) < 0.1
        speeds[(period, amp)] = w.speed()
    assert abs(speeds[(1.1, 0.3)] - 1.2) < 0.1            # the example's gait: its speed
    assert speeds[(0.8, 0.3)] > 1.25 * speeds[(1.1, 0.3)]  # faster steps, faster walk
    assert speeds[(1.1, 0.45)] > 1.3 * speeds[(1.1, 0.3)]  # bigger swing, longer stride
    v = Walker(1.2, 1.1, 0.2).velocity(np.pi / 2)
    assert abs(v[0]) < 1e-9 and v[1] > 0                    # heading +90 deg: walks along +y
    # a swing that stopped: the time since the last crossing lengthens the period
    w = Walker(1.2, 1.1, 0.3 / np.sqrt(2))
    p, t = _swinging(1.1)
    for i in range(len(p)):
        w.update(p[i], 0.0, t[i])
    for k in range(60):
        w.update(np.zeros((20, 3)), 0.0, t[-1] + (k + 1) / 30)
    assert w.speed() < 0.6 * speeds[(1.1, 0.3)]


def test_walking_in_place_walks_the_character_forward_and_it_stops_with_the_user():
    f = WORLD.features['floor']
    p, windows = imitation_stream(f, np.random.default_rng(3000), pattern=((1.0, 5.0),),
                                  total=7.5)
    s, st = to_sensor(p, 'walk_test', 3000, True, states=True)
    ctl = PerformanceController(WORLD, ControlParams(sensor_height=SENSOR_HEIGHT))
    rows = [ctl.step(s[i], i / 30.0, st[i]) for i in range(len(s))]
    t = np.arange(len(rows)) / 30
    com = np.array([o.com for o in rows])
    walk = np.array([o.feature == 'floor' for o in rows])
    assert not walk[t < 1.0].any()                          # standing: no walk
    assert walk[(t > 1.5) & (t < 5.0)].mean() > 0.8
    assert com[t >= 5.5][0, 0] - com[0, 0] > 2.0            # walked forward (+x: its heading)
    assert abs(com[-1, 1] - com[0, 1]) < 0.5 * (com[-1, 0] - com[0, 0])
    assert np.ptp(com[t >= 6.5, 0]) < 0.1                   # the user stopped: so does it
    assert np.all(np.abs(com[:, 2] - com[0, 2]) < 0.2)      # upright on the floor throughout


def test_continuous_performance_bars_rope_water():
    """floor -> walk -> under the bars, jump to catch one -> swing -> drop -> walk -> rope ->
    climb -> drop -> walk (turning 45 deg right) -> into the water -> swim, by a
    performer who stops walking when the character has arrived at the rope."""
    ctl = PerformanceController(WORLD, ControlParams(sensor_height=SENSOR_HEIGHT))
    phase, rows = [], []

    def step(s, st, t):
        o = ctl.step(s, t, st)
        hands = {f for e, f in o.contacts.items() if e.startswith('Hand')}
        phase.append('bars' if 'monkey_bars' in hands else 'rope' if 'rope' in hands
                     else 'water' if ctl.dp.in_water else 'walk' if ctl.walking else '')
        rows.append(o)
        return o

    sched, rope_at = watched_performance(WORLD, 0, step)
    assert rope_at is not None                                  # arrived at the rope
    seq = [x for k, x in enumerate(phase) if x and x != next(
        (y for y in reversed(phase[:k]) if y), '')]
    assert seq == ['walk', 'bars', 'walk', 'rope', 'walk', 'water'], seq
    t = np.arange(len(rows)) / 30.0
    ph = np.array(phase)
    when = {}
    for a, w in sched:
        when.setdefault(w, []).append(a)
    jump = when['jump'][0]
    assert not (ph[t < jump] == 'bars').any()                 # caught with the jump, not before
    assert (ph[(t > jump + 0.5) & (t < when['lower the arms'][0] - 0.5)] == 'bars').mean() > 0.9
    com = np.array([o.com for o in rows])
    stand = com[0, 2]
    rope = ph == 'rope'
    assert not rope[t < rope_at].any()
    assert com[rope, 2].max() > stand + 1.0                     # climbed hand over hand
    first = phase.index('water')
    assert all(x == 'water' for x in phase[first:])           # stays in once in
    walking = ph == 'walk'
    assert np.all(com[walking, 2] > stand - 0.2)              # upright on the walks: no fall
    last = walking & (t > when['walk'][-1])
    assert last.any() and np.all(com[last, 2] < stand + 0.2)  # landed from the rope
    # the last walk turned 45 deg right: from the rope forward and to the right (-y)
    d = com[first] - com[np.nonzero(last)[0][0]]
    assert d[0] > 1.0 and d[1] < -1.0 and abs(abs(np.degrees(np.arctan2(d[1], d[0]))) - 45) < 20
    water = WORLD.features['water'].geoms[0]
    assert np.all(np.abs(com[-1] - water.vec('center')) <= water.vec('half'))
    # swimming, not standing on the pool's bottom: no foot holds the floor
    assert not any(e.startswith('Foot') for o in rows[-60:] for e in o.contacts)
    assert ctl.dp.unstable_steps == 0


def test_the_watched_performers_decisions_change_the_stream_only_after_they_are_taken():
    """The closed loop of :func:`watched_performance` (round 5): each decision -- stop
    for the bars, turn toward them, stop for the rope, walk on when the character rests short of
    it -- regenerates the stream; the frames the controller has already seen, through the sensor
    model, must be the same in the new stream (else the user would have done something else
    before deciding), and the decision must change what follows."""
    from performance_control.performances import (BARS_LATEST, ROPE_LATEST, ROPE_WAIT,
                                                  _watched_sensor, continuous_stream)
    seed = 3

    def frames(**kw):
        a, sched = continuous_stream(WORLD, np.random.default_rng(seed), rope_at=ROPE_LATEST,
                                     **kw)
        return _watched_sensor(a, seed, True)[0], sched

    walk_on, _ = frames(bars_at=BARS_LATEST)
    turned, _ = frames(bars_at=BARS_LATEST, approach=((2.5, -0.4),))
    stopped, _ = frames(bars_at=4.0, approach=((2.5, -0.4),))
    for before, after, t in ((walk_on, turned, 2.5), (turned, stopped, 4.0)):
        k = int(round(t * 30))
        assert np.array_equal(before[:k + 1], after[:k + 1])
        assert not np.allclose(before[k + 31], after[k + 31], atol=0.05)
    # stopped for the rope at r, then (the character rested short) walks on from r + ROPE_WAIT
    r, kw = 14.0, dict(bars_at=4.0, steer=0.3)
    a, s1 = continuous_stream(WORLD, np.random.default_rng(seed), rope_at=r, **kw)
    b, s2 = continuous_stream(WORLD, np.random.default_rng(seed), rope_at=ROPE_LATEST,
                              rope_stops=(r,), **kw)
    k = int(round((r + ROPE_WAIT) * 30))
    assert np.array_equal(a[:k + 1], b[:k + 1])
    assert ('climb' in [w for _, w in s1]) and (r, 'reach for the rope') in s2
    assert (r + ROPE_WAIT, 'walk') in s2
    # on the way to the rope, a course correction at 13 s (round 6)
    c, _ = continuous_stream(WORLD, np.random.default_rng(seed), rope_at=ROPE_LATEST,
                             rope_approach=((13.0, 0.5),), **kw)
    d, _ = continuous_stream(WORLD, np.random.default_rng(seed), rope_at=ROPE_LATEST, **kw)
    k = int(round(13.0 * 30))
    assert np.array_equal(c[:k + 1], d[:k + 1])
    assert not np.allclose(c[k + 31], d[k + 31], atol=0.05)
    # the character still short of the water at r + 17 s: the user walks on, swims later
    # (round 7; d swims at r + 17 from the rope at ROPE_LATEST)
    r = ROPE_LATEST
    e, s3 = continuous_stream(WORLD, np.random.default_rng(seed), rope_at=r, swim_at=r + 19.0,
                              **kw)
    k = int(round((r + 16.8) * 30))
    assert np.array_equal(d[:k + 1], e[:k + 1])
    assert (r + 19.0, 'swim') in s3
    assert not np.allclose(d[k + 36], e[k + 36], atol=0.05)


def test_the_watched_performer_corrects_the_course_when_the_character_would_pass_the_rope():
    """On the way to the rope the user turns by the character's course error when its course
    passes beside the rope (held-out seed 23 of round 4 walked past it 0.35 m to the side:
    its heading differed from the user's aim by ~7 deg and the user never corrected it)."""
    from performance_control.performances import ROPE_STOP, _course_error
    target = np.array([5.0, 0.0])

    def walked(start, heading_deg, speed=1.0, seconds=1.0):
        h = np.radians(heading_deg)
        return [np.asarray(start, float) + speed * k / 30 * np.array([np.cos(h), np.sin(h)])
                for k in range(int(seconds * 30))]

    seen = walked((2.5, -0.5), 4.5)                  # seed 23: would pass ~0.35 m beside it
    turn = _course_error(seen, target, 30.0)
    to = target - seen[-1]
    assert turn is not None
    assert abs(np.degrees(turn) - (np.degrees(np.arctan2(to[1], to[0])) - 4.5)) < 0.5
    ahead = np.degrees(np.arctan2(*(target - [2.5, -0.5])[::-1]))
    assert _course_error(walked((2.5, -0.5), ahead), target, 30.0) is None     # on course
    # passing within half the hands' reach: no correction; too close, past it or standing: none
    miss = 0.4 * ROPE_STOP
    assert _course_error(walked((2.0, miss), 0.0), target, 30.0) is None
    assert _course_error(walked((4.3, -0.5), 0.0, 0.5), target, 30.0) is None
    assert _course_error(walked((6.0, -0.5), 0.0), target, 30.0) is None
    assert _course_error(walked((2.5, -0.5), 0.0, 0.0), target, 30.0) is None
