"""Where the sensor is right, the output follows it: a TRACKED joint is not blamed for
a hidden neighbour (reliability Eq. 6), a new user id is a new user (no whole-skeleton-jump hold
on the old place), and a looping synthetic clip has no teleport."""
import numpy as np
import pytest

from pose_reconstruction.reconstructor import Reconstructor
from pose_reconstruction.reliability import ReliabilityEstimator
from pose_reconstruction.synthetic import random_database
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import (ANKLE_RIGHT, ELBOW_LEFT, FOOT_RIGHT, HAND_LEFT, HIP_CENTER,
                                 INFERRED, KNEE_RIGHT, NUM_JOINTS, SPINE, TRACKED, WRIST_LEFT,
                                 segment_lengths, standard_body)
from skeleton_eval.clips import toy_clip
from skeleton_eval.sensor_stream import LOOP_BLEND_FRAMES, loop_blend
from skeleton_eval.sensor_model import SensorModel


def _standing(n=40, seed=0):
    rng = np.random.default_rng(seed)
    rest = standard_body().rest_positions() + np.array([2.5, 0.0, -0.8])
    return np.repeat(rest[None], n, axis=0) + rng.normal(0, 0.003, (n, NUM_JOINTS, 3))


@pytest.mark.parametrize('plausibility', [True, False])
def test_tracked_spine_above_a_hidden_hip_centre_stays_reliable(plausibility):
    """The table hides the hip centre: INFERRED, held 40 cm from where it is. The tracked
    spine's segment to it is 40 cm off its length; Eq. 6 as printed (plausibility off) blames the
    spine for it (R_k <= 0.5: unreliable), with the plausibility stage only the hidden end is."""
    pos = _standing(60)
    st = np.full((len(pos), NUM_JOINTS), TRACKED, np.uint8)
    st[30:, HIP_CENTER] = INFERRED
    pos[30:, HIP_CENTER] = pos[29, HIP_CENTER] + np.array([0.0, 0.4, 0.0])
    est = ReliabilityEstimator(plausibility=plausibility)
    for p, s in zip(pos, st):
        r = est.update(p, s)
    assert r[HIP_CENTER] == pytest.approx(0.0)
    if plausibility:
        assert r[SPINE] > 0.9
    else:
        assert r[SPINE] < 0.5


@pytest.mark.parametrize('jit', [True, False])
@pytest.mark.parametrize('plausibility', [True, False])
def test_a_reacquired_tracked_ankle_is_reliable_at_once(jit, plausibility):
    """Class b: an object hides the shank for 20 frames (ankle and foot INFERRED, held where they
    were last seen, 15 cm off), then the sensor tracks them again at the right place. Eq. 8 as
    printed smooths min(R_b, R_k, R_t) over 6 frames, so the past INFERRED frames held the
    re-acquired ankle at 0.33, 0.61, 0.81 (its shank filled by the database although seen);
    with the plausibility stage the tracking state is taken for this frame: reliable at once.
    Losing the joint is unchanged (Eq. 8's delay, both modes)."""
    pos = _standing(80)
    st = np.full((len(pos), NUM_JOINTS), TRACKED, np.uint8)
    st[40:60, [ANKLE_RIGHT, FOOT_RIGHT]] = INFERRED
    pos[40:60, [ANKLE_RIGHT, FOOT_RIGHT]] += np.array([0.0, 0.0, 0.15])
    est = ReliabilityEstimator(plausibility=plausibility)
    if not jit:
        est._jit = False
    r = np.array([est.update(p, s) for p, s in zip(pos, st)])
    assert r[39, ANKLE_RIGHT] > 0.9
    assert 0.5 < r[40, ANKLE_RIGHT] < 0.9        # losing it: Eq. 8's delay either way
    assert r[45:60, ANKLE_RIGHT].max() == pytest.approx(0.0, abs=1e-9)
    first = r[60:63, ANKLE_RIGHT]
    if plausibility:
        # reliable from the first frame (the length term still remembers the stale frames)
        assert first.min() > 0.8
        assert r[60:, KNEE_RIGHT].min() > 0.9
    else:
        assert first[0] < 0.5 and first[2] < 0.9   # the paper's ramp


@pytest.mark.parametrize('jit', [True, False])
def test_a_vibrating_reacquired_joint_stays_unreliable(jit):
    """The rule takes the tracking state at once, not the behaviour term: a joint re-acquired
    TRACKED but vibrating (a false positive's 30 mm jitter, Eq. 1-4) stays unreliable."""
    rng = np.random.default_rng(3)
    pos = _standing(80)
    st = np.full((len(pos), NUM_JOINTS), TRACKED, np.uint8)
    st[40:60, ANKLE_RIGHT] = INFERRED
    pos[40:, ANKLE_RIGHT] += rng.normal(0.0, 0.06, (40, 3))
    est = ReliabilityEstimator()
    if not jit:
        est._jit = False
    r = np.array([est.update(p, s) for p, s in zip(pos, st)])
    assert r[60:70, ANKLE_RIGHT].mean() < 0.5


@pytest.mark.parametrize('jit', [True, False])
def test_tracked_wrist_beside_a_wrong_tracked_hand_stays_reliable(jit):
    """Class c/e: the hand rests on an object 20 cm from where it is, still TRACKED (every joint
    tracked). Its 8 cm segment to the wrist is off by more than its length; Eq. 6 as printed
    averages that into the wrist (R_k <= 0.5: the well-seen forearm handed to the database);
    with the plausibility stage a tracked joint is judged by its most consistent segment to a
    tracked joint, so the forearm (length right) keeps the wrist reliable and only the hand,
    whose one segment is wrong, is blamed."""
    pos = _standing(130)
    st = np.full((len(pos), NUM_JOINTS), TRACKED, np.uint8)
    hand = pos[0, HAND_LEFT] - pos[0, WRIST_LEFT]
    side = np.cross(hand, [1.0, 0.0, 0.0])
    pos[100:, HAND_LEFT] += 0.2 * side / np.linalg.norm(side)   # 20 cm aside, at an object
    est = ReliabilityEstimator()
    if not jit:
        est._jit = False   # the same rule in the Python path
    for p, s in zip(pos, st):
        r = est.update(p, s)
    assert r[HAND_LEFT] < 0.5
    assert r[WRIST_LEFT] > 0.9   # the mean of Eq. 6 read 1 - (1 + ~0) / 2 here
    assert r[ELBOW_LEFT] > 0.9


@pytest.fixture(scope='module')
def small_db():
    return random_database(800, seed=5)


def test_a_new_user_id_is_taken_at_its_place_at_once(small_db):
    """The same skeleton 1.5 m aside: for the same user the jump rule holds the last output
    (another person passing); with a new user id (the input says: a new user) the output is at
    the new place from its first frame."""
    pos = _standing(40)
    ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
    shift = np.array([0.0, 1.5, 0.0])
    outs = {}
    for new_id in (False, True):
        r = Reconstructor(small_db, method='C')
        for i, p in enumerate(pos):
            r.process(SkeletonFrame(positions=p, tracking_state=ts, user_id=1,
                                    stamp_ns=i * 33_333_333))
        f = SkeletonFrame(positions=pos[-1] + shift, tracking_state=ts,
                          user_id=2 if new_id else 1, stamp_ns=len(pos) * 33_333_333)
        outs[new_id] = r.process(f).positions
    held = np.linalg.norm(outs[False][HIP_CENTER] - pos[-1][HIP_CENTER])
    moved = np.linalg.norm(outs[True][HIP_CENTER] - (pos[-1][HIP_CENTER] + shift))
    assert held < 0.05          # same user: held at the old place
    assert moved < 0.05         # new user: at the new place


def test_loop_blend_ends_in_the_first_posture_with_the_bone_lengths():
    clip = toy_clip(seconds=3.0)
    p = np.array(clip.positions, float)
    p[:, :, 1] += np.linspace(0.0, 0.6, len(p))[:, None]   # the clip ends 60 cm aside
    q = loop_blend(p)
    assert np.array_equal(q[:-LOOP_BLEND_FRAMES], p[:-LOOP_BLEND_FRAMES])
    step = np.linalg.norm(q[0] - q[-1], axis=1).max()
    assert np.linalg.norm(p[0] - p[-1], axis=1).max() > 0.5 and step < 0.06
    assert np.allclose(segment_lengths(q), segment_lengths(p), atol=1e-9)
    # the live stream of the sensor model loops over the blended clip
    m = SensorModel({'scenarios': {'clean': {}}}, seed=0)
    gen = m.stream(clip, 'clean', loop=True)
    truth = np.array([next(gen)[2] for _ in range(2 * len(p) + 2)])
    jumps = np.linalg.norm(np.diff(truth, axis=0), axis=2).max(axis=1)
    assert jumps.max() < 0.1
