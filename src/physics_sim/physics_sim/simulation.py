"""The physics world: characters PD-tracking their users' target postures (Shum & Ho 2012, Sec. 4,
6, 8; Shum et al. 2013, Sec. VII) in MuJoCo, with virtual joints, objects, pushes and dodging.

Library API (no ROS)::

    sim = Simulation(SimConfig())
    states = sim.step({user_id: positions_20x3}, duration=1/30)   # -> {user_id: CharacterState}
    sim.apply_push(user_id, 'Spine', (200, 0, 0), 0.1)
    sim.throw_ball(position, velocity, radius=0.1, mass=0.5)

Targets arrive in the *sensor* frame and are moved to the world (floor at z = 0) with
:class:`~physics_sim.frames.SensorPose`; every state is reported in both frames. Bad targets (NaN,
wrong shape) raise ``ValueError`` before anything in the simulation changes.

Where things are: this module keeps the characters, turns input into targets and steps the worlds;
:mod:`~physics_sim.world` is one MuJoCo model (a group of characters that may touch each other)
with its bookkeeping (indices, targets, Eq. 2, health, holds, states); :mod:`~physics_sim.pins` the
foot pins; :mod:`~physics_sim.controllers` the controllers (one class per file, registered by
name) and :mod:`~physics_sim.controller` Eq. 1-2 themselves; :mod:`~physics_sim.mjcf_world` /
:mod:`~physics_sim.mjcf_body` build the MJCF; :mod:`~physics_sim.config` the settings.

Worlds (``SimConfig.world_split``): with ``contact``, characters that cannot touch each other are
simulated in separate MuJoCo models, stepped one after the other over the same time steps (a model's
cost for ``actuator_pd`` grows with the square of its characters: every site actuator takes a
Jacobian over all degrees of freedom of its model). Two characters share a model while their
horizontal boxes (joint points and newest target, widened by ``contact_margin`` on every side)
overlap; they part once they have been apart by twice that for ``PART_AFTER`` (recompiling the
models involved, keeping every body's state; a group's compiled model is reused when it meets
again). While there are objects, every character shares one model with them. The default is
``shared`` (one model): with ``explicit_pd``'s compiled Eq. 1, ``auto``'s choice from 3
characters, one model of 6 characters steps faster than 6 models (``bench_physics --rtf-only``).

Controllers (``SimConfig.controller``; :mod:`physics_sim.controllers`): ``explicit_pd`` (the
papers' scheme, Eq. 1 at every step in compiled code), ``actuator_pd`` (Eq. 1-2 as MuJoCo
actuators), ``mocap_constraints`` (soft connects to mocap targets) and ``auto`` (per model:
``actuator_pd`` below ``auto_explicit_from`` (3) characters, ``explicit_pd`` from there on).
"""
from __future__ import annotations

from typing import Dict, List, Mapping, Optional, Sequence

import numpy as np
from skeleton_core.conversions import MAX_ABS_COORDINATE, validate_arrays
from skeleton_core.geometry import quat_rotate, retarget, retarget_by_joint
from skeleton_core.memory import release_freed_memory
from skeleton_core.tf import Transform
from skeleton_core.model import (FOOT_LEFT, FOOT_RIGHT, HAND_LEFT, HAND_RIGHT, HEAD, JOINT_INDEX,
                                 JOINT_NAMES, NUM_JOINTS, SEGMENT_CHILD_INDEX, SEGMENT_OF_JOINT,
                                 SEGMENTS, Body, estimate_height, standard_body)

from .character import Character, Target
from .config import INTEGRATORS, SOLVERS, CharacterState, SimConfig, controllers
from .controller import Gains
from .feature_geometry import load_geometry
from .feature_holds import engaged_hands
from .frames import DEFAULT_SENSOR_POSE, SensorPose
from .mjcf_world import ObjectSpec
from .posture import is_identity, joint_quats_to_segment, segment_quats_to_joints
from .world import Shared, World, controller_for
from skeleton_core.model import SEGMENT_NAMES
import time


class Simulation:
    """The characters (one per user) and objects, in one or more MuJoCo worlds."""

    PART_AFTER = 1.0   # s apart before two characters sharing a world are split up
    # compiled worlds kept for groups that may meet again (each a MuJoCo model and data, ~1-3 MB
    # resident); a world holding a character that left is dropped at once (never reusable)
    CACHE_SIZE = 16

    def __init__(self, config: Optional[SimConfig] = None, objects: Sequence[ObjectSpec] = (),
                 sensor_pose: Optional[Transform] = None):
        self.config = config or SimConfig()
        self.config.validate()
        # the sensor's pose in the world (TF world -> sensor frame; the node looks it up)
        self.sensor_pose: Transform = DEFAULT_SENSOR_POSE if sensor_pose is None else sensor_pose
        self.characters: Dict[int, Character] = {}
        self.shared = Shared(self.config,
                             {'constraint_conflict': 0, 'virtual_joint_released': 0,
                              'nan_reset': 0, 'refused_target': 0, 'rebuilds': 0, 'pins': 0,
                              'regroups': 0, 'reused_models': 0, 'grips': 0},
                             list(objects))
        if self.config.feature_world:
            self.shared.features = load_geometry(self.config.feature_world)
        self.engaged: Dict[int, Dict[int, str]] = {}   # uid -> {hand: feature} (set_engaged)
        self.counters = self.shared.counters
        self._ball_count = 0
        self.time = 0.0
        self.worlds: List[World] = [World(self.shared, [], True, self.time)]
        self._world_of: Dict[int, World] = {}
        # compiled worlds of groups that were split up or merged, by their user ids: characters
        # that keep meeting and parting reuse them instead of recompiling
        self._cache: Dict[tuple, World] = {}
        self._apart: Dict[tuple, float] = {}   # merged pair -> sim time since they are apart

    # ------------------------------------------------------------------ shared state
    @property
    def objects(self) -> List[ObjectSpec]:
        return self.shared.objects

    @property
    def holds(self) -> Dict[str, tuple]:
        return self.shared.holds

    @property
    def pushes(self) -> List[tuple]:
        return self.shared.pushes

    @property
    def sensor(self) -> Optional[SensorPose]:
        return self.shared.sensor

    @sensor.setter
    def sensor(self, value: Optional[SensorPose]) -> None:
        self.shared.sensor = value

    # ------------------------------------------------------------------ worlds
    def world_of(self, user_id: int) -> World:
        """The world simulating user ``user_id``'s character."""
        return self._world_of[int(user_id)]

    @property
    def world(self) -> World:
        """The only world (the objects' world when there is no character): an error when the
        characters are split over several."""
        if len(self.worlds) != 1:
            raise RuntimeError(f'{len(self.worlds)} worlds: use world_of(user_id)')
        return self.worlds[0]

    @property
    def model(self):
        return self.world.model

    @property
    def data(self):
        return self.world.data

    @property
    def controller(self) -> str:
        """The controller of the largest world (``config.controller`` unless it is ``'auto'``)."""
        return max(self.worlds, key=lambda w: len(w.chars)).controller_name

    def _object_world(self) -> World:
        return next(w for w in self.worlds if w.with_objects)

    def _set_worlds(self, groups: List[List[int]], rebuild_objects: bool = False) -> None:
        """One world per group of ``groups`` (user ids): a world whose characters are exactly a
        group is kept, a cached one of the same characters is taken back, every other one is
        compiled anew; all from the characters' current state. The objects live in the first
        world (all characters while there are objects); ``rebuild_objects``: they changed,
        recompile that world even when it is kept."""
        old = list(self.worlds)
        new = []
        for k, g in enumerate([sorted(g) for g in groups] or [[]]):
            w = next((w for w in old if sorted(w.user_ids()) == g and w not in new), None)
            if w is None:
                w = self._cached(g, with_objects=k == 0)
                if w is not None:
                    w.time = self.time
                    w.rebuild(old, recompile=False)
            if w is None:
                w = World(self.shared, [self.characters[u] for u in g], k == 0, self.time,
                          old=old)
            elif w.with_objects != (k == 0) or (k == 0 and rebuild_objects):
                w.with_objects = k == 0
                w.rebuild()
            new.append(w)
        closed = 0
        for w in old:
            if w in new:
                continue
            if w.chars and not self.objects:
                replaced = self._cache.pop(tuple(sorted(w.user_ids())), None)
                if replaced is not None and replaced is not w:
                    replaced.close()
                    closed += 1
                self._cache[tuple(sorted(w.user_ids()))] = w
            else:
                w.close()
                closed += 1
        while len(self._cache) > self.CACHE_SIZE:
            self._cache.pop(next(iter(self._cache))).close()
            closed += 1
        if closed:   # the freed models' pages back to the OS, not kept in the heap's arenas
            release_freed_memory()
        self.worlds = new
        self._world_of = {u: w for w in new for u in w.user_ids()}

    def _cached(self, uids: List[int], with_objects: bool) -> Optional[World]:
        """The cached world of exactly these characters (the same Character objects), if any."""
        w = self._cache.pop(tuple(uids), None)
        if w is None:
            return None
        if self.objects or any(self.characters.get(ch.user_id) is not ch for ch in w.chars):
            w.close()
            return None
        w.with_objects = with_objects
        return w

    def _rebuild(self, objects: bool = False) -> None:
        """Recompile after a character (or, ``objects``, an object) came or went."""
        self._set_worlds(self._groups(), rebuild_objects=objects)

    def _groups(self, bounds: Optional[Dict[int, np.ndarray]] = None) -> List[List[int]]:
        """The characters grouped into worlds: connected components of "boxes within reach"."""
        uids = list(self.characters)
        c = self.config
        if c.world_split == 'shared' or self.objects or len(uids) <= 1:
            return [uids]
        if bounds is None:
            bounds = self._bounds()
        parent = {u: u for u in uids}

        def root(u):
            while parent[u] != u:
                u = parent[u]
            return u

        # horizontal gap between every pair of boxes (negative: overlapping), all at once
        B = np.array([bounds[u] for u in uids])                   # (N, 2 min/max, 2 xy)
        gaps = np.maximum(B[:, None, 0] - B[None, :, 1], B[None, :, 0] - B[:, None, 1]).max(-1)
        gaps = gaps.tolist()
        merge, part = 2.0 * c.contact_margin, 4.0 * c.contact_margin
        for a in range(len(uids)):
            for b in range(a + 1, len(uids)):
                ua, ub = uids[a], uids[b]
                gap = gaps[a][b]
                together = (ua in self._world_of and self._world_of.get(ua) is
                            self._world_of.get(ub))
                # widened boxes overlap: merge; a merged pair parts once it has been apart by
                # twice the margin for PART_AFTER seconds
                if together:
                    if gap < part:
                        self._apart.pop((ua, ub), None)
                    else:
                        since = self._apart.setdefault((ua, ub), self.time)
                        together = self.time - since < self.PART_AFTER
                if together or gap < merge:
                    parent[root(ua)] = root(ub)
        comps: Dict[int, List[int]] = {}
        for u in uids:
            comps.setdefault(root(u), []).append(u)
        return sorted(comps.values(), key=lambda g: min(g))

    def _bounds(self) -> Dict[int, np.ndarray]:
        out = {}
        for w in self.worlds:
            for ch, b in zip(w.chars, w.bounds()):
                out[ch.user_id] = b
        for uid, ch in self.characters.items():
            if uid not in out:   # not simulated yet: its target
                p = ch.cur.positions[:, :2]
                out[uid] = np.stack([p.min(axis=0), p.max(axis=0)])
        return out

    def _regroup(self) -> None:
        """After an advance: merge the worlds of characters coming within reach, part those that
        moved apart."""
        if len(self.characters) <= 1 or self.config.world_split == 'shared' or self.objects:
            return
        groups = self._groups()
        current = sorted(sorted(w.user_ids()) for w in self.worlds if w.chars)
        if sorted(sorted(g) for g in groups) != current:
            self.counters['regroups'] += 1
            self._set_worlds(groups)
        if len(self._apart) > 64:   # pairs no longer sharing a world
            self._apart = {k: v for k, v in self._apart.items()
                           if self._world_of.get(k[0]) is self._world_of.get(k[1])}

    # ------------------------------------------------------------------ targets
    def set_sensor_pose(self, transform: Transform) -> None:
        """Move the sensor (world <- sensor, e.g. a new TF transform): later targets and states
        use it; the floor lift stays."""
        if transform is self.sensor_pose:
            return
        self.sensor_pose = transform
        if self.sensor is not None:
            self.sensor = SensorPose.from_transform(transform, self.sensor.lift)

    def _sensor_pose(self, first_world_positions: Optional[np.ndarray] = None) -> SensorPose:
        if self.sensor is None:
            c = self.config
            pose = self.sensor_pose
            if c.auto_floor and first_world_positions is not None:
                lifted = SensorPose.from_transform(pose).to_world(first_world_positions)
                low = float(min(lifted[FOOT_LEFT, 2], lifted[FOOT_RIGHT, 2]))
                pose = Transform(pose.translation - np.array([0.0, 0.0, low]), pose.rotation)
            lift = 0.0
            if c.lift_feet:
                lift = float(standard_body(max(self._body_height_for(first_world_positions), 0.6))
                             .segment_radii[SEGMENT_OF_JOINT[FOOT_LEFT]])
            self.sensor = SensorPose.from_transform(pose, lift)
        return self.sensor

    def _body_height_for(self, positions: Optional[np.ndarray]) -> float:
        if self.config.body_height > 0:
            return self.config.body_height
        if positions is None:
            return 1.75
        h = estimate_height(positions)
        return float(np.clip(h, 1.0, 2.3)) if np.isfinite(h) else 1.75

    def make_target(self, user_id: int, positions, orientations=None, stamp_ns: int = 0) -> Target:
        """Validate a sensor-frame target and express it in the world (retargeted if configured).
        Raises ``ValueError`` for NaN / wrong shapes; nothing in the simulation changes then."""
        try:
            p, _, _, q = validate_arrays(positions, orientations=orientations)
        except ValueError:
            self.counters['refused_target'] += 1
            raise
        return self._make_target(user_id, p, q, stamp_ns)

    def _make_target(self, user_id: int, p: np.ndarray, q, stamp_ns: int = 0) -> Target:
        """:meth:`make_target` of arrays that ``validate_arrays`` has already returned."""
        sensor = self._sensor_pose(p)
        pw = sensor.to_world(p)
        ch = self.characters.get(int(user_id))
        body = ch.body if ch is not None else self._new_body(pw)
        if self.config.retarget:
            if ch is not None:   # the character's Eq. 3-4 lengths and fallback directions, cached
                pw = retarget_by_joint(pw, ch.retarget_bone, ch.retarget_dirs)
            else:
                pw = retarget(pw, body)
        if is_identity(q):
            sq = Character.default_seg_quats(pw, body)
        else:
            sq = joint_quats_to_segment(sensor.quat_to_world(q))
        return Target(pw, sq, self.time, int(stamp_ns))

    def _new_body(self, world_positions: np.ndarray) -> Body:
        h = self._body_height_for(world_positions)
        return standard_body(h, self.config.body_mass * (h / 1.75) ** 3)

    def set_target(self, user_id: int, positions, orientations=None, stamp_ns: int = 0) -> None:
        """Give user ``user_id`` a new target (sensor frame). A new user spawns a character in
        the target posture."""
        try:
            p, _, _, q = validate_arrays(positions, orientations=orientations)
        except ValueError:
            self.counters['refused_target'] += 1
            raise
        self._set_target(int(user_id), p, q, stamp_ns)

    def _set_target(self, uid: int, p: np.ndarray, q, stamp_ns: int = 0) -> None:
        """:meth:`set_target` of validated arrays."""
        target = self._make_target(uid, p, q, stamp_ns)
        ch = self.characters.get(uid)
        if ch is None:
            if len(self.characters) >= self.config.max_characters:
                raise ValueError(f'already {len(self.characters)} characters (max_characters)')
            used = {c.slot for c in self.characters.values()}
            slot = min(set(range(30)) - used)
            body = self._new_body(target.positions)
            ch = Character(uid, body, slot, target)
            self.characters[uid] = ch
            self._rebuild()
        else:
            ch.push_target(target, self.config.velocity_smoothing)

    def set_targets(self, targets: Sequence[tuple]) -> List[tuple]:
        """:meth:`set_target` of several users at once, ``(user_id, positions, orientations,
        stamp_ns)`` each, as a decoded message holds them (``skeleton_core.cdr`` validated the
        arrays). Users who have a character are moved to the world, retargeted and given their
        segment orientations together: the same bits as one by one (row-wise arithmetic;
        physics_sim/test/test_physics_input.py). A message with a new user, or arrays that are not
        valid, is taken one by one, in order. Returns ``(user_id, error)`` of the users refused
        (max_characters, an invalid array); the others' targets were taken."""
        items = list(targets)
        if not items:
            return []
        if not self.config.retarget or any(int(t[0]) not in self.characters for t in items):
            return self._one_by_one(items)   # a user arrives (rare): the world rebuilds
        given = [k for k, t in enumerate(items) if t[2] is not None and len(t[2]) > 0]
        try:
            p = np.array([t[1] for t in items], float)
            q = np.array([items[k][2] for k in given], float) if given else None
        except (TypeError, ValueError):   # arrays of different shapes
            return self._one_by_one(items)
        if p.shape != (len(items), NUM_JOINTS, 3) or not np.abs(p).max() <= MAX_ABS_COORDINATE:
            return self._one_by_one(items)
        if given:
            if q.shape != (len(given), NUM_JOINTS, 4):
                return self._one_by_one(items)
            n = np.sqrt(np.einsum('nij,nij->ni', q, q))
            if not (np.isfinite(n).all() and n.min() >= 1e-9):
                return self._one_by_one(items)
            q = q / n[..., None]   # as validate_arrays leaves them (normalized once more)
        chars = [self.characters[int(t[0])] for t in items]
        sensor = self._sensor_pose(p[0])
        pw = retarget_by_joint(sensor.to_world(p), np.array([ch.retarget_bone for ch in chars]),
                               np.array([ch.retarget_dirs for ch in chars]))
        seg_q = {}
        if given:
            ident = np.all(np.abs(np.abs(q[..., 3]) - 1.0) < 1e-9, axis=-1).tolist()
            qs = sensor.quat_to_world(q)[:, SEGMENT_CHILD_INDEX]
            seg_q = {k: qs[i] for i, k in enumerate(given) if not ident[i]}
        smoothing = self.config.velocity_smoothing
        for k, (t, ch) in enumerate(zip(items, chars)):
            sq = seg_q.get(k)
            if sq is None:
                sq = Character.default_seg_quats(pw[k], ch.body)
            ch.push_target(Target(pw[k], sq, self.time, int(t[3])), smoothing)
        return []

    def _one_by_one(self, items: List[tuple]) -> List[tuple]:
        refused = []
        for t in items:
            try:
                self.set_target(int(t[0]), t[1], t[2], t[3])
            except ValueError as e:
                refused.append((int(t[0]), e))
        return refused

    def remove_character(self, user_id: int) -> bool:
        if int(user_id) not in self.characters:
            return False
        del self.characters[int(user_id)]
        self.engaged.pop(int(user_id), None)
        self.shared.grips.pop(int(user_id), None)
        self.pushes[:] = [p for p in self.pushes if p[0] != int(user_id)]
        self._world_of.pop(int(user_id), None)
        self._apart = {k: v for k, v in self._apart.items() if int(user_id) not in k}
        self._rebuild()
        # cached worlds with this character can never be taken back (a user who returns is a
        # new Character): free them now instead of when 16 others have pushed them out
        gone = [k for k in self._cache if int(user_id) in k]
        for key in gone:
            self._cache.pop(key).close()
        if gone:
            release_freed_memory()
        return True

    # ------------------------------------------------------------------ objects
    def add_object(self, spec: ObjectSpec) -> None:
        if any(o.name == spec.name for o in self.objects):
            raise ValueError(f'object {spec.name!r} exists')
        self.objects.append(spec)
        self._rebuild(objects=True)
        w = self._object_world()
        oid = w.obj_id(spec.name)
        adr = w.model.jnt_dofadr[w.model.body_jntadr[oid]]
        w.data.qvel[adr:adr + 3] = spec.vel

    def remove_object(self, name: str) -> bool:
        n = len(self.objects)
        self.objects[:] = [o for o in self.objects if o.name != name]
        self.holds.pop(name, None)
        if len(self.objects) != n:
            self._rebuild(objects=True)
            return True
        return False

    def throw_ball(self, position, velocity, radius: float = 0.1, mass: float = 0.5,
                   name: Optional[str] = None) -> str:
        """Add a ball at ``position`` (world) flying at ``velocity`` (m/s); returns its name."""
        self._ball_count += 1
        name = name or f'thrown{self._ball_count}'
        self.add_object(ObjectSpec(name, 'ball', tuple(position), (radius,), mass, tuple(velocity),
                                   rgba=(0.9, 0.3, 0.2, 1.0)))
        return name

    def throw_at(self, user_id: int, joint: int = HEAD, speed: float = 6.0, distance: float = 3.0,
                 radius: float = 0.1, mass: float = 0.5) -> str:
        """Throw a ball at a character's joint from ``distance`` in front of it (gravity-corrected)."""
        ch = self.characters[int(user_id)]
        d = self.world_of(user_id).data
        aim = ch.joint_points(d)[joint]
        fwd = quat_rotate(ch.segment_quats(d)[0], np.array([1.0, 0.0, 0.0]))
        fwd[2] = 0.0
        fwd /= max(np.linalg.norm(fwd), 1e-9)
        start = aim + distance * fwd
        t = distance / speed
        vel = -fwd * speed + np.array([0.0, 0.0, 0.5 * 9.81 * t])
        return self.throw_ball(start, vel, radius, mass)

    def object_poses(self) -> Dict[str, tuple]:
        """name -> (position (3,), quaternion x y z w, spec), world frame."""
        out = {}
        if not self.objects:
            return out
        w = self._object_world()
        for o in self.objects:
            b = w.obj_id(o.name)
            q = w.data.xquat[b]
            out[o.name] = (w.data.xpos[b].copy(), np.array([q[1], q[2], q[3], q[0]]), o)
        return out

    def hold(self, user_id: int, object_name: str, hand: str = 'right') -> None:
        """Virtual joint (ball) between a character's hand and a holdable object (Sec. 6.1)."""
        if int(user_id) not in self.characters:
            raise ValueError(f'no character {user_id}')
        spec = next((o for o in self.objects if o.name == object_name), None)
        if spec is None or not spec.holdable:
            raise ValueError(f'{object_name!r} is not a holdable object')
        hand_j = HAND_RIGHT if hand == 'right' else HAND_LEFT
        self.holds[object_name] = (int(user_id), hand_j)
        self.world_of(user_id).hold(object_name, int(user_id), hand_j)

    def release(self, object_name: str) -> None:
        if object_name in self.holds:
            self._object_world().release(object_name)

    def obj_id(self, name: str) -> int:
        """Body id of an object in the objects' world (``self.world`` while there are objects)."""
        return self._object_world().obj_id(name)

    # ------------------------------------------------------------------ virtual joints
    def pin(self, user_id: int, joint: str, point=None) -> None:
        """Pin a foot joint ('FootLeft'/'FootRight') to a world point (default: where it is) with
        a virtual ball joint until :meth:`unpin`; it is not released when the target lifts."""
        ch = self.characters[int(user_id)]
        w = self.world_of(user_id)
        j = JOINT_INDEX.get(joint, -1)
        if j not in ch.pins:
            raise ValueError(f'only {[JOINT_NAMES[k] for k in ch.pins]} can be pinned')
        p = ch.joint_points(w.data)[j] if point is None else np.asarray(point, float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError('pin point must be 3 finite numbers')
        pin = ch.pins[j]
        pin.active, pin.manual, pin.point = True, True, p.copy()
        w.pins.set(ch, j, True, p)
        w.pack_targets()

    def unpin(self, user_id: int, joint: str) -> None:
        ch = self.characters[int(user_id)]
        w = self.world_of(user_id)
        j = JOINT_INDEX.get(joint, -1)
        if j in ch.pins:
            ch.pins[j].active = ch.pins[j].manual = False
            w.pins.set(ch, j, False)
            w.pack_targets()

    # ------------------------------------------------------------------ feature grips
    def set_engaged(self, user_id: int, effectors: Sequence[str] = (),
                    features: Sequence[str] = ()) -> None:
        """The control node's engaged effectors and their features for a user (parallel lists,
        as in ``skeleton_msgs/Intention``): its hands grip those features from the next step on
        and let go of the others (only with ``feature_world``)."""
        hands = engaged_hands(effectors, features)
        if hands:
            self.engaged[int(user_id)] = hands
        else:
            self.engaged.pop(int(user_id), None)

    @property
    def grips(self) -> Dict[int, Dict[int, tuple]]:
        """{uid: {hand joint: (feature, body, anchor in the body)}} of the gripping hands."""
        return self.shared.grips

    def grip_points(self, user_id: int) -> Dict[int, np.ndarray]:
        """{hand joint: world point} of a user's grips now (a rope's where it swung to)."""
        return self.world_of(user_id).grip_points(int(user_id))

    # ------------------------------------------------------------------ pushes
    def apply_push(self, user_id: int, segment, force, duration: float) -> None:
        """External force (N, world) on a segment's centre of mass for ``duration`` s. ``segment`` is
        the segment's child-joint name (e.g. 'Spine'), its SEGMENT_NAMES name, or an index."""
        uid = int(user_id)
        if uid not in self.characters:
            raise ValueError(f'no character {uid}')
        f = np.asarray(force, float)
        if f.shape != (3,) or not np.all(np.isfinite(f)):
            raise ValueError('force must be 3 finite numbers')
        if not (np.isfinite(duration) and 0.0 < duration <= 5.0):
            raise ValueError('duration must be in (0, 5] s')
        k = self.segment_index(segment)
        self.pushes.append((uid, k, f, self.time + float(duration)))

    @staticmethod
    def segment_index(segment) -> int:
        if isinstance(segment, (int, np.integer)):
            if 0 <= int(segment) < len(SEGMENTS):
                return int(segment)
        elif segment in JOINT_INDEX and SEGMENT_OF_JOINT[JOINT_INDEX[segment]] >= 0:
            return SEGMENT_OF_JOINT[JOINT_INDEX[segment]]
        elif segment in SEGMENT_NAMES:
            return SEGMENT_NAMES.index(segment)
        raise ValueError(f'unknown segment {segment!r} (use a child joint name such as "Spine")')

    # ------------------------------------------------------------------ stepping
    def step(self, targets=None, duration: Optional[float] = None) -> Dict[int, CharacterState]:
        """Set targets (``{user_id: positions}`` / ``{user_id: (positions, orientations)}`` or one
        (20, 3) array for user 0), advance by ``duration`` (default 1/30 s), return the states.
        All targets are validated before any is applied."""
        if targets is not None:
            if not isinstance(targets, Mapping):
                targets = {0: targets}
            prepared = []
            for uid, t in targets.items():
                if isinstance(t, tuple):
                    pos, ori = t
                else:
                    pos, ori = t, None
                try:  # SkeletonFormatError is a ValueError
                    p, _, _, q = validate_arrays(pos, orientations=ori)
                except ValueError:
                    self.counters['refused_target'] += 1
                    raise
                prepared.append((int(uid), p, q))
            for uid, p, q in prepared:
                self._set_target(uid, p, q)
        self.advance(1.0 / 30.0 if duration is None else duration)
        return self.states()

    def advance(self, duration: float) -> None:
        """Simulate ``duration`` seconds in fixed time steps, every world in turn."""
        n = max(1, int(round(duration / self.config.timestep)))
        for w in self.worlds:
            w.time = self.time
            if self.shared.features and (self.engaged or self.shared.grips):
                w.update_grips(self.engaged)
            w.advance(n)
        self.time = self.worlds[0].time
        if self.pushes:
            self.pushes[:] = [p for p in self.pushes if p[3] > self.time]
        self._regroup()

    def reset_to_targets(self) -> None:
        for w in self.worlds:
            w.reset_to_targets()

    # ------------------------------------------------------------------ state
    def _sensor_or_default(self) -> SensorPose:
        return self.sensor or SensorPose.from_transform(self.sensor_pose)

    def state(self, user_id: int) -> CharacterState:
        ch = self.characters[int(user_id)]
        d = self.world_of(user_id).data
        pts = ch.joint_points(d)
        q = segment_quats_to_joints(ch.segment_quats(d))
        sensor = self._sensor_or_default()
        return CharacterState(
            user_id=ch.user_id, positions=pts, orientations=q,
            positions_sensor=sensor.to_sensor(pts), orientations_sensor=sensor.quat_to_sensor(q),
            stamp_ns=ch.cur.stamp_ns,
            pinned={JOINT_NAMES[j]: p.active for j, p in ch.pins.items()},
            target_world=ch.cur.positions.copy())

    def states(self) -> Dict[int, CharacterState]:
        """:meth:`state` of every character, computed per world for all of its characters."""
        sensor = self._sensor_or_default()
        out = {}
        for w in self.worlds:
            out.update(w.states(sensor))
        return out


def warm_up() -> float:
    """Compile (or load from numba's cache) the compiled kernels -- explicit_pd's Eq. 1 and
    Eq. 2, the target orientations -- by stepping a throw-away one-character world once, so that
    a node does it at start and not on its first frame. Returns the seconds it took."""
    t0 = time.perf_counter()
    body = standard_body()
    sim = Simulation(SimConfig(controller='explicit_pd', body_height=body.height))
    sim.step({0: body.rest_positions() - np.array([0.0, 0.0, 0.8])})
    return time.perf_counter() - t0


CONTROLLERS = controllers()   # the built-in controllers and 'auto' (config.controllers() is live)

__all__ = ['Simulation', 'SimConfig', 'SensorPose', 'CharacterState', 'CONTROLLERS', 'SOLVERS',
           'INTEGRATORS', 'Gains', 'ObjectSpec', 'World', 'controller_for', 'warm_up']
