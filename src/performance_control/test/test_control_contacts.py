"""Intentional contacts (Ishigaki 2009, Sec. 5): equality constraints switched at run time, the
COM moved by the contact springs (Eq. 1-4), release by rule, feature dynamics."""
import numpy as np
import pytest

from performance_control.controller import ControlParams, PerformanceController
from performance_control.dynamics import DynamicProcess
from performance_control.examples import imitation
from performance_control.features import EFFECTORS, WorldError, load_world, parse_world
from performance_control.performances import SENSOR_HEIGHT, imitation_stream, to_sensor
from skeleton_core.model import standard_body

WORLD = load_world('playground')
BAR_Z = WORLD.features['monkey_bars'].geoms[0].vec('from')[2]
UP = {'HandLeft': np.array([0.0, 0.2, 1.1]), 'HandRight': np.array([0.0, -0.2, 1.1]),
      'FootLeft': np.array([0.0, 0.1, -0.95]), 'FootRight': np.array([0.0, -0.1, -0.95])}


def _hold(dp, seconds, rel=None):
    rel = np.array([(rel or UP)[e] for e in EFFECTORS])
    for _ in range(int(round(seconds * 30))):
        dp.set_targets(rel, 0.0, 1 / 30)
        dp.step(1 / 30)


def test_engage_holds_the_character_and_release_drops_it():
    bars = WORLD.features['monkey_bars']
    dp = DynamicProcess(WORLD, 75.0, [3.0, 0.0, BAR_Z - 1.1], UP)
    for e in ('HandLeft', 'HandRight'):
        dist, body, pt = dp.feature_distance(e, bars)
        assert body == 'world' and dist < bars.engage.distance
        dp.engage(e, bars, body, pt)
        assert dp.data.eq_active[dp.eq_ids[(e, 'world')]] == 1
    _hold(dp, 1.0)
    # hanging: the hands stay on the bar, the COM hangs below it at |r^| minus the spring's sag
    # (m g / 2 ks per arm = 75 * 9.81 / 18000 = 4 cm)
    assert dp.constraint_gap() < 0.005
    assert dp.effectors()[0] == pytest.approx([3.0, 0.2, BAR_Z], abs=0.01)
    assert BAR_Z - 1.1 - 0.08 < dp.com[2] < BAR_Z - 1.1 + 0.01
    z_hang = dp.com[2]
    dp.release_all()
    assert not dp.contacts and not dp.data.eq_active.any()
    _hold(dp, 0.4)
    assert dp.com[2] < z_hang - 0.4      # free fall: 0.5 g t^2 = 0.78 m in 0.4 s


def test_user_swinging_the_arms_swings_the_character_about_the_bar():
    """Fig. 4: the pitch PD through the contact turns the user's arm swing into a COM swing."""
    bars = WORLD.features['monkey_bars']
    dp = DynamicProcess(WORLD, 75.0, [3.0, 0.0, BAR_Z - 1.1], UP)
    for e in ('HandLeft', 'HandRight'):
        _, body, pt = dp.feature_distance(e, bars)
        dp.engage(e, bars, body, pt)
    xs = []
    for k in range(90):
        a = 0.5 * np.sin(2 * np.pi * k / 30 / 1.6)
        rel = dict(UP)
        for e in ('HandLeft', 'HandRight'):
            rel[e] = np.array([1.1 * np.sin(a), UP[e][1], 1.1 * np.cos(a)])
        _hold(dp, 1 / 30, rel)
        xs.append(dp.com[0])
    assert max(xs) - min(xs) > 0.5
    assert dp.constraint_gap() < 0.01


def test_rope_swings_under_the_characters_weight_and_the_trampoline_gives():
    rope = WORLD.features['rope']
    top = rope.geoms[0].vec('top')
    dp = DynamicProcess(WORLD, 75.0, [top[0], top[1], 2.6 - 1.1], UP)
    for e in ('HandLeft', 'HandRight'):
        dist, body, pt = dp.feature_distance(e, rope)
        assert body.startswith('f_rope_0_seg')
        dp.engage(e, rope, body, pt)
    lean = dict(UP)
    for e in ('HandLeft', 'HandRight'):
        lean[e] = UP[e] + np.array([0.4, 0.0, -0.1])   # the user pulls the COM behind the hands
    _hold(dp, 1.0, lean)
    seg = dp.data.xpos[dp.model.body(dp.contacts['HandLeft'].body).id]
    assert dp.constraint_gap() < 0.01
    assert not np.allclose(seg[:2], top[:2], atol=0.02) or dp.contacts['HandLeft'].body.endswith('seg0')
    # trampoline: standing on it compresses the spring by about m g / k = 3 cm
    tr = WORLD.features['trampoline']
    c, h = tr.geoms[0].vec('center'), tr.geoms[0].vec('half')
    dp = DynamicProcess(WORLD, 75.0, [c[0], c[1], c[2] + h[2] + 0.99], UP)
    _hold(dp, 0.3)
    for e in ('FootLeft', 'FootRight'):
        dist, body, pt = dp.feature_distance(e, tr)
        assert dist < 0.1 and body == 'f_trampoline_0'
        dp.engage(e, tr, body, pt)
    _hold(dp, 1.5)
    z = dp.data.xpos[dp.model.body('f_trampoline_0').id][2]
    assert c[2] - 0.06 < z < c[2] - 0.015


def test_user_lowering_the_arms_releases_the_bars_and_the_character_lands():
    ctl = PerformanceController(WORLD, ControlParams(), start='monkey_bars')
    f = WORLD.features['monkey_bars']
    n = 150
    act = np.r_[np.ones(60), np.zeros(n - 60)]
    p = imitation(f.example.generator, f.example.params, standard_body(1.7), n,
                  active=act) + [2.5, 0, -0.8]
    outs = [ctl.step(p[i], i / 30.0) for i in range(n)]
    assert {'HandLeft', 'HandRight'} <= set(outs[50].contacts)
    assert not any(e.startswith('Hand') for e in outs[80].contacts)
    assert outs[-1].com[2] < outs[50].com[2] - 0.3
    assert {'FootLeft', 'FootRight'} & set(outs[-1].contacts)     # landed on the floor
    assert max(o.penetration for o in outs) < 0.02


@pytest.mark.parametrize('seed', [2, 4])
def test_lowering_the_arms_from_the_bars_is_a_dismount_not_a_fling(seed):
    """A user swinging on the bars lowers the arms over 0.3 s; while the hands still
    hold, the target turning about the grip (~8 rad/s) drove the pitch PD with up to 4 body
    weights per hand and the COM left the bars at 5-8 m/s, landing 3 m away (main at 14991c8:
    these performers 5.2 / 7.8 m/s, 3.2 / 2.9 m). Bounded across the arm (SWING_STRENGTH) and
    let go as the arm comes down (RELEASE_SPEED): 2.4 / 2.5 m/s, 1.0 / 0.6 m."""
    f = WORLD.features['monkey_bars']
    p, _ = imitation_stream(f, np.random.default_rng(seed), pattern=((-1.0, 5.0),), total=8.0,
                            fade=0.3)
    s, st = to_sensor(p, 'release', seed, False, states=True)
    ctl = PerformanceController(WORLD, ControlParams(sensor_height=SENSOR_HEIGHT),
                                start='monkey_bars')
    outs = [ctl.step(s[i], i / 30.0, st[i]) for i in range(len(s))]
    held = [any(e.startswith('Hand') for e in o.contacts) for o in outs]
    assert all(held[:int(4.5 * 30)])                           # swung on the bars
    k = next(i for i in range(len(held) - 1, 0, -1) if held[i - 1] and not held[i])
    assert 4.6 < k / 30 < 5.3                                   # let go as the arms came down
    com = np.array([o.com for o in outs])
    speed = np.linalg.norm(np.diff(com, axis=0), axis=1) * 30
    assert speed[k - 6:k + 3].max() < 3.5
    land = next(i for i in range(k, len(outs)) if any(
        e.startswith('Foot') and WORLD.features[x].kind == 'floor'
        for e, x in outs[i].contacts.items()))
    assert np.linalg.norm(com[land, :2] - com[k, :2]) < 1.5
    assert ctl.dp.unstable_steps == 0


def test_world_files_are_validated_with_clear_errors():
    with pytest.raises(WorldError, match="feature 'bar'.*radius"):
        parse_world({'features': {'bar': {'geometry': [
            {'type': 'capsule', 'from': [0, 0, 2], 'to': [1, 0, 2], 'radius': -1}]}}}, 'w.yaml')
    with pytest.raises(WorldError, match='effector'):
        parse_world({'features': {'f': {'geometry': [{'type': 'plane'}],
                                        'engage': {'effectors': ['Nose']}}}}, 'w.yaml')
    with pytest.raises(FileNotFoundError, match='available'):
        load_world('no_such_world')


def test_a_rope_crossing_a_free_forearm_is_cleared_and_a_held_hand_stays():
    """Eq. 12's p_pen <= p for segment capsules: a rope segment through the middle of a forearm
    (both joints outside it, so pushing joints out does nothing) is cleared by moving the wrist
    and hand; a held hand (skip) does not move."""
    from performance_control.composition import Obstacles
    from performance_control.examples import imitation
    from skeleton_core.model import ELBOW_LEFT, HAND_RIGHT, WRIST_LEFT, standard_body
    p = imitation('rope_climb', {'period': 1.4}, standard_body(1.75), 1)[0]
    mid = 0.5 * (p[ELBOW_LEFT] + p[WRIST_LEFT])
    obs = Obstacles()
    obs.capsules.append((mid + [0.0, 0.0, -0.5], mid + [0.0, 0.0, 0.5], 0.02, 'rope'))
    obs.freeze()
    before = obs.penetration(p, 1.75)
    assert before > 0.03
    q = p.copy()
    obs.push_out(q, set(), 1.75)
    assert obs.penetration(q, 1.75) > 0.03       # pushing the joints out is not enough
    skip = {HAND_RIGHT}                                          # the right hand is held
    obs.clear_segments(q, skip, 1.75)
    assert obs.penetration(q, 1.75) < 1e-3
    assert q[HAND_RIGHT] == pytest.approx(p[HAND_RIGHT])
    assert np.linalg.norm(q[WRIST_LEFT] - p[WRIST_LEFT]) < 0.2      # a local correction


def test_climbing_hand_over_hand_regrabs_the_swinging_rope():
    """The free hand at the top of its reach grabs the rope within regrab_reach: the character
    never lets go of the rope with both hands while the user climbs, and grabs again and again."""
    from performance_control.controller import ControlParams, PerformanceController
    from performance_control.performances import SENSOR_HEIGHT, imitation_stream, to_sensor
    f = WORLD.features['rope']
    rng = np.random.default_rng(31)
    p, _ = imitation_stream(f, rng, pattern=((-1.0, 9.0),), total=4.0, fade=0.2)
    s = to_sensor(p, 'climb', 31, noise=False)
    ctl = PerformanceController(WORLD, ControlParams(sensor_height=SENSOR_HEIGHT), start='rope')
    held = []
    for i in range(len(s)):
        o = ctl.step(s[i], i / 30.0)
        held.append(sum(e.startswith('Hand') for e in o.contacts))
    held = np.array(held)
    assert np.all(held >= 1)
    regrabs = np.sum((held[1:] == 2) & (held[:-1] == 1))
    assert regrabs >= 3, held


def test_a_rope_crossing_a_thigh_is_cleared():
    """The same for a leg: a rope through the middle of a free thigh (a body falling past it)."""
    from performance_control.composition import Obstacles
    from performance_control.examples import imitation
    from skeleton_core.model import HIP_RIGHT, KNEE_RIGHT, standard_body
    p = imitation('rope_climb', {'period': 1.4}, standard_body(1.75), 1)[0]
    mid = 0.5 * (p[HIP_RIGHT] + p[KNEE_RIGHT])
    obs = Obstacles()
    obs.capsules.append((mid + [0.0, -0.5, 0.0], mid + [0.0, 0.5, 0.0], 0.02, 'rope'))
    obs.freeze()
    q = p.copy()
    obs.push_out(q, set(), 1.75)
    assert obs.penetration(q, 1.75) > 0.03
    obs.clear_segments(q, set(), 1.75)
    assert obs.penetration(q, 1.75) < 1e-3
