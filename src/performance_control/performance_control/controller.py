"""One user's performance controller (Ishigaki et al. 2009, Fig. 3): feature identification and
intention recognition, the dynamic process, kinematic composition and motion integration, per
sensor frame. No ROS: the node (``control_node``) only adapts messages and parameters.

    ctrl = PerformanceController(load_world('playground'), ControlParams())
    out = ctrl.step(positions_sensor_20x3, t_seconds)     # -> ControlOutput
    out.positions_sensor    # the pose the physics character tracks (sensor frame)

Frames: input and output in the sensor frame (REP-103); the world is the physics world
(:class:`physics_sim.simulation.SensorPose`: floor at z = 0). The character starts at the world's
``spawn`` (or a feature's ``start``), facing +x; it turns with the user (yaw relative to the user's
first frame). The user's floor is the lowest foot of the first frames.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Dict, Optional

import numpy as np
from physics_sim.simulation import SensorPose
from skeleton_core.geometry import facing_yaw
from skeleton_core.params import check, nested, param
from skeleton_core.model import (FOOT_LEFT, FOOT_RIGHT, JOINT_INDEX, estimate_height)

from .composition import NEAR, Obstacles, PoseComposer, integrate_motion, integrate_rule
from .dynamics import DynamicProcess
from .examples import example_motion
from .features import EFFECTORS, Feature, World
from .intention import (ExampleModel, IntentionRecognizer, Recognition, RecognizerParams,
                        center_of_mass, yaw_rotation)
from .locomotion import Walker, example_gait

HANDS = ('HandLeft', 'HandRight')
# s: the character keeps walking this long after the floor's recognizer last said "imitating"
# (one walking step: a user's walk in place drops out for a few frames -- an arm briefly
# occluded, a step off the example's rhythm -- and the character should not stop and go)
WALK_HOLD = 0.4
FEET = ('FootLeft', 'FootRight')
# m: how far above the character's hand a bar may be and still be caught when the user jumps
# under it. Not a human jump (0.3-0.5 m): the character jumps as high as the bars need, as the
# user's small space and modest jump ask (the playground's bars are 2.75 m up, for a hanging
# 1.95 m user's feet to clear the floor; a 1.5-1.95 m character's hands, swinging overhead, are
# at 1.75-2.2 m, measured on the bench's performers -- 1.61-1.65 m in the jump of the continuous
# performance's seed 3, a 1.5 m performer with bent elbows, who missed the bar at 1.0 m)
JUMP_REACH = 1.25
# m: how far ahead (horizontally) of the character's hand a bar may be and still be caught in the
# jump: the character leaps to it, as a child jumps forward to the first rung. The walk stops
# where the user stops walking in place, not exactly under a bar (the 0.4 m between bars); without
# it the catch needed the hand within the bars' 0.15 m engage distance, and the continuous
# performance's seed 0 reached the bar only thanks to a false walk of the first 0.6 s (the
# activity gate's start-up noise, removed: intention.py)
JUMP_LEAP = 0.5
# m/s: on a feature the hands do not climb (no engage.regrab: the bars) a held hand lets go when
# the user lowers it faster than this relative to their COM -- the release read from the arm's
# movement, before the hand is low enough for hand_release_margin. Lowering the arms while
# holding turns the hands' target about the grip at ~8 rad/s and the contact's PD pulls the body
# round the bar (the COM left the bars at 6-8 m/s); the swings of the continuous
# performance's seeds 0-9 lower a held hand at most ~0.6 m/s (0.1 s smoothed), the user's
# arms coming down reach 1.2-1.4 m/s two frames before the hands pass the head. On the rope
# and the rocks lowering a held hand is the pull of the climb: there both held hands lowered
# together let go (climbing, seeds 0-9, the less lowered of two held hands went down at most
# 0.13 m/s; lowering both arms from the rope pulled the body up along them and it rose 0.6-0.7 m
# after letting go, seeds 16 and 17).
RELEASE_SPEED = 1.0


@dataclass
class ControlParams:
    """The controller; every field is a node parameter (skeleton_core.params)."""

    recognizer: RecognizerParams = nested(RecognizerParams)
    free_gain: float = param(1500.0, 'N/m (N/rad): gain of effectors without a contact',
                             range=(10.0, 1e5), public=False)
    release_after: float = param(2.0, 's without imitation before hands on a feature with an '
                                 'example let go (the character falls when the user stops; '
                                 'longer than a hand the sensor reports TRACKED at a wrong place, '
                                 'up to 1.5 s, plus the errors\' smoothing; 0 = never)',
                                 range=(0.0, 60.0), public=False)
    hand_release_margin: float = param(0.05, "m: a held hand lets go when the user's hand drops "
                                       "this far below the feature's engage joint",
                                       range=(0.0, 1.0), public=False)
    regrab_speed: float = param(0.5, 'm/s: on a feature with engage.regrab (the rope) a held hand '
                                'the user raises faster lets go to grab higher (hand over hand)',
                                range=(0.05, 10.0), public=False)
    regrab_reach: float = param(0.2, "body heights: climbing hand over hand, the free hand at the "
                                "top of its reach grabs the rope where it passes this close (an "
                                "arm's length: the arm reaches for the swinging rope; 0 = only "
                                "within the feature's engage distance)", range=(0.0, 1.0),
                                public=False)
    foot_down_height: float = param(0.06, "m: the user's foot this close to their floor is "
                                    'constrained (may hold the floor / trampoline)',
                                    range=(0.005, 0.5), public=False)
    blend_time: float = param(0.3, 's: transition in/out of the composed pose (Sec. 6.2)',
                              range=(0.01, 5.0))
    compose_components: int = param(6, 'pose PCA size m of Eq. 7', range=(1, 30), read_only=True,
                                    public=False)
    compose_k: int = param(4, 'nearest example frames in q_rep (Eq. 10)', range=(1, 50),
                           read_only=True, public=False)
    w_e: float = param(0.05, 'Eq. 8 weight of G_E (example similarity; w_P = 1)',
                       range=(0.0, 100.0), public=False)
    w_s: float = param(0.2, 'Eq. 8 weight of G_S (smoothness)', range=(0.0, 100.0), public=False)
    sensor_height: float = param(0.8, 'm above the floor (the same world as the physics node)',
                                 range=(0.0, 5.0), read_only=True)
    sensor_pitch: float = param(0.0, 'sensor tilt down (deg)', range=(-45.0, 45.0),
                                read_only=True, name='sensor_pitch_deg', degrees=True)
    body_mass: float = param(75.0, 'kg at 1.75 m (scaled with height^3)', range=(20.0, 300.0),
                             read_only=True)
    compute_penetration: bool = param(True, 'measure the deepest penetration of the body into '
                                      'the features every frame (diagnostics, the benchmark)',
                                      public=False)

    def validate(self) -> None:
        check(self, nested=False)
        self.recognizer.validate()
        for k in ('free_gain', 'blend_time', 'body_mass', 'foot_down_height'):
            if not getattr(self, k) > 0:
                raise ValueError(f'{k} must be positive')
        if self.release_after < 0:
            raise ValueError('release_after must be >= 0')
        if not 1 <= self.compose_components <= 30 or not 1 <= self.compose_k <= 50:
            raise ValueError('compose_components in [1, 30], compose_k in [1, 50]')


def build_models(world: World, params: RecognizerParams) -> Dict[str, ExampleModel]:
    """The PCA model of every feature's example motion."""
    return {f.name: ExampleModel(f.name, example_motion(f.example, fps=params.fps),
                                 f.example.effectors, f.example.components, params,
                                 max_change_share=f.example.max_change_share,
                                 hang_joint=(f.engage.hand_above or 'Head') if f.kind == 'bars'
                                 else None,
                                 own_posture=(float(f.example.params.get('period', 1.5))
                                              if getattr(f.example, 'own_posture', False)
                                              else 0.0))
            for f in world.with_example()}


@dataclass
class ControlOutput:
    positions_world: np.ndarray      # (20, 3) the composed, integrated pose
    positions_sensor: np.ndarray     # (20, 3) the same in the sensor frame
    feature: str                     # engaged feature (or the imitated one), '' = none
    recognition: Optional[Recognition]
    imitating: bool
    contacts: Dict[str, str]         # effector -> feature
    contact_points: Dict[str, np.ndarray]
    com: np.ndarray
    penetration: float
    compute_ms: float                # wall time of the step
    cpu_ms: float                    # CPU time of the step (this thread: robust to the load)
    blend: float


def _rotz(yaw: float) -> np.ndarray:
    return yaw_rotation(-yaw)   # body -> world


class PerformanceController:
    """Per user (see module docstring)."""

    def __init__(self, world: World, params: Optional[ControlParams] = None,
                 models: Optional[Dict[str, ExampleModel]] = None, start: str = ''):
        self.world = world
        self.params = params or ControlParams()
        self.params.validate()
        if start and start not in world.features:
            raise ValueError(f'start feature {start!r} is not in world {world.name} '
                             f'({sorted(world.features)})')
        self.start = start
        self.models = models if models is not None else build_models(world, self.params.recognizer)
        self.recognizer = IntentionRecognizer(list(self.models.values()), self.params.recognizer)
        self.composers = {n: PoseComposer(m, self.params.compose_components, self.params.compose_k,
                                          1.0, self.params.w_e, self.params.w_s)
                          for n, m in self.models.items()}
        self.sensor = SensorPose(self.params.sensor_height, self.params.sensor_pitch)
        self.dp: Optional[DynamicProcess] = None
        self.height = 1.75
        self.user_floor = 0.0
        self.yaw0 = 0.0
        self.t_last: Optional[float] = None
        self.last_imitation: Dict[str, float] = {}
        self.blend = 0.0
        self.blend_feature = ''
        self.obstacles = Obstacles()
        self._plan = None      # the features' geometry for the obstacles (_obstacle_plan)
        self.frames = 0
        self._stand_z = 1.0
        self._hand_z: Dict[str, float] = {}
        # walking on the floor (Sec. 8.3): the floor's example is a walk cycle
        self.floor_walk = next((f.name for f in world.features.values()
                                if f.kind == 'floor' and f.name in self.models), '')
        self.walker = (Walker(*example_gait(self.models[self.floor_walk].positions,
                                            self.params.recognizer.fps))
                       if self.floor_walk else None)
        self.walking = False
        self._was_walking = False
        self._walk_z = 1.0
        self._walk_seen = -math.inf
        self._hand_vz: Dict[str, float] = {e: 0.0 for e in EFFECTORS}

    # ------------------------------------------------------------------ set-up
    def _offsets(self, rel_world: np.ndarray) -> Dict[str, np.ndarray]:
        return {e: rel_world[JOINT_INDEX[e]] for e in EFFECTORS}

    def _start_com(self, rel_world: np.ndarray) -> np.ndarray:
        """Where the COM starts: the world's spawn on the floor, or the start feature's pose."""
        feet_z = min(rel_world[FOOT_LEFT, 2], rel_world[FOOT_RIGHT, 2])
        stand = np.array([*self.world.spawn, -feet_z + 0.04])
        if not self.start:
            return stand
        f = self.world.features[self.start]
        st = f.start or {}
        kind = f.kind
        if kind == 'bars':
            xy = np.asarray(st.get('com_xy', self.world.spawn), float)
            caps = [g for g in f.geoms if g.type == 'capsule']
            bar = min(caps, key=lambda g: np.linalg.norm(
                0.5 * (g.vec('from') + g.vec('to'))[:2] - xy))
            mid = 0.5 * (bar.vec('from') + bar.vec('to'))
            hands = 0.5 * (rel_world[JOINT_INDEX['HandLeft']] + rel_world[JOINT_INDEX['HandRight']])
            return np.array([mid[0], mid[1], mid[2]]) - np.array([hands[0], hands[1], hands[2]])
        if kind == 'rope':
            g = next(g for g in f.geoms if g.type == 'rope')
            top = g.vec('top')
            z = float(st.get('height', top[2] - 2.0))
            hands = 0.5 * (rel_world[JOINT_INDEX['HandLeft']] + rel_world[JOINT_INDEX['HandRight']])
            return np.array([top[0] - hands[0], top[1] - hands[1], z - hands[2]])
        if kind == 'water':
            g = next(g for g in f.geoms if g.type == 'volume')
            c = g.vec('center')
            xy = np.asarray(st.get('com_xy', c[:2]), float)
            return np.array([xy[0], xy[1], float(st.get('com_z', c[2]))])
        if kind == 'rocks':       # standing on the floor in front of the wall
            xy = np.asarray(st.get('com_xy', self.world.spawn), float)
            return np.array([xy[0], xy[1], stand[2]])
        if kind == 'trampoline':
            g = next(g for g in f.geoms if g.type == 'box')
            c, hf = g.vec('center'), g.vec('half')
            return np.array([c[0], c[1], c[2] + hf[2] - feet_z + 0.04])
        return stand

    def _init(self, p: np.ndarray) -> None:
        h = estimate_height(p)
        self.height = float(np.clip(h, 1.0, 2.3)) if np.isfinite(h) else 1.75
        self.recognizer.height = self.height
        self.user_floor = float(min(p[FOOT_LEFT, 2], p[FOOT_RIGHT, 2]))
        self.yaw0 = float(facing_yaw(p))
        rel = self._char_rel(p)
        mass = self.params.body_mass * (self.height / 1.75) ** 3
        com = self._start_com(rel)
        feet_z = min(rel[FOOT_LEFT, 2], rel[FOOT_RIGHT, 2])
        self._stand_z = float(-feet_z + 0.04)     # the COM's height standing on the floor
        self.dp = DynamicProcess(self.world, mass, com, self._offsets(rel), self.params.free_gain)
        self._plan = None
        if self.start:
            f = self.world.features[self.start]
            for e in f.engage.effectors:
                dist, body, pt = self.dp.feature_distance(e, f)
                if body is not None and dist < 3 * f.engage.distance:
                    self.dp.move_effector(e, pt)     # already holding: no jump at the start
                    self.dp.engage(e, f, body, pt)
        self._refresh_obstacles()

    def _char_rel(self, p: np.ndarray) -> np.ndarray:
        """The user's joints relative to their COM, turned by the character's yaw offset
        (world axes of the character)."""
        rel = p - center_of_mass(p)
        return rel @ _rotz(-self.yaw0).T

    # ------------------------------------------------------------------ obstacles
    def _obstacle_plan(self):
        """(floor feature or None, [(kind, data)]): the features' solid geometry in the world
        file's order, read once -- static capsules and boxes as arrays, the moving rope segments
        and the trampoline by their MuJoCo body ids (:meth:`_refresh_obstacles` reads their pose
        every frame)."""
        import mujoco
        floor, plan = None, []
        m = self.dp.model
        for f in self.world.features.values():
            for i, g in enumerate(f.geoms):
                n = f'f_{f.name}_{i}'
                if g.type == 'plane':
                    floor = f.name
                elif g.type == 'capsule':
                    plan.append(('capsule', (g.vec('from'), g.vec('to'), g.num('radius'), f.name)))
                elif g.type == 'box':
                    if 'stiffness' in g.data:
                        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n)
                        plan.append(('moving box', (b, g.vec('half'), f.name)))
                    else:
                        plan.append(('box', (g.vec('center'), g.vec('half'), f.name)))
                elif g.type == 'rope':
                    seg, r = g.num('length'), g.num('radius')
                    for s in range(int(g.data['segments'])):
                        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f'{n}_seg{s}')
                        plan.append(('segment', (b, np.array([0.0, 0.0, -seg]), r, f.name)))
        return floor, plan

    def _refresh_obstacles(self) -> None:
        if self._plan is None:
            self._plan = self._obstacle_plan()
        floor, plan = self._plan
        ob = Obstacles()
        ob.floor = floor
        d = self.dp.data
        for kind, x in plan:
            if kind == 'capsule':
                ob.capsules.append(x)
            elif kind == 'segment':
                b, down, r, name = x
                a0 = d.xpos[b].copy()
                ob.capsules.append((a0, a0 + d.xmat[b].reshape(3, 3) @ down, r, name))
            elif kind == 'box':
                ob.boxes.append(x)
            else:
                ob.boxes.append((d.xpos[x[0]].copy(), x[1], x[2]))
        self.obstacles = ob.freeze()

    # ------------------------------------------------------------------ rules
    def _user_hand_raised(self, p: np.ndarray, e: str, f: Feature, margin: float = 0.0) -> bool:
        if f.engage.hand_above is None:
            return True
        return bool(p[JOINT_INDEX[e], 2] > p[JOINT_INDEX[f.engage.hand_above], 2] - margin)

    def _user_foot_down(self, p: np.ndarray, e: str) -> bool:
        return bool(p[JOINT_INDEX[e], 2] - self.user_floor < self.params.foot_down_height)

    def _track_hands(self, p: np.ndarray, dt: float) -> None:
        """Smoothed vertical speed (0.1 s) of the user's hands and feet relative to their COM."""
        com_z = float(center_of_mass(p)[2])
        g = 1.0 - math.exp(-dt / 0.1)
        for e in EFFECTORS:
            z = float(p[JOINT_INDEX[e], 2]) - com_z
            if e in self._hand_z:
                self._hand_vz[e] += g * ((z - self._hand_z[e]) / dt - self._hand_vz[e])
            self._hand_z[e] = z

    def _above_other(self, e: str) -> bool:
        """The hand ``e`` holds the rope above the other hand (nearer the top)."""
        a = self.dp.rope_arc(e)
        b = self.dp.rope_arc(HANDS[1 - HANDS.index(e)])
        return a is not None and b is not None and a < b

    def _climbing_rope(self) -> bool:
        """A hand holds the rope: the character hangs from it, its feet off the ground (the
        user imitates the climb standing: their feet on their floor do not stand the character
        on it; with both hands needed, each regrab -- one hand free -- put the feet back on the
        floor and the character never rose more than 0.3 m)."""
        return any(c is not None and self.world.features[c.feature].kind == 'rope'
                   for c in (self.dp.contacts.get(h) for h in HANDS))

    def _jump_catch(self, e: str, f: Feature, pt) -> bool:
        """Reach/jump to engage: under the bars, the user's feet leave their floor
        with both hands above the bars' engage joint (a jump, or a real hang: :mod:`.support`);
        the character's hand catches a bar within :data:`JUMP_LEAP` horizontally and at most
        :data:`JUMP_REACH` above it."""
        if f.kind != 'bars' or pt is None or self.dp.in_water:
            return False
        if not self.recognizer.support.reaching(f.engage.hand_above or 'Head'):
            return False
        h = self.dp.effectors()[EFFECTORS.index(e)]
        return bool(np.linalg.norm(pt[:2] - h[:2]) < max(f.engage.distance, JUMP_LEAP)
                    and 0.0 < pt[2] - h[2] < JUMP_REACH)

    def _update_contacts(self, p: np.ndarray, recs: Dict[str, Recognition], t: float) -> None:
        dp, prm = self.dp, self.params
        vel = dp.effector_velocities()
        # both held hands lowered together: the release on a feature the hands climb (the climb
        # pulls with one hand while the other holds still or reaches up)
        both_lowered = all(h in dp.contacts and self._hand_vz[h] < -RELEASE_SPEED for h in HANDS)
        for k, e in enumerate(EFFECTORS):
            c = dp.contacts.get(e)
            if c is not None:
                f = self.world.features[c.feature]
                if e in HANDS:
                    lost = (f.name in self.models and prm.release_after > 0
                            and t - max(self.last_imitation.get(f.name, c.since_wall),
                                        c.since_wall) > prm.release_after)
                    other = HANDS[1 - HANDS.index(e)]
                    # hand over hand: only the lower hand lets go to grab higher (the rope
                    # below the upper hand carries no load: hanging from it drops the body)
                    regrab = (f.engage.regrab and other in dp.contacts
                              and self._hand_vz[e] > prm.regrab_speed
                              and not self._above_other(e))
                    lowered = f.engage.hand_above is not None and (
                        both_lowered if f.engage.regrab else self._hand_vz[e] < -RELEASE_SPEED)
                    if lost or regrab or lowered or not self._user_hand_raised(
                            p, e, f, prm.hand_release_margin):
                        dp.release(e)
                elif f.kind == 'rocks':
                    # a foot on a rock (Sec. 8.4) lets go when the user lifts it to step higher
                    if self._hand_vz[e] > prm.regrab_speed:
                        dp.release(e)
                elif (not self._user_foot_down(p, e) or (f.kind == 'floor' and dp.in_water)
                      or (f.kind == 'floor' and self._climbing_rope())):
                    dp.release(e)     # in the water the floor is the pool's bottom: a foot
                    # that stood on it as the character walked in lets go (it swims); on the
                    # rope the character hangs from its hands (it climbs from the floor)
                continue
            for f in self.world.features.values():
                if e not in f.engage.effectors:
                    continue
                if e in HANDS and not self._user_hand_raised(p, e, f):
                    continue
                if e in HANDS and f.engage.regrab and self._hand_vz[e] > 0.1:
                    continue      # climbing: grab at the top of the reach, not on the way up
                held = dp.contacts.get(HANDS[1 - HANDS.index(e)]) if e in HANDS else None
                if (held is not None and held.feature != f.name
                        and self.world.features[held.feature].engage.regrab):
                    continue      # hand over hand: the free hand climbs the rope the other
                    # holds (the rope swinging back under the last bar hung a climbing
                    # character by one hand from the bar, seed 23 of the watched performance)
                if e in FEET and f.kind != 'rocks' and not self._user_foot_down(p, e):
                    continue      # on a rock the foot is held above its face, not on the floor
                if e in FEET and f.kind == 'floor' and (dp.in_water or self._climbing_rope()):
                    continue      # swimming: the user's feet on their floor do not stand the
                    # character on the pool's bottom (walked in, it would stay there); climbing
                    # the rope, not on the ground (the user imitates standing)
                # hand over hand: the other hand holds the rope, this one is at the top of its
                # reach -- it reaches for the rope where it is now (an arm's length), whatever
                # its speed (the rope and the body swing)
                climbing = (e in HANDS and f.engage.regrab
                            and HANDS[1 - HANDS.index(e)] in dp.contacts
                            and dp.contacts[HANDS[1 - HANDS.index(e)]].feature == f.name)
                if not climbing and float(np.linalg.norm(vel[k])) > f.engage.max_speed:
                    continue
                # climbing, the free hand grabs above the held one (along the rope)
                above = dp.rope_arc(HANDS[1 - HANDS.index(e)]) if climbing else None
                dist, body, pt = dp.feature_distance(e, f, above)
                if e in HANDS and body is not None and self._jump_catch(e, f, pt):
                    dp.move_effector(e, pt)          # the character jumps and catches the bar
                    dp.engage(e, f, body, pt)
                    dp.contacts[e].since_wall = t
                    break
                reach = max(f.engage.distance, prm.regrab_reach * self.height) if climbing \
                    else f.engage.distance
                if body is not None and dist < reach:
                    if dist > f.engage.distance:
                        dp.move_effector(e, pt)      # the hand reaches the rope
                    dp.engage(e, f, body, pt)
                    dp.contacts[e].since_wall = t
                    break

    # ------------------------------------------------------------------ step
    def step(self, positions_sensor: np.ndarray, t: float,
             tracking_state: Optional[np.ndarray] = None) -> ControlOutput:
        """One sensor frame (20, 3) at time ``t`` (s); ``tracking_state`` (20,) the sensor's
        per-joint states (None: all TRACKED), used by the recognizer for occluded effectors."""
        t_start = time.perf_counter()
        c_start = time.thread_time()
        p = self.sensor.to_world(np.asarray(positions_sensor, float))
        if p.shape != (20, 3) or not np.all(np.isfinite(p)):
            raise ValueError('positions must be 20 x 3 finite numbers')
        if self.dp is None:
            self._init(p)
            for c in self.dp.contacts.values():
                c.since_wall = t
        dt = 1.0 / 30.0 if self.t_last is None else min(max(t - self.t_last, 1.0 / 240), 0.1)
        self.t_last = t
        self.frames += 1
        recs = self.recognizer.update(p, t, tracking_state)
        self._track_hands(p, dt)
        for n, r in recs.items():
            if r.imitating:
                self.last_imitation[n] = t
        dp = self.dp
        # ---- feature identification: engage / release by rule (Sec. 4, 5)
        self._update_contacts(p, recs, t)
        held = {e: c.feature for e, c in dp.contacts.items()}
        water = dp.in_water or next((f.name for f in self.world.features.values()
                                     if f.engage.com_inside and dp.com_inside(f)), None)
        feature = next((held[e] for e in HANDS if e in held), '') or (water or '')
        # ---- kinematic composition (Sec. 6.2)
        user_yaw = float(facing_yaw(p))
        char_yaw = user_yaw - self.yaw0
        # ---- walking on the floor (Sec. 8.3): the user walks in place, the character walks
        self.walking = False
        if self.walker is not None:
            self.walker.update(p, user_yaw, t)
            rw = recs.get(self.floor_walk)
            if rw is not None and rw.imitating:
                self._walk_seen = t
            on_floor = all(self.world.features[c.feature].kind == 'floor'
                           for c in dp.contacts.values())   # not on a rock, the trampoline
            self.walking = bool(not feature and on_floor and t - self._walk_seen <= WALK_HOLD
                                and dp.com[2] < self._stand_z + 0.3)
            if self.walking:
                if not self._was_walking:
                    self._walk_z = float(dp.com[2])    # the height it walks at
                feature = self.floor_walk
                dp.shift(np.zeros(3))      # the feet let go of the floor (carried below)
            self._was_walking = self.walking
        body_rel = (p - center_of_mass(p)) @ yaw_rotation(user_yaw).T   # body frame
        rec = recs.get(feature)
        compose = feature in self.composers and rec is not None and rec.imitating
        target_blend = 1.0 if compose else 0.0
        if compose:
            self.blend_feature = feature
        step_b = dt / self.params.blend_time
        if self.blend < target_blend:
            self.blend = min(target_blend, self.blend + step_b)
        else:
            self.blend = max(target_blend, self.blend - step_b)
        q = body_rel
        bf = self.blend_feature
        if self.blend > 0 and bf in self.composers:
            r_bf = recs[bf]
            m = self.models[bf]
            comp = self.composers[bf].compose({j: body_rel[j] for j in m.effectors}, r_bf.w,
                                              self.height)
            replace = (list(FEET) if self.walking and bf == self.floor_walk else
                       [e for e in FEET if self._user_foot_down(p, e) and e not in held])
            mixed = integrate_rule(body_rel, comp, replace)
            q = (1.0 - self.blend) * body_rel + self.blend * mixed
        if water:
            pitch = math.radians(self.world.features[water].dynamics.get('body_pitch_deg', 0.0))
            c, s = math.cos(pitch), math.sin(pitch)
            q = q @ np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]).T
        q = q - center_of_mass(q)
        q_world_rel = q @ _rotz(char_yaw).T
        # ---- dynamic process (Sec. 5)
        dp.set_targets(np.array([q_world_rel[JOINT_INDEX[e]] for e in EFFECTORS]), char_yaw, dt)
        walk_from = dp.com
        dp.step(dt)
        if self.walking:
            v = self.walker.velocity(char_yaw)
            dp.carry_to(np.array([*(walk_from[:2] + v[:2] * dt), self._walk_z]), v)
        # ---- motion integration (Sec. 7)
        self._refresh_obstacles()
        eff = dp.effectors()
        contacts = {e: eff[EFFECTORS.index(e)] for e in dp.contacts}
        held = {e: c.feature for e, c in dp.contacts.items()}
        # the features near enough to touch: the constraints and the metric test only these
        near = self.obstacles.near(dp.com, NEAR * self.height)
        out_w = integrate_motion(q_world_rel, dp.com, contacts, near, held, self.height)
        pen = (near.penetration(out_w, self.height, held)
               if self.params.compute_penetration else float('nan'))
        ms = (time.perf_counter() - t_start) * 1e3
        cpu = (time.thread_time() - c_start) * 1e3
        shown = rec if rec is not None else self.recognizer.best(recs)
        return ControlOutput(
            positions_world=out_w, positions_sensor=self.sensor.to_sensor(out_w),
            feature=feature or (shown.feature if shown is not None and shown.imitating else ''),
            recognition=shown, imitating=bool(shown is not None and shown.imitating),
            contacts=held, contact_points=contacts, com=dp.com, penetration=pen, compute_ms=ms,
            cpu_ms=cpu, blend=self.blend)


__all__ = ['PerformanceController', 'ControlParams', 'ControlOutput', 'build_models']
