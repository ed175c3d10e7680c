"""Built-in motions produced by code: the default database when no mocap data is available.

Every clip is driven by joint rotations on the standard body (``model.standard_body``), so segment
lengths are exact and orientations follow the :mod:`skeleton_data.mocap` convention (identity = the
T-pose facing +x; ``quat_rotate(q[j], rest_dir[j])`` is the segment direction, exactly). Motions are
sums of smooth periodic or smoothly interpolated random curves (30 fps, 6 s each). Feet: the root
height is set every frame so that the lowest sole point (toe joint, or heel = ankle minus the ankle
height along the foot) is on the floor, so the standing body never floats or sinks; during walking
the contact point's horizontal position is kept fixed (no foot skating) by moving the root.

Motions and their Shum 2013 class: walk (locomotion), arm raises and waving (upper_body), punches
and a front kick (boxing), pick-up, squat-lift and reaching to random targets (object_handling),
two-handed sword swings (sword_fighting). ``builtin_clips(seed)`` draws amplitudes, speeds and phases from a seeded
generator; :func:`builtin_split` uses different seeds for database and dev clips.
"""
from __future__ import annotations

from typing import Callable, Dict, List, Optional, Tuple

import numpy as np

from skeleton_core.geometry import quat_conjugate, quat_multiply, quat_rotate
from .mocap import MotionClip, rest_directions
from skeleton_core.model import (ANKLE_LEFT, ANKLE_RIGHT, ELBOW_LEFT, ELBOW_RIGHT, FOOT_LEFT, FOOT_RIGHT, HEAD,
                    HAND_LEFT, HAND_RIGHT, KNEE_LEFT, KNEE_RIGHT, NUM_JOINTS,
                    PARENTS, SHOULDER_CENTER, SPINE, WRIST_LEFT, WRIST_RIGHT, Body, standard_body)

__all__ = ['builtin_clips', 'builtin_split', 'BUILTIN_MOTIONS', 'pose_from_rotations']

FPS = 30.0
_I = np.array([0.0, 0.0, 0.0, 1.0])


# ------------------------------------------------------------------------------------------
# Rotation helpers (batched, xyzw)
# ------------------------------------------------------------------------------------------
def _axis_angle(axis, angle) -> np.ndarray:
    angle = np.asarray(angle, float)
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    h = angle[..., None] / 2.0
    return np.concatenate([a * np.sin(h), np.cos(h)], -1)


def rx(a):
    return _axis_angle((1, 0, 0), a)


def ry(a):
    return _axis_angle((0, 1, 0), a)


def rz(a):
    return _axis_angle((0, 0, 1), a)


def _mul(*qs):
    out = qs[0]
    for q in qs[1:]:
        out = quat_multiply(out, q)
    return out


def _min_rot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched smallest rotation taking unit vectors a to b (never exactly opposite here)."""
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    c = np.cross(a, b)
    w = 1.0 + np.sum(a * b, -1, keepdims=True)
    q = np.concatenate([c, w], -1)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# ------------------------------------------------------------------------------------------
# Forward kinematics from local rotations / aim directions
# ------------------------------------------------------------------------------------------
def pose_from_rotations(body: Body, local: Dict[int, np.ndarray], t: int,
                        aims: Optional[Dict[int, np.ndarray]] = None,
                        root_xy: Optional[np.ndarray] = None):
    """Joint positions (t, 20, 3) and segment orientations (t, 20, 4) from per-joint rotations.

    ``local[j]`` (t, 4) rotates segment j relative to its parent segment (root: the pelvis in the
    world); ``aims[j]`` (t, 3), if given instead, is segment j's direction in the frame of the
    thorax (segment ShoulderCenter) and is reached by the smallest rotation from the parent frame.
    The root height puts the lowest sole point on the floor; ``root_xy`` (t, 2) sets the
    horizontal root position (default 0).
    """
    aims = aims or {}
    rest = body.rest_offsets
    rdir = rest_directions(body)
    q = np.zeros((t, NUM_JOINTS, 4))
    p = np.zeros((t, NUM_JOINTS, 3))
    q[:, 0] = local.get(0, np.broadcast_to(_I, (t, 4)))
    for j in range(1, NUM_JOINTS):
        par = q[:, PARENTS[j]]
        if j in aims:
            d_world = quat_rotate(q[:, SHOULDER_CENTER], _unit(aims[j]))
            d_par = quat_rotate(quat_conjugate(par), d_world)
            lq = _min_rot(np.broadcast_to(rdir[j], d_par.shape), d_par)
            if j in local:  # extra twist about the segment's own rest axis
                lq = quat_multiply(lq, local[j])
        else:
            lq = local.get(j, np.broadcast_to(_I, (t, 4)))
        q[:, j] = quat_multiply(par, lq)
        p[:, j] = p[:, PARENTS[j]] + quat_rotate(q[:, j], np.broadcast_to(rest[j], (t, 3)))
    # soles: toe joints and heels (ankle + foot orientation applied to the ankle height)
    h_ankle = -body.rest_offsets[FOOT_LEFT, 2]
    heels = p[:, [ANKLE_LEFT, ANKLE_RIGHT]] + quat_rotate(
        q[:, [FOOT_LEFT, FOOT_RIGHT]], np.broadcast_to([0.0, 0.0, -h_ankle], (t, 2, 3)))
    soles = np.concatenate([p[:, [FOOT_LEFT, FOOT_RIGHT]], heels], 1)  # (t, 4, 3): L, R, L, R
    lowest = soles[..., 2].min(1)
    p[..., 2] -= lowest[:, None]
    if root_xy is not None:
        p[..., :2] += root_xy[:, None, :]
    q *= np.where(q[..., 3:4] < 0, -1.0, 1.0)
    return p, q, soles


def _no_skate(body, local, t, aims=None):
    """Positions with the root moved so that the lowest sole point (the stance foot's contact
    point: toe or heel) does not slide."""
    p, q, soles = pose_from_rotations(body, local, t, aims)
    contact = np.argmin(soles[..., 2], 1)  # (t,) index into the 4 sole points
    root = np.zeros((t, 2))
    for k in range(1, t):
        s = contact[k]
        root[k] = root[k - 1] - (soles[k, s, :2] - soles[k - 1, s, :2])
    p[..., :2] += root[:, None, :]
    return p, q


# ------------------------------------------------------------------------------------------
# Posture building blocks (angles in radians)
# ------------------------------------------------------------------------------------------
def _legs(local, hip_flex_l, knee_l, ankle_l, hip_flex_r, knee_r, ankle_r,
          abd_l=0.0, abd_r=0.0):
    """Sagittal leg angles: hip flexion (+ = thigh forward), knee flexion (+ = shank back),
    ankle dorsiflexion (+ = toes up); hip abduction (+ = outward)."""
    local[KNEE_LEFT] = _mul(ry(-np.asarray(hip_flex_l)), rx(-np.asarray(abd_l) + 0 * hip_flex_l))
    local[KNEE_RIGHT] = _mul(ry(-np.asarray(hip_flex_r)), rx(np.asarray(abd_r) + 0 * hip_flex_r))
    local[ANKLE_LEFT] = ry(np.asarray(knee_l))
    local[ANKLE_RIGHT] = ry(np.asarray(knee_r))
    local[FOOT_LEFT] = ry(-np.asarray(ankle_l))
    local[FOOT_RIGHT] = ry(-np.asarray(ankle_r))


def _crouch(local, depth, t):
    """Both legs bent with flat feet under the hips: hip flex d, knee 2d, ankle d."""
    d = np.broadcast_to(np.asarray(depth, float), (t,))
    _legs(local, d, 2 * d, d, d, 2 * d, d)


def _trunk(local, bend, twist, t, side=0.0):
    """Forward bend (+ = lean forward) split over lumbar and thoracic segments, axial twist
    (+ = turn left) and side bend."""
    bend = np.broadcast_to(np.asarray(bend, float), (t,))
    twist = np.broadcast_to(np.asarray(twist, float), (t,))
    side = np.broadcast_to(np.asarray(side, float), (t,))
    local[SPINE] = _mul(rz(0.5 * twist), ry(0.6 * bend), rx(-0.5 * side))
    local[SHOULDER_CENTER] = _mul(rz(0.5 * twist), ry(0.4 * bend), rx(-0.5 * side))
    local[HEAD] = ry(-0.5 * bend)  # keep looking ahead


def _arm_dir(flex, abd, side):
    """Upper-arm direction in the thorax frame from shoulder flexion (0 = hanging, pi/2 =
    forward, pi = up) and abduction (+ = outward from the sagittal plane)."""
    flex = np.asarray(flex, float)
    abd = np.asarray(abd, float)
    s = 1.0 if side == 'left' else -1.0
    d = np.stack([np.sin(flex) * np.cos(abd), s * np.sin(abd) + 0 * flex,
                  -np.cos(flex) * np.cos(abd)], -1)
    return d


def _forearm_dir(upper, bend, side, plane_up=None, flex=None):
    """Forearm direction: the upper-arm direction bent by ``bend`` towards ``plane_up``
    (thorax frame). Default: the natural elbow-flexion direction ``(cos f, 0, sin f)`` for
    shoulder flexion f, which is perpendicular to the upper arm for any abduction (forward for a
    hanging arm, up for an arm held forward), so there is no singular pose."""
    u = _unit(upper)
    if plane_up is None:
        f = np.broadcast_to(np.asarray(flex, float), u.shape[:-1])
        plane_up = np.stack([np.cos(f), np.zeros_like(f), np.sin(f)], -1)
    w = plane_up - np.sum(plane_up * u, -1, keepdims=True) * u
    w = _unit(w + 1e-9)
    b = np.asarray(bend, float)[..., None]
    return np.cos(b) * u + np.sin(b) * w


def _arms(aims, t, flex_l, abd_l, elbow_l, flex_r, abd_r, elbow_r, up_l=None, up_r=None):
    flex_l, flex_r = np.broadcast_to(flex_l, (t,)), np.broadcast_to(flex_r, (t,))
    ul = _arm_dir(flex_l, np.broadcast_to(abd_l, (t,)), 'left')
    ur = _arm_dir(flex_r, np.broadcast_to(abd_r, (t,)), 'right')
    aims[ELBOW_LEFT] = ul
    aims[ELBOW_RIGHT] = ur
    fl = _forearm_dir(ul, np.broadcast_to(elbow_l, (t,)), 'left', up_l, flex_l)
    fr = _forearm_dir(ur, np.broadcast_to(elbow_r, (t,)), 'right', up_r, flex_r)
    aims[WRIST_LEFT] = fl
    aims[WRIST_RIGHT] = fr
    aims[HAND_LEFT] = fl
    aims[HAND_RIGHT] = fr


def _keys(rng, t, period, lo, hi):
    """A smooth random curve: values drawn in [lo, hi] every ``period`` seconds, joined by
    cosine ease-in/out (zero velocity at the keys)."""
    n = int(np.ceil(t / (period * FPS))) + 2
    vals = rng.uniform(lo, hi, n)
    x = np.arange(t) / (period * FPS)
    k = np.floor(x).astype(int)
    u = 0.5 - 0.5 * np.cos(np.pi * (x - k))
    return vals[k] * (1 - u) + vals[k + 1] * u


def _sway(rng, local, t, amount=1.0):
    """Secondary motion added to standing clips: slow random trunk lean, twist and side bend."""
    a = np.radians(amount)
    _trunk(local, _keys(rng, t, 2.3, -4 * a, 12 * a), _keys(rng, t, 1.9, -15 * a, 15 * a), t,
           side=_keys(rng, t, 2.7, -6 * a, 6 * a))


def _smooth_pulse(x):
    """0 -> 1 -> 0 over x in [0, 1] with zero slope at both ends (periodic: uses frac(x))."""
    return 0.5 - 0.5 * np.cos(2 * np.pi * (x % 1.0))


# ------------------------------------------------------------------------------------------
# Motions: each returns (name, class, local, aims, walk?)
# ------------------------------------------------------------------------------------------
def _walk(rng, t, time):
    f = rng.uniform(0.85, 1.05)              # stride frequency (Hz); two steps per stride
    hip_a = np.radians(rng.uniform(20, 28))
    knee_a = np.radians(rng.uniform(50, 62))
    arm_a = np.radians(rng.uniform(12, 25))
    ph = 2 * np.pi * f * time
    local, aims = {}, {}
    hip_l = hip_a * np.sin(ph)
    hip_r = hip_a * np.sin(ph + np.pi)
    # knee flexes while the thigh swings forward (early swing), a little during stance
    # swing = hip flexing (cos(ph) > 0); the knee bends from late stance to late swing
    knee_l = np.radians(5) + knee_a * np.maximum(0, np.cos(ph + 0.3)) ** 2
    knee_r = np.radians(5) + knee_a * np.maximum(0, np.cos(ph + np.pi + 0.3)) ** 2
    ankle_l = np.radians(8) * np.sin(ph + 0.5)
    ankle_r = np.radians(8) * np.sin(ph + np.pi + 0.5)
    _legs(local, hip_l, knee_l, ankle_l, hip_r, knee_r, ankle_r)
    local[0] = rz(np.radians(4) * np.sin(ph))  # pelvis rotation
    _trunk(local, np.radians(4), -np.radians(6) * np.sin(ph), t)
    _arms(aims, t, arm_a * np.sin(ph + np.pi), np.radians(8),
          np.radians(20) + 0.5 * arm_a * (1 + np.sin(ph + np.pi)),
          arm_a * np.sin(ph), np.radians(8), np.radians(20) + 0.5 * arm_a * (1 + np.sin(ph)))
    return 'walk', 'locomotion', local, aims, True


def _arm_raise(rng, t, time):
    f = rng.uniform(0.25, 0.4)
    top = np.radians(rng.uniform(120, 170))
    lateral = rng.uniform() < 0.5
    u = _smooth_pulse(f * time)
    u2 = _smooth_pulse(f * time + 0.5 * rng.uniform(0, 1))
    local, aims = {}, {}
    _crouch(local, _keys(rng, t, 2.1, 0.0, np.radians(12)), t)
    _sway(rng, local, t)
    if lateral:  # abduction in the frontal plane
        _arms(aims, t, np.radians(5), np.radians(6) + top * u, np.radians(10),
              np.radians(5), np.radians(6) + top * u2, np.radians(10))
    else:        # forward flexion
        _arms(aims, t, np.radians(5) + top * u, np.radians(10), np.radians(10),
              np.radians(5) + top * u2, np.radians(10), np.radians(10))
    return 'arm_raise_lateral' if lateral else 'arm_raise_forward', 'upper_body', local, aims, False


def _wave(rng, t, time):
    f = rng.uniform(1.2, 2.0)
    amp = np.radians(rng.uniform(20, 35))
    env = np.clip(time / 1.0, 0, 1) * np.clip((time[-1] - time) / 1.0, 0, 1)
    env = 0.5 - 0.5 * np.cos(np.pi * env)
    local, aims = {}, {}
    _crouch(local, _keys(rng, t, 2.1, 0.0, np.radians(10)), t)
    _sway(rng, local, t, 0.6)
    # right upper arm raised sideways, forearm up, oscillating in the frontal plane
    ur = _arm_dir(np.radians(20) * env + np.radians(5), np.radians(6) + np.radians(80) * env,
                  'right')
    aims[ELBOW_RIGHT] = ur
    up = np.broadcast_to([0.0, 0.0, 1.0], (t, 3)) + np.stack(
        [0 * time, -np.sin(amp * np.sin(2 * np.pi * f * time)) * env, 0 * time], -1)
    fr = _forearm_dir(ur, np.radians(15) + np.radians(75) * env, 'right', up)
    aims[WRIST_RIGHT] = fr
    aims[HAND_RIGHT] = fr
    ul = _arm_dir(np.radians(5), np.radians(6), 'left')
    aims[ELBOW_LEFT] = np.broadcast_to(ul, (t, 3))
    fl = _forearm_dir(aims[ELBOW_LEFT], np.broadcast_to(np.radians(12), (t,)), 'left',
                      flex=np.radians(5))
    aims[WRIST_LEFT] = fl
    aims[HAND_LEFT] = fl
    return 'wave', 'upper_body', local, aims, False


def _punch(rng, t, time):
    rate = rng.uniform(0.8, 1.4)          # punches per second
    reach = np.radians(rng.uniform(75, 95))
    local, aims = {}, {}
    _crouch(local, np.radians(rng.uniform(10, 20)), t)
    n = max(1, int(np.ceil(time[-1] * rate)))
    left = np.zeros(t)
    right = np.zeros(t)
    for k in range(n):
        c = (k + 0.5) / rate
        w = np.exp(-0.5 * ((time - c) / 0.09) ** 2)
        (left if k % 2 == 0 else right)[:] += w
    left, right = np.clip(left, 0, 1), np.clip(right, 0, 1)
    _trunk(local, np.radians(8) + _keys(rng, t, 1.7, -np.radians(4), np.radians(10)),
           np.radians(25) * (right - left) + _keys(rng, t, 1.3, -np.radians(10), np.radians(10)),
           t, side=_keys(rng, t, 1.5, -np.radians(6), np.radians(6)))
    guard_flex, guard_abd, guard_elbow = np.radians(35), np.radians(12), np.radians(125)
    _arms(aims, t,
          guard_flex + (reach - guard_flex) * left, guard_abd * (1 - left) - np.radians(8) * left,
          guard_elbow * (1 - left) + np.radians(5) * left,
          guard_flex + (reach - guard_flex) * right,
          guard_abd * (1 - right) - np.radians(8) * right,
          guard_elbow * (1 - right) + np.radians(5) * right)
    return 'punch', 'boxing', local, aims, False


def _kick(rng, t, time):
    period = rng.uniform(1.8, 2.6)
    height = np.radians(rng.uniform(55, 80))
    side = rng.uniform() < 0.5
    local, aims = {}, {}
    x = (time / period) % 1.0
    lift = np.where(x < 0.6, _smooth_pulse(x / 0.6), 0.0)          # thigh up and down
    ext = np.where((x > 0.15) & (x < 0.45), _smooth_pulse((x - 0.15) / 0.3), 0.0)  # snap
    hip_k = height * lift
    knee_k = np.radians(90) * lift * (1 - ext) + np.radians(5)
    ankle_k = -np.radians(20) * lift
    d = np.radians(8)
    if side:
        _legs(local, d + hip_k, 2 * d + knee_k, d + ankle_k, d, 2 * d, d)
    else:
        _legs(local, d, 2 * d, d, d + hip_k, 2 * d + knee_k, d + ankle_k)
    _trunk(local, -np.radians(10) * lift, 0.0, t)
    _arms(aims, t, np.radians(35), np.radians(12), np.radians(120),
          np.radians(35), np.radians(12), np.radians(120))
    return 'kick', 'boxing', local, aims, False


def _pick_up(rng, t, time):
    period = rng.uniform(3.0, 4.0)
    bend = np.radians(rng.uniform(50, 75))
    knee = np.radians(rng.uniform(15, 35))
    local, aims = {}, {}
    u = _smooth_pulse(time / period)
    _crouch(local, knee * u, t)
    _trunk(local, bend * u, 0.0, t)
    # arms reach down/forward while bent, hold an object in front when upright
    flex = np.radians(40) + np.radians(10) * u
    _arms(aims, t, flex, np.radians(6), np.radians(50) * (1 - u) + np.radians(10),
          flex, np.radians(6), np.radians(50) * (1 - u) + np.radians(10))
    return 'pick_up', 'object_handling', local, aims, False


def _squat_lift(rng, t, time):
    period = rng.uniform(3.0, 4.5)
    depth = np.radians(rng.uniform(45, 70))
    local, aims = {}, {}
    u = _smooth_pulse(time / period)
    _crouch(local, depth * u, t)
    _trunk(local, np.radians(35) * u, 0.0, t)
    _arms(aims, t, np.radians(20) + np.radians(60) * u, np.radians(10), np.radians(30),
          np.radians(20) + np.radians(60) * u, np.radians(10), np.radians(30))
    return 'squat_lift', 'object_handling', local, aims, False


def _sword(rng, t, time):
    period = rng.uniform(1.5, 2.2)
    local, aims = {}, {}
    x = (time / period) % 1.0
    # diagonal swing: raised over the right shoulder, cut down to the left, return
    s = np.where(x < 0.35, _smooth_pulse(x / 0.7), _smooth_pulse(0.5 + (x - 0.35) / 1.3))
    _crouch(local, np.radians(12), t)
    _trunk(local, np.radians(20) * s + _keys(rng, t, 1.9, -np.radians(5), np.radians(8)),
           np.radians(30) * (s - 0.5) + _keys(rng, t, 2.3, -np.radians(12), np.radians(12)), t)
    flex = np.radians(150) - np.radians(110) * s
    _arms(aims, t, flex, -np.radians(10) - np.radians(15) * (1 - s), np.radians(25),
          flex, np.radians(15) * (1 - s) - np.radians(10), np.radians(25))
    return 'sword_swing', 'sword_fighting', local, aims, False


def _reach(rng, t, time):
    """Reaching to random targets around the body, one or both hands, leaning towards them."""
    local, aims = {}, {}
    period = rng.uniform(1.0, 1.6)
    flex_l = _keys(rng, t, period, np.radians(10), np.radians(150))
    flex_r = _keys(rng, t, period * 1.13, np.radians(10), np.radians(150))
    abd_l = _keys(rng, t, period * 0.91, -np.radians(25), np.radians(80))
    abd_r = _keys(rng, t, period * 1.07, -np.radians(25), np.radians(80))
    el_l = _keys(rng, t, period * 0.87, np.radians(0), np.radians(110))
    el_r = _keys(rng, t, period * 1.21, np.radians(0), np.radians(110))
    _arms(aims, t, flex_l, abd_l, el_l, flex_r, abd_r, el_r)
    reach_fwd = 0.5 * (np.sin(flex_l) + np.sin(flex_r))
    _crouch(local, _keys(rng, t, 1.7, 0.0, np.radians(25)), t)
    _trunk(local, np.radians(25) * reach_fwd * rng.uniform(0.3, 1.0),
           0.6 * (abd_r - abd_l) * 0.3, t, side=_keys(rng, t, 2.0, -np.radians(8), np.radians(8)))
    return 'reach', 'object_handling', local, aims, False


BUILTIN_MOTIONS: Tuple[Callable, ...] = (_walk, _arm_raise, _wave, _punch, _kick, _pick_up,
                                         _squat_lift, _sword, _reach)


def builtin_clips(seed: int = 0, body: Optional[Body] = None, duration: float = 6.0,
                  repeats: int = 1) -> List[MotionClip]:
    """The built-in motion set (one clip per motion in :data:`BUILTIN_MOTIONS`, ``repeats``
    times with fresh random parameters), on ``body`` (default: the standard body)."""
    body = standard_body() if body is None else body
    rng = np.random.default_rng(seed)
    t = int(round(duration * FPS))
    time = np.arange(t) / FPS
    clips = []
    for r in range(repeats):
        for make in BUILTIN_MOTIONS:
            name, cls, local, aims, walking = make(rng, t, time)
            if walking:
                p, q = _no_skate(body, local, t, aims)
            else:
                p, q, _ = pose_from_rotations(body, local, t, aims)
            yaw = rng.uniform(-np.pi, np.pi)
            qy = rz(np.array(yaw))
            p = quat_rotate(np.broadcast_to(qy, p.shape[:-1] + (4,)), p)
            p[..., :2] += rng.uniform(-1.0, 1.0, 2)
            q = quat_multiply(np.broadcast_to(qy, q.shape), q)
            q *= np.where(q[..., 3:4] < 0, -1.0, 1.0)
            suffix = f'_{r}' if repeats > 1 else ''
            clips.append(MotionClip(name=f'builtin_{name}{suffix}', motion_class=cls, fps=FPS,
                                    positions=p, orientations=q,
                                    source=f'builtin:{name}:seed={seed}',
                                    description=make.__name__.strip('_')))
    return clips


def builtin_split(seed: int = 0, body: Optional[Body] = None
                  ) -> Tuple[List[MotionClip], List[MotionClip]]:
    """(database_clips, dev_clips): the same motions with independent random parameters
    (database: 5 variants of each motion from ``seed``; dev: one variant from ``seed + 1000``),
    so dev postures are not in the database."""
    return builtin_clips(seed, body, repeats=5), builtin_clips(seed + 1000, body)
