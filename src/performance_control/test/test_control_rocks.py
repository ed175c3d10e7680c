"""Rock climbing (Ishigaki 2009, Sec. 8.4): rocks are contact points with a radius; a hand engages
when closed (our stand-in: raised above the shoulders) and within the radius, a foot when within
it and above the rock's face."""
import copy

import numpy as np
import yaml

from performance_control.controller import ControlParams, PerformanceController
from performance_control.dynamics import DynamicProcess
from performance_control.examples import _arm, _legs
from performance_control.features import parse_world, world_path
from physics_sim.simulation import SensorPose
from skeleton_core.model import JOINT_INDEX, standard_body
from skeleton_data.motions import pose_from_rotations

DOC = yaml.safe_load(world_path('playground').read_text())
SENSOR = SensorPose(0.8, 0.0)


def _world(extra_rock=None):
    doc = copy.deepcopy(DOC)
    if extra_rock is not None:
        doc['features']['climbing_wall']['geometry'].append(
            {'type': 'rock', 'center': list(extra_rock), 'radius': 0.12})
    return parse_world(doc, 'test')


def _climber(n=90, flex_deg=150.0, leg_from=45, arms_down_from=None):
    """A user facing the sensor 3 m away: both arms raised forward-up (flex_deg), from frame
    ``leg_from`` the left knee lifted (hip 70, knee 80 deg); from ``arms_down_from`` the arms
    hang again. Sensor frame (T, 20, 3)."""
    body = standard_body(1.75)
    flex = np.full(n, np.radians(flex_deg))
    if arms_down_from is not None:
        flex[arms_down_from:] = np.radians(5)
    aims, local = {}, {}
    for side in ('left', 'right'):
        _arm(aims, side, flex, np.full(n, np.radians(15)), np.full(n, np.radians(10)), n)
    hip, knee = np.zeros(n), np.zeros(n)
    hip[leg_from:], knee[leg_from:] = np.radians(70), np.radians(80)
    _legs(local, hip, knee, 0.0, np.radians(4), n)
    p, _, _ = pose_from_rotations(body, local, n, aims)
    pw = p @ np.diag([-1.0, -1.0, 1.0]).T + [3.0, 0.0, 0.0]     # facing the sensor
    return np.array([SENSOR.to_sensor(x) for x in pw])


def test_a_foot_engages_a_rock_only_within_its_radius_and_above_its_face():
    world = _world()
    wall = world.features['climbing_wall']
    assert wall.kind == 'rocks'
    rock = wall.geoms[1].vec('center')
    rel = {'HandLeft': np.array([0.2, 0.2, 0.6]), 'HandRight': np.array([0.2, -0.2, 0.6]),
           'FootRight': np.array([0.0, -0.1, -0.95])}
    for dz, engages in ((0.05, True), (-0.05, False)):
        foot = rock + [-0.05, 0.0, dz]
        com = foot - [0.1, 0.1, -0.5]
        rel['FootLeft'] = foot - com
        dp = DynamicProcess(world, 75.0, com, rel)
        dist, body, pt = dp.feature_distance('FootLeft', wall)
        assert (dist < wall.engage.distance) == engages, (dz, dist)
        if engages:     # held on top of the rock's centre
            assert body == 'world' and pt[2] > rock[2]
    # a hand far from every rock (1 m below the lowest): out of reach
    dp = DynamicProcess(world, 75.0, [6.0, 3.0, 1.0], {**rel, 'HandLeft': np.array([0.0, 0.0,
                                                                                   -2.0])})
    assert dp.feature_distance('HandLeft', wall)[0] > 0.5


def test_raised_hands_hold_the_rocks_a_lifted_foot_steps_on_one_and_lowered_hands_let_go():
    s = _climber(n=150, leg_from=45, arms_down_from=110)
    # where the lifted left foot arrives on this body (probe run without the extra rock)
    ctl = PerformanceController(_world(), ControlParams(), start='climbing_wall')
    for i in range(80):
        o = ctl.step(s[i], i / 30.0)
    assert o.contacts.get('HandLeft') == 'climbing_wall'
    assert o.contacts.get('HandRight') == 'climbing_wall'
    assert 'FootLeft' not in o.contacts                   # no rock under the lifted foot
    foot = ctl.dp.effectors()[2]
    # the same performance with a rock just under where the foot is lifted to
    ctl = PerformanceController(_world(foot - [0.0, 0.0, 0.05]), ControlParams(),
                                start='climbing_wall')
    rows = [ctl.step(s[i], i / 30.0) for i in range(len(s))]
    assert rows[40].contacts.get('FootLeft') == 'floor'
    assert rows[100].contacts.get('FootLeft') == 'climbing_wall'
    hands = [o.positions_world[JOINT_INDEX['HandLeft']] for o in rows[60:100]]
    assert np.ptp(np.array(hands), axis=0).max() < 0.03   # held still on the rock
    last = rows[-1]
    assert not any(e.startswith('Hand') for e in last.contacts)   # arms lowered: let go
    assert max(o.penetration for o in rows) < 0.02
