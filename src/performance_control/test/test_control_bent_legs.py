"""The legs at work veto every example (real Kinect v2: sit-to-stand and the deep squat
took the breaststroke and the rope): the feet planted and the hips lowered is a squat, not an
imitation; standing again, the same arm motion is recognised; a jump's tucked legs are no squat."""
import numpy as np

from performance_control.controller import build_models
from performance_control.examples import imitation
from performance_control.features import load_world
from performance_control.intention import IntentionRecognizer, RecognizerParams
from performance_control.performances import lift
from performance_control.support import CROUCH, CROUCH_HOLD, HangDetector, bent_legs_mask
from skeleton_core.model import FOOT_LEFT, FOOT_RIGHT, JOINT_INDEX, standard_body

WORLD = load_world('playground')
FPS = 30.0
_FEET = [JOINT_INDEX[j] for j in ('AnkleLeft', 'AnkleRight', 'FootLeft', 'FootRight')]


def _swim(n):
    return np.array(imitation('breaststroke', {'period': 1.5, 'reach': 0.5}, standard_body(1.75),
                              n, active=np.ones(n)))


def _squat(p, t, t0, t1, depth):
    """Lower everything but the feet by ``depth`` of the standing hip height between t0 and t1
    (0.3 s ramps): the hips go down, the feet stay planted."""
    p = p.copy()
    hip = p[0, JOINT_INDEX['HipCenter'], 2] - p[0, [FOOT_LEFT, FOOT_RIGHT], 2].min()
    ramp = np.clip((t - t0) / 0.3, 0, 1) * np.clip((t1 - t) / 0.3, 0, 1)
    body = [j for j in range(p.shape[1]) if j not in _FEET]
    p[:, body, 2] -= (depth * hip * ramp)[:, None]
    return p


def _water(p):
    rec = IntentionRecognizer(list(build_models(WORLD, RecognizerParams()).values()),
                              RecognizerParams())
    return np.array([rec.update(p[i], i / FPS)['water'].imitating for i in range(len(p))])


def test_the_breaststroke_while_squatting_is_no_imitation_and_again_when_standing():
    n = int(9 * FPS)
    t = np.arange(n) / FPS
    p = _swim(n)
    assert _water(p)[t > 1.0].mean() > 0.8                      # standing: swimming
    sq = _water(_squat(p, t, 2.0, 6.0, 0.35))
    assert not sq[(t > 2.3) & (t < 5.7)].any()     # hips 35 % down: a squat (ramps 0.3 s)
    assert sq[t > 6.0 + CROUCH_HOLD + 0.3].mean() > 0.8        # stood up: swimming again
    assert sq[t < 2.0].mean() > 0.5
    # a shallow knee bend (half the threshold) vetoes nothing
    shallow = _water(_squat(p, t, 2.0, 6.0, 0.5 * CROUCH))
    assert shallow[t > 1.0].mean() > 0.8


def test_tucked_legs_in_a_jump_are_no_squat_and_the_offline_mask_is_the_online_rule():
    n = int(6 * FPS)
    t = np.arange(n) / FPS
    p = _swim(n)
    jump = lift(_squat(p, t, 2.0, 2.6, 0.3), 2.15, 0.45)      # legs tucked while airborne only
    det = HangDetector()
    rows = []
    for i in range(n):
        det.update(jump[i], t[i])
        rows.append((det.depth, det.airborne, det.legs_bent()))
    depth, air, bent = map(np.array, zip(*rows))
    assert air.any() and depth[air].max() > CROUCH
    np.testing.assert_array_equal(bent, bent_legs_mask(t, depth, air))
    sq = _squat(p, t, 2.0, 4.0, 0.4)
    det = HangDetector()
    rows = []
    for i in range(n):
        det.update(sq[i], t[i])
        rows.append((det.depth, det.airborne, det.legs_bent()))
    depth, air, bent = map(np.array, zip(*rows))
    assert bent.any() and not bent[t < 2.0].any()
    np.testing.assert_array_equal(bent, bent_legs_mask(t, depth, air))
