"""Intention recognition (Ishigaki 2009, Sec. 6.1): e1/e2 of Eq. 5-6 against a PCA computed by
hand, invariance of the feature vector, a scripted imitation recognised and walking not."""
import math

import numpy as np
import pytest

from performance_control.controller import ControlParams, PerformanceController, build_models
from performance_control.examples import imitation, random_style
from performance_control.features import load_world
from performance_control.intention import (ExampleModel, IntentionRecognizer, RecognizerParams,
                                           approach_discount, feature_vectors,
                                           partial_reconstruction_error, pca_columns,
                                           reconstruction_error, residual)
from performance_control.performances import non_imitation_clips
from skeleton_core.model import (ELBOW_RIGHT, HAND_LEFT, HAND_RIGHT, INFERRED, TRACKED,
                                 WRIST_RIGHT, standard_body)

WORLD = load_world('playground')


def test_e1_e2_against_a_hand_computed_pca():
    # three examples on the line w1 = w2: mean (2, 2), first component (1, 1)/sqrt(2)
    w = np.array([[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]])
    mean, a, lam = pca_columns(w, 1)
    assert mean == pytest.approx([2.0, 2.0])
    assert abs(a[:, 0] @ np.array([1.0, 1.0]) / math.sqrt(2)) == pytest.approx(1.0)
    assert lam[0] == pytest.approx(2.0)          # variance along the line: (2 + 0 + 2) / 2
    m = object.__new__(ExampleModel)
    m.mean, m.A = mean, a
    # w^ = (3, 1): centred (1, -1) is orthogonal to the line -> e1 = |(1, -1)|^2 = 2
    # dw = (1, 0): projection (0.5, 0.5), residual (0.5, -0.5) -> e2 = 0.5
    e1, e2 = m.errors(np.array([3.0, 1.0]), np.array([1.0, 0.0]))
    assert e1 == pytest.approx(2.0)
    assert e2 == pytest.approx(0.5)
    # a point on the line and a change along it reconstruct exactly
    assert m.errors(np.array([5.0, 5.0]), np.array([-1.0, -1.0])) == pytest.approx((0.0, 0.0))
    assert reconstruction_error(np.array([[0.0, 2.0]]), a)[0] == pytest.approx(2.0)


def test_feature_vector_ignores_position_yaw_and_body_size():
    body = standard_body(1.75)
    p = imitation('monkey_swing', {'period': 1.5}, body, 40)
    prm = RecognizerParams()
    w0 = feature_vectors(p, (HAND_LEFT, HAND_RIGHT), 1.75, prm)
    yaw = 1.1
    rot = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0],
                    [0, 0, 1]])
    moved = p @ rot.T + np.array([3.0, -2.0, 0.5])
    assert feature_vectors(moved, (HAND_LEFT, HAND_RIGHT), 1.75, prm) == pytest.approx(w0, abs=1e-9)
    # a bigger user doing the same: the same w in body-height units
    big = imitation('monkey_swing', {'period': 1.5}, standard_body(1.95), 40)
    wb = feature_vectors(big, (HAND_LEFT, HAND_RIGHT), 1.95, prm)
    assert wb == pytest.approx(w0, abs=1e-6)


def _run(models, p, prm):
    rec = IntentionRecognizer(list(models.values()), prm)
    return [rec.update(p[i], i / 30.0) for i in range(len(p))]


@pytest.mark.parametrize('feature', ['monkey_bars', 'rope', 'water'])
def test_scripted_imitation_is_recognised_and_only_as_its_feature(feature):
    prm = RecognizerParams()
    models = build_models(WORLD, prm)
    f = WORLD.features[feature]
    rng = np.random.default_rng(11)
    body = standard_body(1.62)
    params = dict(f.example.params, period=f.example.params['period'] * 1.15)
    n = 150
    p = imitation(f.example.generator, params, body, n, style=random_style(rng, 0.5))
    rows = _run(models, p, prm)
    mine = np.array([r[feature].imitating for r in rows[15:]])
    assert mine.mean() > 0.8, [round(r[feature].e1, 4) for r in rows[15::15]]
    first = next(i for i, r in enumerate(rows) if r[feature].imitating)
    assert first / 30.0 <= 0.5
    others = np.array([any(x.imitating for k, x in r.items() if k != feature) for r in rows])
    assert others.mean() < 0.05


def test_change_share_subspace_of_a_two_handed_stroke_rejects_one_hand():
    """The breaststroke moves both hands mirror-symmetrically, so every direction its positions
    move in is symmetric: a one-handed change has at least half of its energy outside (share >=
    0.5) while the example's own changes lie inside."""
    prm = RecognizerParams()
    m = build_models(WORLD, prm)['water']
    a = m.A_pos                                   # (6, k): [left xyz, right xyz]
    mirror = np.array([1.0, -1.0, 1.0])
    assert a[3:] == pytest.approx(a[:3] * mirror[:, None], abs=1e-6)   # symmetric directions
    rng = np.random.default_rng(2)
    for _ in range(20):
        d = np.concatenate([rng.normal(size=3), np.zeros(3)])
        assert reconstruction_error(d, a) / (d @ d) >= 0.5 - 1e-9
    npos = a.shape[0]
    own = m.w[4:, :npos] - m.w[:-4, :npos]
    share = reconstruction_error(own, a).sum() / np.sum(own * own)
    assert share < 0.01


def test_example_change_share_gate_is_validated():
    from performance_control.features import WorldError, parse_world
    doc = {'features': {'w': {'geometry': [{'type': 'volume', 'center': [0, 0, 1],
                                            'half': [1, 1, 1]}],
                              'example': {'generator': 'breaststroke', 'max_change_share': 1.5}}}}
    with pytest.raises(WorldError, match="feature 'w'.*max_change_share"):
        parse_world(doc)


def test_scripted_walk_boxing_and_standing_are_not_imitations():
    """Punches included: the breaststroke recognizer's change-share gate rejects one-handed
    changes its two-handed example never makes. Walking imitates only the floor's walk
    (Sec. 8.3: walking is the floor's example)."""
    prm = RecognizerParams()
    models = build_models(WORLD, prm)
    for name, clip in non_imitation_clips(4242):
        rows = _run(models, clip, prm)
        bad = np.mean([any(x.imitating for n, x in r.items() if n != 'floor' or name != 'walk')
                       for r in rows])
        assert bad <= 0.02, (name, bad)
        if name == 'walk':
            assert np.mean([r['floor'].imitating for r in rows]) > 0.8


def test_scripted_imitation_engages_the_bars_and_a_walk_engages_nothing():
    """The whole controller: hands reaching the bars engage, the imitation keeps the character
    hanging; a walk on the floor holds no feature with the hands and imitates nothing."""
    ctl = PerformanceController(WORLD, ControlParams(), start='monkey_bars')
    f = WORLD.features['monkey_bars']
    p = imitation(f.example.generator, f.example.params, standard_body(1.7), 90) + [2.5, 0, -0.8]
    outs = [ctl.step(p[i], i / 30.0) for i in range(len(p))]
    assert all({'HandLeft', 'HandRight'} <= set(o.contacts) for o in outs[5:])
    assert all(o.contacts['HandLeft'] == 'monkey_bars' for o in outs[5:])
    assert np.mean([o.imitating for o in outs[30:]]) > 0.8
    assert min(o.com[2] for o in outs[5:]) > 1.0       # hanging, feet off the floor
    ctl = PerformanceController(WORLD, ControlParams())
    walk = dict(non_imitation_clips(7))['walk'] + [2.5, 0, -0.8]
    outs = [ctl.step(walk[i], i / 30.0) for i in range(len(walk))]
    assert not any(e.startswith('Hand') for o in outs for e in o.contacts)
    assert not any(o.imitating and o.feature != 'floor' for o in outs)
    assert all(o.feature in ('', 'floor') for o in outs)


def test_missing_effector_error_against_a_hand_computed_fit():
    """Eq. 5 on the observed coordinates: the subspace coefficient fitted to them, the residual
    scaled by (D - m) / (D_o - m)."""
    a = np.array([[1.0], [1.0], [0.0]]) / math.sqrt(2)       # D = 3, m = 1
    v = np.array([3.0, 1.0, 4.0])
    # all observed: Eq. 5 (projection (2, 2, 0), residual (1, -1, 4))
    assert partial_reconstruction_error(v, a, [True] * 3) == pytest.approx(18.0)
    # z missing: c / sqrt2 = 2 fits (3, 1) with residual (1, -1) -> 2, x (3 - 1) / (2 - 1) = 4
    assert partial_reconstruction_error(v, a, [True, True, False]) == pytest.approx(4.0)
    # y missing: c / sqrt2 = 3 fits x exactly, z's 4 remains -> 16 x 2 = 32
    assert partial_reconstruction_error(v, a, [True, False, True]) == pytest.approx(32.0)
    with pytest.raises(ValueError, match='cannot test'):
        partial_reconstruction_error(v, a, [True, False, False])
    # with the Gaussian prior sigma^2 / lambda = 1: c = (a_o . v_o) / (|a_o|^2 + 1) = sqrt2,
    # fitted (1, 1), residual (2, 0) -> 4 x 2 = 8
    r, scale = residual(v, a, [True, True, False], prior=np.array([1.0]))
    assert r == pytest.approx([2.0, 0.0])
    assert float(r @ r) * scale == pytest.approx(8.0)


def test_e2_approach_discounts_only_the_change_back_into_the_subspace():
    r_old = np.array([0.0, 0.0, 2.0])          # 2 out of the subspace, lag frames ago
    # heading straight back by 1.5: no e2; sideways 1 kept whole
    assert approach_discount(r_old + [0, 0, -1.5], np.array([0, 0, -1.5])) == pytest.approx(0)
    dr = np.array([1.0, 0.0, -1.5])
    assert approach_discount(r_old + dr, dr) == pytest.approx([1.0, 0.0, 0.0])
    # overshooting past the subspace: only |r_old| = 2 is credited
    dr = np.array([0.0, 0.0, -3.0])
    assert approach_discount(r_old + dr, dr) == pytest.approx([0.0, 0.0, -1.0])
    # moving away is all error
    dr = np.array([0.0, 0.5, 0.5])
    assert approach_discount(r_old + dr, dr) == pytest.approx(dr)


def _frozen_right_arm(feature, seed=5, onset=1.0, n=75):
    """A user imitating ``feature`` from ``onset`` s whose right arm the sensor froze at rest
    (INFERRED): the Kinect's occlusion at the movement's onset."""
    f = WORLD.features[feature]
    t = np.arange(n) / 30.0
    env = np.clip((t - onset) / 0.2, 0, 1)
    p = imitation(f.example.generator, dict(f.example.params), standard_body(1.62), n,
                  style=random_style(np.random.default_rng(seed), 0.5), active=env)
    st = np.full(p.shape[:2], TRACKED, np.uint8)
    arm = [ELBOW_RIGHT, WRIST_RIGHT, HAND_RIGHT]
    p[:, arm] = p[0, arm]
    st[:, arm] = INFERRED
    return p, st, t


@pytest.mark.parametrize('feature', ['monkey_bars', 'rope'])
def test_an_imitation_with_an_occluded_arm_is_recognised_from_the_tracked_one(feature):
    p, st, t = _frozen_right_arm(feature)
    flags = {}
    for missing in (True, False):
        prm = RecognizerParams(missing_effectors=missing)
        rec = IntentionRecognizer(list(build_models(WORLD, prm).values()), prm)
        flags[missing] = np.array([rec.update(p[i], t[i], st[i])[feature].imitating
                                   for i in range(len(p))])
    early = (t >= 1.0) & (t <= 1.5)
    assert not flags[True][t < 1.0].any()                  # standing still: nothing
    assert flags[True][early].any()                        # the tracked arm recognised in 0.5 s
    assert flags[True][t >= 1.5].mean() > 0.8
    assert not flags[False].any()                          # the frozen arm as reported: never


def test_an_untestable_change_share_gate_does_not_pass():
    """The breaststroke's gate needs both hands (its directions are mirror-symmetric): with one
    hand occluded it cannot tell a stroke from a punch, so the water recognizer stays off."""
    p, st, t = _frozen_right_arm('water')
    prm = RecognizerParams()
    rec = IntentionRecognizer(list(build_models(WORLD, prm).values()), prm)
    recs = [rec.update(p[i], t[i], st[i])['water'] for i in range(len(p))]
    assert not any(r.imitating for r in recs)
    assert all(r.change_share == pytest.approx(1.0) for r in recs[40:])
    # the same stroke with both arms tracked is recognised
    f = WORLD.features['water']
    q = imitation(f.example.generator, dict(f.example.params), standard_body(1.62), 75,
                  style=random_style(np.random.default_rng(5), 0.5),
                  active=np.clip((t - 1.0) / 0.2, 0, 1))
    rec = IntentionRecognizer(list(build_models(WORLD, prm).values()), prm)
    assert any(rec.update(q[i], t[i])['water'].imitating for i in range(len(q)))


def test_walk_recognition_ignores_a_users_constant_posture_offset_not_an_in_phase_swing():
    """The floor's walk is compared also about the user's own mean posture (``own_posture``,
    round 7), while the feet alternate:
    a walker whose elbows are bent 24 deg more and shoulders flexed 11 deg more than the example's
    (the continuous performance's seed 1, walk recognised only in bursts about the example's
    mean) is as near the example's subspace as the example's own walker, within half the
    threshold; both arms swinging together (a bilateral raise, what real shoulder exercises do)
    is still no walk."""
    prm = RecognizerParams()
    own = build_models(WORLD, prm)['floor']
    f = WORLD.features['floor']
    assert own.own_posture == pytest.approx(f.example.params['period'])
    plain = ExampleModel('floor', own.positions, f.example.effectors, f.example.components, prm,
                         max_change_share=f.example.max_change_share)
    body, n = standard_body(1.7), 180

    def e1(model, style, lift=35.0):
        p = imitation('walk_cycle', dict(f.example.params, knee_lift_deg=lift), body, n,
                      style=style)
        rec = IntentionRecognizer([model], prm)
        rs = [rec.update(p[i], i / 30)['floor'] for i in range(n)][30:]
        return (float(np.median([r.e1 for r in rs])) / prm.e1_threshold,
                float(np.mean([r.imitating for r in rs])))

    bent = {'elbow': math.radians(24), 'flex_offset': math.radians(10.8)}
    e_plain, _ = e1(plain, bent)
    e_own, rate = e1(own, bent)
    assert e_plain > 0.8                 # about the example's mean: at the threshold's edge
    assert e_own < 0.5 and e_own < 0.5 * e_plain and rate == 1.0
    for style in ({'asym': 0.5}, {'asym': 0.5, **bent}):      # the arms in phase
        e, rate = e1(own, style)
        assert e > 1.0 and rate == 0.0
    # the user's own posture only while the feet alternate (the legs' evidence of a walk): the
    # same arms over still legs are judged about the example's mean
    e_still, _ = e1(own, bent, lift=1e-3)
    assert e_still > 0.8 and e_still > 2.0 * e_own
