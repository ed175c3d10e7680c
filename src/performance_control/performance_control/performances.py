"""Scripted performances for the tests, the benchmark and the demo: what a user in the real space
does, optionally through the Kinect sensor model.

* :func:`imitation_stream` -- stand, imitate a feature's example, stand, imitate again (another
  body size, style, period and amplitude than the example; fades of ``fade`` s).
* :func:`jump_stream` -- jumping in place (crouch, take-off, flight, landing) for the trampoline.
* :func:`non_imitation_clips` -- walking, boxing (punches, kicks) and standing: must not engage.
* :func:`to_sensor` -- a clip (T, 20, 3, world: floor z = 0) through the sensor model (sensor
  frame, noise, occlusions) or just placed in front of the sensor.
"""
from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Dict, List, Optional, Tuple

import numpy as np
from skeleton_core.model import (ANKLE_LEFT, ANKLE_RIGHT, FOOT_LEFT, FOOT_RIGHT, HIP_LEFT,
                                 HIP_RIGHT, KNEE_LEFT, KNEE_RIGHT, TRACKED, Body, standard_body)
from skeleton_data.motions import builtin_clips, pose_from_rotations

from .examples import FPS, _legs, imitation, random_style
from skeleton_eval.sensor_model import SensorModel


_LEG_JOINTS = (HIP_LEFT, HIP_RIGHT, KNEE_LEFT, KNEE_RIGHT, ANKLE_LEFT, ANKLE_RIGHT, FOOT_LEFT,
               FOOT_RIGHT)


def performer(rng: np.random.Generator) -> Tuple[Body, Dict, float]:
    """(body, style, scale): another body size (1.5-1.95 m), style and tempo than the example."""
    body = standard_body(float(rng.uniform(1.5, 1.95)))
    return body, random_style(rng), float(rng.uniform(0.75, 1.3))


def _envelope(n: int, windows: List[Tuple[float, float]], fade: float, fps: float) -> np.ndarray:
    t = np.arange(n) / fps
    env = np.zeros(n)
    for a, b in windows:
        up = np.clip((t - a) / fade, 0, 1) * np.clip((b - t) / fade, 0, 1)
        env = np.maximum(env, 0.5 - 0.5 * np.cos(np.pi * up))
    return env


def imitation_stream(feature, rng: np.random.Generator, fps: float = FPS,
                     pattern=((2.0, 6.0), (8.0, 12.0)), total: float = 13.0, fade: float = 0.2):
    """(positions (T, 20, 3) world, windows [(start, end) s]) of a user imitating ``feature``'s
    example during ``pattern``."""
    body, style, tempo = performer(rng)
    params = dict(feature.example.params)
    params['period'] = float(params.get('period', 1.5)) * tempo
    for k in ('amplitude_deg', 'reach'):
        if k in params:
            params[k] = float(params[k]) * float(rng.uniform(0.8, 1.2))
    n = int(round(total * fps))
    env = _envelope(n, list(pattern), fade, fps)
    p = imitation(feature.example.generator, params, body, n, fps, style,
                  phase0=float(rng.uniform()), active=env)
    return p, list(pattern)


def jump_stream(rng: np.random.Generator, n_jumps: int = 4, fps: float = FPS,
                body: Optional[Body] = None, lead: float = 1.0) -> np.ndarray:
    """Jumping in place: per jump a 0.3 s crouch, a 0.15 s push-off (the legs extend while the
    feet are still on the floor), ``flight`` s in the air, a 0.3 s landing crouch."""
    body = body or standard_body(float(rng.uniform(1.6, 1.85)))
    cycle = 1.4
    total = lead + n_jumps * cycle + 1.0
    n = int(round(total * fps))
    t = np.arange(n) / fps
    crouch = np.zeros(n)
    lift = np.zeros(n)
    g = 9.81
    for k in range(n_jumps):
        t0 = lead + k * cycle
        flight = float(rng.uniform(0.3, 0.4))
        x = (t - t0) / 0.3                     # down
        crouch += np.where((x >= 0) & (x < 1), 0.5 - 0.5 * np.cos(np.pi * x), 0.0)
        x = (t - t0 - 0.3) / 0.15              # push-off
        crouch += np.where((x >= 0) & (x < 1), 0.5 + 0.5 * np.cos(np.pi * x), 0.0)
        tf = t - (t0 + 0.45)
        inair = (tf >= 0) & (tf < flight)
        lift += np.where(inair, 0.5 * g * tf * (flight - tf), 0.0)
        xl = (tf - flight) / 0.3
        crouch += np.where((xl >= 0) & (xl < 1), 0.5 * np.sin(np.pi * xl), 0.0)
    d = np.radians(45) * crouch
    local: Dict = {}
    _legs(local, d, 2 * d, d, 2 * d, n)
    p, _, _ = pose_from_rotations(body, local, n, {})
    p[..., 2] += lift[:, None]
    return p


def lift(p: np.ndarray, t0: float, flight: float, fps: float = FPS) -> np.ndarray:
    """The poses (T, 20, 3) with a jump: from ``t0`` s the whole body flies ``flight`` s (a
    parabola: the feet leave the floor by g flight^2 / 8 at the top)."""
    tf = np.arange(len(p)) / fps - t0
    up = np.where((tf >= 0) & (tf < flight), 0.5 * 9.81 * tf * (flight - tf), 0.0)
    out = np.array(p, float)
    out[..., 2] += up[:, None]
    return out


def jump_to_bars_stream(world, rng: np.random.Generator, jump: float = 1.5,
                        flight: float = 0.45, stop: float = 7.0, total: float = 10.0,
                        fps: float = FPS) -> np.ndarray:
    """A user under the bars: raises the arms overhead, jumps at ``jump`` s (``flight`` s in the
    air, the arms up: the reach/jump to engage), swings them like on the monkey bars until
    ``stop`` s, then lowers them (the character lets go and drops). World poses (T, 20, 3)."""
    body, style, tempo = performer(rng)
    prm = dict(world.features['monkey_bars'].example.params)
    prm['period'] = float(prm.get('period', 1.6)) * tempo
    n = int(round(total * fps))
    env = _envelope(n, [(jump - 0.7, stop)], 0.3, fps)
    return lift(imitation('monkey_swing', prm, body, n, fps, style, active=env), jump, flight, fps)


def _turn(p: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Each frame (T, 20, 3) turned by ``yaw`` (T,) rad about the vertical through its hips."""
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.zeros((len(yaw), 3, 3))
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = c, -s, s, c, 1.0
    piv = p[:, :1, :].copy()
    piv[..., 2] = 0.0
    return np.einsum('tij,tkj->tki', rot, p - piv) + piv


def continuous_stream(world, rng: np.random.Generator, fps: float = FPS,
                      rope_at: Optional[float] = None, steer: float = 0.0,
                      bars_at: float = 3.5, rope_stops: Tuple[float, ...] = (),
                      approach: Tuple[Tuple[float, float], ...] = (),
                      rope_approach: Tuple[Tuple[float, float], ...] = (),
                      swim_at: Optional[float] = None):
    """One continuous performance (Sec. 8.3): stand; walk in place (the character
    walks forward under the monkey bars) until ``bars_at`` s; stop, raise the arms and jump (the
    character catches a bar); swing like on the bars; lower the arms (the character lets go and
    drops); walk in place turning 45 deg right (the character walks into the water); swim a
    breaststroke. With ``rope_at`` (s), the rope before the water: after the bars the user walks
    straight on until ``rope_at`` -- when the character has arrived at the rope: the user watches
    it, see :func:`watched_performance` --, climbs hand over hand 6 s, lowers the arms (the
    character drops), then walks turning 45 deg right into the water and swims. ``rope_stops``
    (s, before ``rope_at``): earlier stops at which the user reached up for the rope, saw the
    character come to rest short of it and walked on (from ``stop`` + :data:`ROPE_WAIT`).
    ``steer`` (rad, left positive): with the rope, the user turns by this much as they start the
    walk after the bars (toward the rope, :func:`watched_performance`), and from the rope turns
    to 45 deg right of where they first faced. ``approach`` ((s, rad), ...): turns on the walk to
    the bars, each to the given heading (left positive, from where they first faced) over 1 s;
    ``rope_approach`` the same on the walk to the rope (after ``steer``). ``swim_at`` (s, with
    the rope; default ``rope_at`` + 17): when the user stops walking and swims (the walk fades
    out over the 0.2 s before it: the stream up to ``swim_at`` - 0.2 is the same as any later
    one's).
    Returns (positions (T, 20, 3) world, schedule [(start s, what the user does)]) with the
    user's body, style and tempo drawn from ``rng``."""
    body, style, tempo = performer(rng)
    walk = dict(world.features['floor'].example.params)
    walk['period'] = float(walk.get('period', 1.1)) * tempo
    swing = dict(world.features['monkey_bars'].example.params)
    swing['period'] = float(swing.get('period', 1.6)) * tempo
    swim = dict(world.features['water'].example.params)
    swim['period'] = float(swim.get('period', 1.5)) * tempo
    # the bars' part starts this much later (the walk fades out over 0.2 s after bars_at, the
    # arms rise from bars_at + 0.2: the stream up to bars_at is the same as any later stop's)
    d = float(bars_at) - 3.5
    bars = [(0.0, 'stand'), (1.0, 'walk'), (3.7 + d, 'raise the arms'), (4.5 + d, 'jump'),
            (5.0 + d, 'swing'), (9.0 + d, 'lower the arms'), (10.5 + d, 'walk')]
    if rope_at is None:
        sched = bars + [(18.0 + d, 'swim')]
        total, walks, turn, climbs = 24.0 + d, [(1.0, bars_at + 0.2), (10.5 + d, 18.0 + d)], 11.0 + d, []
    else:
        r = float(rope_at)
        stops = [float(x) for x in rope_stops]
        sched = list(bars)
        walks = [(1.0, bars_at + 0.2)]     # fades out after bars_at (as the rope's walks)
        climbs = []
        start = 10.5 + d
        for s_ in stops:        # reached up at the stop, saw the character short, walked on
            walks.append((start, s_ + 0.2))
            climbs.append((s_ + 0.2, s_ + ROPE_WAIT + 0.3))
            sched += [(s_, 'reach for the rope'), (s_ + ROPE_WAIT, 'walk')]
            start = s_ + ROPE_WAIT
        sw = r + 17.0 if swim_at is None else float(swim_at)
        if not r + 8.5 <= sw <= ROPE_LATEST + 23.0 - SWIM_MIN:
            raise ValueError(f'swim_at {sw} s: after the walk from the rope and at least '
                             f'{SWIM_MIN} s before the end of the stream')
        sched += [(r, 'climb'), (r + 6.5, 'lower the arms'), (r + 8.0, 'walk'), (sw, 'swim')]
        # one length whatever rope_at (the sensor noise is drawn for the whole stream: the same
        # frames get the same noise, so the performance up to rope_at is the one watched)
        total = ROPE_LATEST + 23.0
        # the walk fades out after rope_at (the stream is the same as any later stop's up to it)
        walks += [(start, r + 0.2), (r + 8.0, sw)]
        turn = r + 8.5
        climbs.append((r + 0.2, r + 6.5))
    n = int(round(total * fps))
    t = np.arange(n) / fps
    env_w = _envelope(n, walks, 0.2, fps)
    env_b = _envelope(n, [(3.7 + d, 9.0 + d)], 0.3, fps)
    env_s = _envelope(n, [(sched[-1][0] + 0.3, total + 1.0)], 0.25, fps)
    pw = imitation('walk_cycle', walk, body, n, fps, style, active=env_w)
    pb = imitation('monkey_swing', swing, body, n, fps, style, active=env_b)
    ps = imitation('breaststroke', swim, body, n, fps, style, active=env_s)
    arms = [j for j in range(pw.shape[1]) if j not in _LEG_JOINTS]
    p = pw.copy()
    layers = [(env_b, pb), (env_s, ps)]
    if climbs:
        rope = dict(world.features['rope'].example.params)
        rope['period'] = float(rope.get('period', 1.4)) * tempo
        env_r = _envelope(n, climbs, 0.3, fps)
        layers.append((env_r, imitation('rope_climb', rope, body, n, fps, style, active=env_r)))
    for env, src in layers:
        on = (env > 0)[:, None, None]
        p[:, arms] = np.where(on, src[:, arms], p[:, arms])
    p = lift(p, 4.5 + d, 0.45, fps)
    # the user's heading: each turn toward its aim over 1 s, the last to 45 deg right (half
    # turned: still tracked)
    aims = [(float(a), float(y)) for a, y in approach]
    if climbs and steer:
        aims.append((STEER_AT + d, float(steer)))
    if climbs:
        aims += [(float(a), float(y)) for a, y in rope_approach]
    yaw, prev = np.zeros(n), 0.0
    for a, y in aims:
        yaw = yaw + (y - prev) * np.clip((t - a) / 1.0, 0, 1)
        prev = y
    yaw = yaw + (-np.radians(45) - prev) * np.clip((t - turn) / 1.0, 0, 1)
    return _turn(p, yaw), sched


# s: the latest the user stops walking for the bars (the stream's length is fixed by it and
# ROPE_LATEST); the blind script stopped at 3.5 s, where the characters of slow walkers (seeds 12
# and 14: 0.6-0.9 m short of the first bar) could not reach a bar with their jump
BARS_LATEST = 8.0
# m: the user stops walking when the character will come to rest this close (horizontally) to the
# middle bar (one bar spacing): aiming at the first bar (within half a spacing of it), the
# anticipated coast's error -- the walk slows as the user's swing fades -- left dev seed 9's
# character 0.5 m short of it, its hands out of the jump's reach; from the middle bar, a coast off
# by +-0.6 m still rests under a bar. The whole bar, not its midpoint: aiming at the midpoint
# (within 0.4 m), held-out seed 23's character passed under the bars 0.45-0.5 m to the side of it
# and walked on
BARS_STOP = 0.4
# s: the latest the user may start to climb the rope (the stream's length is fixed by it)
ROPE_LATEST = 24.0 + (BARS_LATEST - 3.5)
# m: the user stops walking when the character will come to rest this close (horizontally) to
# the rope: the hands reach 0.3 m (the rope's engage distance)
ROPE_STOP = 0.3
# s: how long the character walks on after the user stops -- the user anticipates it: WALK_HOLD
# (0.4 s) and the walk's 0.2 s fade. Stopping when the COM itself was 0.6 m from the rope, a
# fast walker (seed 3, ~1 m/s) came to rest 0.3 m past the rope, its hands behind it
COAST = 0.6
# s: after stopping for the rope the user reaches up for it and watches the character come to
# rest; this long after the stop, a character still farther than ROPE_STOP from the rope (the
# anticipated coast is only a guess: the walk slows down as the user's swing fades -- seeds 2 and
# 10 rested 0.5-0.57 m short) makes the user walk on (at most ROPE_TRIES stops)
ROPE_WAIT = 1.2
ROPE_TRIES = 3
# s, rad: on the walk to the bars the user looks every APPROACH_EVERY s where the character is
# and, when the bars' middle is more than APPROACH_TOLERANCE off the way they face, turns toward
# it (at most MAX_STEER). The sensor model's turn episodes (the user turning away, up to ~90 deg
# for 1-2 s) turn the character with the user: seed 14's walked 1.5 m to the side of the bars
APPROACH_EVERY = 1.0
APPROACH_TOLERANCE = np.radians(15)
# s: when the user, who has watched the character land from the bars, starts walking again and
# turns toward the rope (the character lands 0.1-2 m from where it let go, up to 0.6 m to the side
# of the rope's line: walking straight on it passed the rope, seeds 3 and 6); with the bars later
# (``bars_at``), as much later
STEER_AT = 10.5
# s: the least the user swims at the end of the stream; the user who sees the character still
# short of the water when they would start to swim (the rope's swim_at, rope_at + 17 s) walks on
# until it is in the water, at the latest this long before the stream ends (held-out seed 34's
# character stood 1.2 m short of the water's edge when its blind script started to swim)
SWIM_MIN = 4.0
# rad: the most the user turns toward the rope (a user turned further away from the sensor is
# tracked badly; the last walk turns 45 deg too)
MAX_STEER = np.radians(45)


def _bars_centre(world) -> np.ndarray:
    """The middle (x, y) of the world's bars (their capsules' midpoints averaged)."""
    mids = [0.5 * (g.vec('from')[:2] + g.vec('to')[:2]) for f in world.features.values()
            if f.kind == 'bars' for g in f.geoms if g.type == 'capsule']
    return np.mean(mids, axis=0)


def _middle_bar(world, centre: np.ndarray):
    """(from, to) (x, y) of the bar nearest the middle of the world's bars."""
    caps = [g for f in world.features.values() if f.kind == 'bars' for g in f.geoms
            if g.type == 'capsule']
    g = min(caps, key=lambda g: float(np.linalg.norm(
        0.5 * (g.vec('from')[:2] + g.vec('to')[:2]) - centre)))
    return g.vec('from')[:2], g.vec('to')[:2]


def _segment_distance(xy: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Distance (m) of a point to the segment a-b (all (x, y))."""
    ab = b - a
    u = float(np.clip((xy - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(xy - (a + u * ab)))


def _watched_sensor(p: np.ndarray, seed: int, noise: bool):
    """The continuous performance through the sensor model, placed so that a frame's placement
    does not depend on the rest of the stream: the user starts facing the sensor (the clip, facing
    +x, turned to -x) and the model does not turn the clip to its mean facing (``face_sensor``:
    the mean of a stream that turns toward the rope or climbs earlier differs, and the
    continuation stream of :func:`watched_performance` was turned by up to 16 deg against the
    watched prefix -- a turn of the character the user did not make)."""
    q = np.array(p, float)
    q[..., :2] *= -1.0
    return to_sensor(q, f'cont{seed}', seed, noise, WATCHED_PLACEMENT, states=True)


def _course_error(seen: List[np.ndarray], target: np.ndarray, fps: float) -> Optional[float]:
    """The turn (rad, left positive) that points the character's course (its COM's horizontal
    motion over the last 0.5 s) at ``target`` (x, y), when that course passes beside it -- farther
    than half of :data:`ROPE_STOP` (the hands reach ROPE_STOP) -- and the target is ahead and at
    least 1 m away (a turn takes the user 1 s); else None (standing, on course, or too close)."""
    n = int(round(0.5 * fps))
    if len(seen) <= n:
        return None
    v = (seen[-1] - seen[-1 - n]) * fps / n
    speed = float(np.linalg.norm(v))
    to = np.asarray(target, float) - seen[-1]
    if speed < 0.3 or float(np.linalg.norm(to)) < 1.0 or float(to @ v) <= 0.0:
        return None
    if abs(float(v[0] * to[1] - v[1] * to[0])) / speed <= 0.5 * ROPE_STOP:
        return None
    turn = math.atan2(to[1], to[0]) - math.atan2(v[1], v[0])
    return float((turn + math.pi) % (2 * math.pi) - math.pi)


def _predicted_rest(seen: List[np.ndarray], fps: float) -> np.ndarray:
    """Where the character (its COM's horizontal positions ``seen``, one per frame) comes to rest
    if the user stops now: its speed over 0.3 s carried on for :data:`COAST` s."""
    n = int(round(0.3 * fps))
    v = (seen[-1] - seen[-1 - n]) * fps / n if len(seen) > n else np.zeros(2)
    return seen[-1] + COAST * v


def watched_performance(world, seed: int, step, noise: bool = True, fps: float = FPS):
    """The continuous performance with the rope, performed by a user who watches the character:
    they walk in place until the character, which walks on :data:`COAST` s after they stop, would
    come to rest under the bars (within :data:`BARS_STOP` of the middle bar), then jump; after the bars
    they turn toward the rope (:data:`STEER_AT`) and walk on until it would come to rest within
    :data:`ROPE_STOP` of the rope, reach up for it and, should it rest farther
    (:data:`ROPE_WAIT` s later), walk on again; then climb (:func:`continuous_stream` with
    ``bars_at``, ``rope_stops`` and ``rope_at``). ``step(positions (20, 3) sensor frame, tracking
    states (20,), t) -> the character's COM`` (or the controller's output: its ``com`` and
    ``contacts``, so that the user also sees a hand on the rope) is called once per frame (a
    controller of the caller's). Returns (schedule, rope_at or None: never arrived).
    Each decision changes the script only after the frame it was taken on: the sensor frames up
    to it are the previous stream's (the sensor model's noise and, with :func:`_watched_sensor`,
    its placement do not depend on the rest of the stream)."""
    g = next(g for g in world.features['rope'].geoms if g.type == 'rope')
    top = g.vec('top')
    rng = np.random.default_rng

    held = {}

    def perform(i):       # one frame: the character's COM (x, y); what its hands hold
        r = step(sa[i], sta[i], i / fps)
        held.clear()
        held.update(getattr(r, 'contacts', {}))
        return np.asarray(getattr(r, 'com', r), float)[:2]

    def stream(**kw):
        a, sched = continuous_stream(world, rng(seed), fps, **kw)
        sa, sta = _watched_sensor(a, seed, noise)
        return sched, sa, sta

    # the bars: walk until the character will rest under them, turning toward them when it
    # heads elsewhere
    bars = _bars_centre(world)
    middle = _middle_bar(world, bars)
    approach: List[Tuple[float, float]] = []
    aim = 0.0
    sched, sa, sta = stream(bars_at=BARS_LATEST, rope_at=ROPE_LATEST)
    seen: List[np.ndarray] = []
    nxt, bars_at = 0, BARS_LATEST        # nxt: the next frame to perform
    every = int(round(APPROACH_EVERY * fps))
    while nxt < int(round(BARS_LATEST * fps)):
        seen.append(perform(nxt))
        nxt += 1
        rest = _predicted_rest(seen, fps)
        if nxt / fps > 1.5 and _segment_distance(rest, *middle) < BARS_STOP:
            bars_at = (nxt - 1) / fps
            break
        to = bars - seen[-1]
        if nxt >= 2 * fps and nxt % every == 0 and float(np.linalg.norm(to)) > 1.0:
            want = float(np.clip(np.arctan2(to[1], to[0]), -MAX_STEER, MAX_STEER))
            if abs(want - aim) > APPROACH_TOLERANCE:     # off course: turn toward the bars
                aim = want
                approach.append(((nxt - 1) / fps, aim))
                sched, sa, sta = stream(bars_at=BARS_LATEST, rope_at=ROPE_LATEST,
                                        approach=tuple(approach))
    d = bars_at - 3.5
    kw = dict(bars_at=bars_at, approach=tuple(approach))
    sched, sa, sta = stream(rope_at=ROPE_LATEST, **kw)
    while nxt < int(round((STEER_AT + d) * fps)):
        seen.append(perform(nxt))
        nxt += 1
    # the user looks where the character stands and turns toward the rope as they walk (the
    # character heads where the user faces, +x at the start)
    to = top[:2] - seen[-1]
    steer = float(np.clip(np.arctan2(to[1], to[0]), -MAX_STEER, MAX_STEER))
    heading = np.array([math.cos(steer), math.sin(steer)])
    kw['steer'] = steer
    sched, sa, sta = stream(rope_at=ROPE_LATEST, **kw)
    stops: List[float] = []
    fixes: List[Tuple[float, float]] = []      # course corrections on the way to the rope
    aim = steer
    while True:
        rope_at = None
        while nxt < len(sa):
            seen.append(perform(nxt))
            nxt += 1
            now = (nxt - 1) / fps
            if now <= ROPE_LATEST and float(np.linalg.norm(
                    _predicted_rest(seen, fps) - top[:2])) < ROPE_STOP:
                rope_at = now
                break
            # on the way the user watches where the character heads and, when it would pass
            # beside the rope, turns by the character's course error (their facing and the
            # character's heading differ by the sensor's yaw: correcting the course, not the aim)
            if now <= ROPE_LATEST and now >= STEER_AT + d + 1.0 and nxt % every == 0:
                turn = _course_error(seen, top[:2], fps)
                if turn is not None:
                    aim = float(np.clip(aim + turn, -MAX_STEER, MAX_STEER))
                    heading = np.array([math.cos(aim), math.sin(aim)])
                    fixes.append((now, aim))
                    kw['rope_approach'] = tuple(fixes)
                    sched, sa, sta = stream(rope_at=ROPE_LATEST, rope_stops=tuple(stops), **kw)
        if rope_at is None:
            return sched, None
        sched, sa, sta = stream(rope_at=rope_at, rope_stops=tuple(stops), **kw)
        while nxt < min(int(round((rope_at + ROPE_WAIT) * fps)), len(sa)):
            seen.append(perform(nxt))
            nxt += 1
        to = top[:2] - seen[-1]
        short = (float(np.linalg.norm(to)) > ROPE_STOP and float(to @ heading) > 0.0
                 and 'rope' not in held.values())
        if not short or len(stops) + 1 >= ROPE_TRIES or rope_at + ROPE_WAIT >= ROPE_LATEST:
            break
        stops.append(rope_at)     # short of the rope (ahead): walk on
        sched, sa, sta = stream(rope_at=ROPE_LATEST, rope_stops=tuple(stops), **kw)
    # the last walk: the user watches the character too -- still short of the water when they
    # would start to swim (the walk's fade-out, 0.2 s before), they walk on until it is in it
    kw = dict(kw, rope_at=rope_at, rope_stops=tuple(stops))
    wet = _in_volume(world, 'water')
    fade = int(round((rope_at + 17.0 - 0.2) * fps))
    while nxt < min(fade, len(sa)):
        seen.append(perform(nxt))
        nxt += 1
    if nxt < len(sa) and not wet(seen[-1]):
        latest = int(round((ROPE_LATEST + 23.0 - SWIM_MIN - 0.2) * fps))
        while nxt < latest and not wet(seen[-1]):
            if nxt == fade:
                sched, sa, sta = stream(swim_at=latest / fps + 0.2, **kw)
            seen.append(perform(nxt))
            nxt += 1
        sched, sa, sta = stream(swim_at=nxt / fps + 0.2, **kw)
    for k in range(nxt, len(sa)):
        perform(k)
    return sched, rope_at


def _in_volume(world, name: str):
    """A test of an (x, y) against the horizontal extent of the feature's volumes."""
    boxes = [(g.vec('center')[:2], g.vec('half')[:2]) for g in world.features[name].geoms
             if g.type == 'volume']
    return lambda xy: any(bool(np.all(np.abs(np.asarray(xy) - c) <= h)) for c, h in boxes)


def non_imitation_clips(seed: int) -> List[Tuple[str, np.ndarray]]:
    """Walking, boxing (punch, kick) and standing clips (name, (T, 20, 3) world)."""
    out = []
    for c in builtin_clips(seed):
        base = c.name.replace('builtin_', '')
        if base in ('walk', 'punch', 'kick'):
            out.append((base, np.asarray(c.positions, float)))
    rng = np.random.default_rng(seed)
    body = standard_body(float(rng.uniform(1.55, 1.9)))
    n = int(6 * FPS)
    stand = imitation('monkey_swing', {}, body, n, active=np.zeros(n))
    stand = stand + np.cumsum(rng.normal(0, 0.0015, (n, 1, 3)), axis=0) * [1, 1, 0]
    out.append(('stand', stand))
    return out


# The play space of a performance: the whole body with the hands raised above the head must be in
# the 43 deg vertical field of view; at the default 2.5 m / 0.8 m (sensor_model.yaml) raised hands
# leave it (NOT_TRACKED). 3.5 m away with the sensor 1.2 m up sees 2.4 m high hands and the feet.
PERFORMANCE_PLACEMENT = {'placement': {'distance_m': 3.5, 'sensor_height_m': 1.2}}
# The continuous performance's sensor: the same placement, the user's turns kept (the sensor model
# otherwise keeps every user facing the screen)
TURNING_PLACEMENT = {'placement': {**PERFORMANCE_PLACEMENT['placement'], 'keep_facing': False}}
SENSOR_HEIGHT = 1.2
# The watched performance's sensor: the turning placement with the clip's own facing kept (see
# performances._watched_sensor)
WATCHED_PLACEMENT = {'placement': {**TURNING_PLACEMENT['placement'], 'face_sensor': False}}


def to_sensor(positions: np.ndarray, name: str, seed: int, noise: bool = True,
              sensor_params=None, states: bool = False):
    """A world clip as the sensor reports it (sensor frame): the sensor model's stream (placement,
    noise, dropouts; scenario a) or, with ``noise=False``, just placed 2.5 m ahead facing it.
    With ``states``: (positions, tracking states (T, 20) uint8; all TRACKED without noise)."""
    sm = SensorModel(PERFORMANCE_PLACEMENT if sensor_params is None else sensor_params, seed=seed)
    clip = SimpleNamespace(name=name, positions=positions, fps=FPS)
    if not noise:
        pos = sm.place(clip)
        return (pos, np.full(pos.shape[:2], TRACKED, np.uint8)) if states else pos
    s = sm.corrupt(clip, 'a')
    pos = np.asarray(s.positions, float)
    return (pos, np.asarray(s.tracking_state, np.uint8)) if states else pos


__all__ = ['PERFORMANCE_PLACEMENT', 'SENSOR_HEIGHT', 'imitation_stream', 'jump_stream',
           'jump_to_bars_stream', 'lift',
           'continuous_stream', 'TURNING_PLACEMENT',
           'non_imitation_clips', 'to_sensor', 'performer']
