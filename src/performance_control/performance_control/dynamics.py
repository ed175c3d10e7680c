"""The dynamic process (Ishigaki et al. 2009, Sec. 5): the character's global motion from its
intentional contacts, gravity and the features' own dynamics, in MuJoCo.

Every effector j (hands, feet) is tied to the COM by the paper's intentional-contact actuator,
evaluated in the body's yaw frame (pitch axis = the body's lateral axis, roll axis = its forward
axis) with the user's relative movement r^_j = d^_j - x^ as the target:

    f_l = (ks (|r^| - |r|) + kd (|r^|' - |r|')) r / |r|          (Eq. 2, linear spring)
    f_a = (ka (a^ - a) + kad (a^' - a')) u                         (Eq. 3, pitch PD)
    f_b = (kb (b^ - b) + kbd (b^' - b')) v                         (Eq. 4, roll PD)

(a, b: the angles of r about the pitch and roll axes; u, v: the unit tangents of those rotations;
gains in N/m and N/rad). The sum acts on the effector and its opposite on the COM (Eq. 1): a free
effector just follows the user's hand, an engaged one -- held on the feature by a MuJoCo
``connect`` equality switched on at run time -- pulls the COM to where the user's relative movement
says, and its reaction goes into the feature (the rope swings, the trampoline compresses). Gains
are the engaged feature's dynamics D (e.g. kb = 0 on the bars: the sideways swing is passive);
free effectors use ``free_gain``.

Water: while the COM is inside a water volume, MuJoCo's fluid model is on (``opt.density``,
``opt.viscosity``: drag on the COM box and on the effectors' paddles, so strokes of the hands
relative to the COM propel the body) and a buoyancy force for the feature's ``body_density``
(the paper cancels gravity) acts on the COM.

The COM body only translates: the character's orientation follows the user's (the paper lets the
orientation be passive in free fall; we keep the user's, a simplification documented in
docs/research/2026-11-28-performance-control-development.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, Optional, Tuple

import mujoco
import numpy as np

from skeleton_core import jit as _jit

from .features import EFFECTORS, Feature, World
from .world_mjcf import EFFECTOR_RADIUS, world_model_xml

GAIN_KEYS = ('ks', 'kd', 'ka', 'kad', 'kb', 'kbd')


def _closest_on_segment(p, a, b):
    ab = b - a
    t = float(np.clip(np.dot(p - a, ab) / max(np.dot(ab, ab), 1e-12), 0.0, 1.0))
    return a + t * ab


@dataclass
class Contact:
    """An active intentional contact."""

    effector: str
    feature: str
    body: str
    eq: int
    since: float
    since_wall: float = 0.0   # caller's clock when it engaged


# body weights: the largest force one hand exerts on the body (Eq. 2-4 clamped). A hang with a
# swing needs about 1.6 (one hand: the weight plus the centripetal pull of a 2.4 m/s swing on a
# 1 m pendulum), climbing the rope hand over hand more (2 sank the climber 0.6 m, 3 regrabbed too
# rarely in test_climbing_hand_over_hand_regrabs_the_swinging_rope); without a bound, a user
# lowering the arms while holding the bars drove the pitch PD (the target direction turning ~8
# rad/s) with over 13 kN (18 body weights) and the release flung the body at 12 m/s.
ARM_STRENGTH = 4.0
# body weights: the largest force one hand exerts across the arm, turning the body about the grip
# (the Eq. 3-4 part of its force, perpendicular to r; Shum & Ho 2012 bound their PD forces "to
# avoid unexpected high control force while the target values are very different from the
# current ones"). A hanging body is swung by the shoulders and a kip, not pulled along the arm.
# A user lowering the arms from the bars turned the hands' target about the grip at ~8 rad/s and
# the pitch PD (mostly its rate term, kad 600 N s/rad) pushed each hand across the arm with 1.3-
# 2.6 kN for the 0.1 s before the hands were low enough to let go: the COM left the bars at 7-8
# m/s and landed 5 m behind. The swings of the continuous performance (seeds 0-9) ask
# for 1.0-1.2 body weights across the arm (99th percentile of the frames held) for six of nine
# performers, 1.9-3.6 for three, who swing less with the bound (the bench's and the tests'
# swings still hold and swing). The pull along the arm keeps ARM_STRENGTH (climbing).
SWING_STRENGTH = 1.0


class DynamicProcess:
    """One character's dynamic model in a feature world."""

    def __init__(self, world: World, total_mass: float, com, offsets: Dict[str, np.ndarray],
                 free_gain: float = 1500.0):
        self.world = world
        self.total_mass = float(total_mass)
        self.xml, self.anchors = world_model_xml(world, com, total_mass, offsets)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        self._body_ids: Dict[str, int] = {}   # MuJoCo body ids by name (_body_id)
        m = self.model
        bid = lambda n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n)  # noqa: E731
        self.com_body = bid('com')
        self.eff_body = np.array([bid(f'eff_{e}') for e in EFFECTORS])
        jid = lambda n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)  # noqa: E731
        self.com_dof = int(m.jnt_dofadr[jid('com_x')])
        self.eff_dof = np.array([int(m.jnt_dofadr[jid(f'{e}_x')]) for e in EFFECTORS])
        # qpos addresses differ from dof addresses after the rope's ball joints (4 vs 3 each)
        self.com_qpos = int(m.jnt_qposadr[jid('com_x')])
        self.eff_qpos = np.array([int(m.jnt_qposadr[jid(f'{e}_x')]) for e in EFFECTORS])
        self.eq_ids: Dict[Tuple[str, str], int] = {}
        for e in EFFECTORS:
            for a in self.anchors:
                self.eq_ids[(e, a.body)] = mujoco.mj_name2id(
                    m, mujoco.mjtObj.mjOBJ_EQUALITY, f'c_{e}_{a.body}')
        self.contacts: Dict[str, Contact] = {}
        self.free_gain = float(free_gain)
        self.time = 0.0
        mass = np.array([m.body_mass[b] for b in self.eff_body])
        kd = 2.0 * np.sqrt(self.free_gain * mass)
        self._free = np.stack([np.full(4, self.free_gain), kd, np.full(4, self.free_gain), kd,
                               np.full(4, self.free_gain), kd], 1)     # (4, 6) GAIN_KEYS order
        self._gains = self._free.copy()
        # N: the most an arm pulls or pushes along itself (ARM_STRENGTH body weights per hand)
        # and across itself (SWING_STRENGTH); the feet unbounded (a landing takes 3-5 body
        # weights)
        w = self.total_mass * 9.81
        self._fmax = np.array([[ARM_STRENGTH * w, SWING_STRENGTH * w] if e.startswith('Hand')
                               else [np.inf, np.inf] for e in EFFECTORS])
        self._yaw = 0.0
        self._r0 = np.array([offsets[e] for e in EFFECTORS], float)
        self._zero = np.zeros((4, 3))
        self._eff_dofs = np.concatenate([np.arange(a, a + 3) for a in self.eff_dof])
        self._r1 = self._r0.copy()
        self._rd = np.zeros((4, 3))
        self._t0, self._period = 0.0, 1.0 / 30.0
        self.in_water: Optional[str] = None
        self.unstable_steps = 0   # physics steps MuJoCo found unstable (bad QACC: it reset the data)
        self._buoy = 0.0
        # MuJoCo's buoyancy volume: the inertia boxes of the character's bodies
        self._mj_volume = 0.0
        for b in [self.com_body, *self.eff_body]:
            i = m.body_inertia[b]
            mb = m.body_mass[b]
            dims = [math.sqrt(max(6.0 * (i[(k + 1) % 3] + i[(k + 2) % 3] - i[k]) / mb, 0.0))
                    for k in range(3)]
            self._mj_volume += dims[0] * dims[1] * dims[2]
        self._water = {f.name: f for f in world.features.values() if f.kind == 'water'}
        mujoco.mj_forward(m, self.data)

    # ------------------------------------------------------------------ state
    @property
    def com(self) -> np.ndarray:
        return self.data.xpos[self.com_body].copy()

    @property
    def com_velocity(self) -> np.ndarray:
        return self.data.qvel[self.com_dof:self.com_dof + 3].copy()

    def effectors(self) -> np.ndarray:
        """World positions (4, 3) of the effector bodies, EFFECTORS order."""
        return self.data.xpos[self.eff_body].copy()

    def effector_velocities(self) -> np.ndarray:
        return np.stack([self.data.qvel[a:a + 3] for a in self.eff_dof])

    def place(self, com, offsets: Dict[str, np.ndarray]) -> None:
        """Teleport the character (COM and effectors), at rest."""
        d = self.data
        com = np.asarray(com, float)
        d.qpos[self.com_qpos:self.com_qpos + 3] += com - self.com
        pos = self.effectors()
        for k, e in enumerate(EFFECTORS):
            a = self.eff_qpos[k]
            d.qpos[a:a + 3] += com + offsets[e] - pos[k]
        d.qvel[:] = 0.0
        mujoco.mj_forward(self.model, d)

    def shift(self, delta) -> None:
        """Move the character (COM and effectors) by ``delta`` (world, m): walking on the floor
        (Sec. 8.3). The paper's reading of walking: the user's feet are constrained, the
        character's are not -- the feet held on the floor let go, and the body is carried
        (the composed walk's legs step; the simplified model holds no floor contact)."""
        delta = np.asarray(delta, float)
        for e, c in list(self.contacts.items()):
            if self.world.features[c.feature].kind == 'floor':
                self.release(e)
        d = self.data
        d.qpos[self.com_qpos:self.com_qpos + 3] += delta
        for a in self.eff_qpos:
            d.qpos[a:a + 3] += delta
        mujoco.mj_forward(self.model, d)

    def carry_to(self, com, velocity) -> None:
        """Put the COM at ``com`` moving at ``velocity`` (world), the effectors moved along:
        walking, the body is carried (the floor holds it while no foot does)."""
        d = self.data
        delta = np.asarray(com, float) - self.com
        d.qpos[self.com_qpos:self.com_qpos + 3] += delta
        d.qvel[self.com_dof:self.com_dof + 3] = np.asarray(velocity, float)
        for a in self.eff_qpos:
            d.qpos[a:a + 3] += delta
        mujoco.mj_forward(self.model, d)

    # ------------------------------------------------------------------ targets
    def set_targets(self, rel: np.ndarray, yaw: float, period: float) -> None:
        """The user's relative movement r^_j (4, 3, world axes) for the next ``period`` s: the
        target moves linearly from the previous one to ``rel`` over that time."""
        rel = np.asarray(rel, float)
        self._r0 = self._target_at(self.time)
        self._r1 = rel.copy()
        self._period = max(float(period), 1e-3)
        self._rd = (self._r1 - self._r0) / self._period
        self._t0 = self.time
        self._yaw = float(yaw)

    def _target_at(self, t: float) -> np.ndarray:
        s = min(max((t - self._t0) / self._period, 0.0), 1.0)
        return self._r0 + s * (self._r1 - self._r0)

    # ------------------------------------------------------------------ contacts
    def _body_id(self, name: str) -> int:
        """The MuJoCo id of a body of the model, looked up once."""
        if name not in self._body_ids:
            self._body_ids[name] = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name)
        return self._body_ids[name]

    def feature_distance(self, effector: str, feature: Feature, max_arc: Optional[float] = None):
        """(distance to the feature's surface, anchor body, contact point in the world) for an
        effector; the contact point is where the effector's centre is held (on a bar's axis for a
        hand, one effector radius above a surface for a foot). (inf, None, None) if nothing.
        ``max_arc``: on a rope, only the part within this length (m) along the rope from its top
        (the part above a hand that holds it, see :meth:`rope_arc`)."""
        d = self.data
        p = self.data.xpos[self.eff_body[EFFECTORS.index(effector)]]
        rad = EFFECTOR_RADIUS[effector]
        best = (math.inf, None, None)
        for i, g in enumerate(feature.geoms):
            n = f'f_{feature.name}_{i}'
            if g.type == 'plane':
                c = np.array([p[0], p[1], rad])
                cand = [(float(p[2]) - rad, 'world', c)]
            elif g.type == 'capsule':
                c = _closest_on_segment(p, g.vec('from'), g.vec('to'))
                cand = [(float(np.linalg.norm(p - c)) - g.num('radius'), 'world', c)]
            elif g.type == 'box':
                if 'stiffness' in g.data:
                    ctr, body = d.xpos[self._body_id(n)], n
                else:
                    ctr, body = g.vec('center'), 'world'
                half = g.vec('half')
                top = ctr[2] + half[2]
                inside = np.all(np.abs(p[:2] - ctr[:2]) <= half[:2])
                c = np.array([p[0], p[1], top + rad])
                cand = [(float(p[2]) - top - rad if inside else math.inf, body, c)]
            elif g.type == 'rock':
                # Sec. 8.4: a contact point and the radius within which it may be held; a foot
                # only from above the rock's face (its centre's height), held on top of it
                ctr = g.vec('center')
                c = ctr + [0.0, 0.0, rad] if effector.startswith('Foot') else ctr
                far = float(np.linalg.norm(p - ctr)) - g.num('radius')
                above = not effector.startswith('Foot') or p[2] >= ctr[2]
                cand = [(far if above else math.inf, 'world', c)]
            elif g.type == 'rope':
                cand = []
                seg, r = g.num('length'), g.num('radius')
                for s in range(int(g.data['segments'])):
                    top = max_arc - s * seg if max_arc is not None else seg
                    if top <= 0.0:
                        break                 # this segment and the ones below: out of range
                    b = self._body_id(f'{n}_seg{s}')
                    a0 = d.xpos[b]
                    a1 = a0 + d.xmat[b].reshape(3, 3) @ np.array([0.0, 0.0, -min(seg, top)])
                    c = _closest_on_segment(p, a0, a1)
                    cand.append((float(np.linalg.norm(p - c)) - r, f'{n}_seg{s}', c))
            else:
                cand = []
            for x in cand:
                if x[0] < best[0]:
                    best = x
        return best

    def rope_arc(self, effector: str) -> Optional[float]:
        """Where a held effector holds a rope: its anchor's length (m) along the rope from the
        rope's top; None if it does not hold a rope segment."""
        c = self.contacts.get(effector)
        if c is None or '_seg' not in c.body:
            return None
        f = self.world.features[c.feature]
        g = next(g for g in f.geoms if g.type == 'rope')
        k = int(c.body.rsplit('_seg', 1)[1])
        return k * g.num('length') - float(self.model.eq_data[c.eq, 5])

    def com_inside(self, feature: Feature) -> bool:
        x = self.com
        for g in feature.geoms:
            if g.type == 'volume' and np.all(np.abs(x - g.vec('center')) <= g.vec('half')):
                return True
        return False

    def move_effector(self, effector: str, point) -> None:
        """Teleport one effector body to ``point`` (world), at rest."""
        k = EFFECTORS.index(effector)
        a, v = self.eff_qpos[k], self.eff_dof[k]
        d = self.data
        d.qpos[a:a + 3] += np.asarray(point, float) - d.xpos[self.eff_body[k]]
        d.qvel[v:v + 3] = 0.0
        mujoco.mj_forward(self.model, d)

    def engage(self, effector: str, feature: Feature, body: str, point) -> None:
        """Hold ``effector`` at ``point`` (world) on ``body`` of ``feature`` (an equality
        constraint switched on)."""
        self.release(effector)
        m, d = self.model, self.data
        e = self.eq_ids[(effector, body)]
        if body == 'world':
            local = np.asarray(point, float)
        else:
            b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body)
            local = d.xmat[b].reshape(3, 3).T @ (np.asarray(point, float) - d.xpos[b])
        m.eq_data[e, 0:3] = 0.0
        m.eq_data[e, 3:6] = local
        d.eq_active[e] = 1
        k = EFFECTORS.index(effector)
        self._gains[k] = [feature.dynamics[x] for x in GAIN_KEYS]
        self.contacts[effector] = Contact(effector, feature.name, body, e, self.time)

    def release(self, effector: str) -> None:
        c = self.contacts.pop(effector, None)
        if c is not None:
            self.data.eq_active[c.eq] = 0
            k = EFFECTORS.index(effector)
            self._gains[k] = self._free[k]

    def release_all(self) -> None:
        for e in list(self.contacts):
            self.release(e)

    # ------------------------------------------------------------------ stepping
    def _update_water(self) -> None:
        inside = next((f for f in self._water.values() if self.com_inside(f)), None)
        name = inside.name if inside else None
        if name == self.in_water:
            return
        self.in_water = name
        m = self.model
        if inside is None:
            m.opt.density, m.opt.viscosity, self._buoy = 0.0, 0.0, 0.0
            return
        rho = inside.dynamics.get('density', 1000.0)
        m.opt.density = rho
        m.opt.viscosity = inside.dynamics.get('viscosity', 0.0009)
        body_rho = inside.dynamics.get('body_density', 985.0)
        g = -float(m.opt.gravity[2])
        # MuJoCo's inertia-box fluid model gives the drag but no buoyancy (measured: a body at
        # rest in it sinks like in air): the paper's buoyancy is added here, mass / body density
        self._buoy = rho * g * self.total_mass / body_rho

    def forces(self, t: float) -> np.ndarray:
        """Eq. 2-4 forces (4, 3) on the effectors (world axes) at time ``t``."""
        d = self.data
        s = min(max((t - self._t0) / self._period, 0.0), 1.0)
        rh = self._r0 + s * (self._r1 - self._r0)
        rhd = self._rd if s < 1.0 else self._zero
        return _contact_forces(d.xpos[self.com_body], d.qvel[self.com_dof:self.com_dof + 3],
                               d.xpos[self.eff_body], d.qvel[self._eff_dofs].reshape(4, 3),
                               rh, rhd, self._gains, self._yaw)

    def step(self, duration: float) -> None:
        """Advance ``duration`` s: at every physics step Eq. 2-4 from the current state (one numba
        call writing ``xfrc_applied``), then ``mj_step``."""
        m, d = self.model, self.data
        self._update_water()
        n = max(1, int(round(duration / m.opt.timestep)))
        xfrc = d.xfrc_applied
        xfrc[:] = 0.0
        xpos, qvel = d.xpos, d.qvel
        for _ in range(n):
            _apply_forces(xpos, qvel, xfrc, self.com_body, self.com_dof, self.eff_body,
                          self.eff_dof, self._r0, self._r1, self.time, self._t0, self._period,
                          self._gains, self._yaw, self._buoy, self._fmax)
            mujoco.mj_step(m, d)
            self.time = float(d.time)
        bad = int(d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number)
        if bad > self.unstable_steps:
            # MuJoCo reset the data (the start pose, every equality off): no phantom contacts
            self.unstable_steps = bad
            self.contacts.clear()
            self._gains[:] = self._free
        if not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))):
            raise FloatingPointError('dynamic process diverged')

    def constraint_gap(self) -> float:
        """Largest distance (m) between an engaged effector and its anchor point."""
        m, d = self.model, self.data
        gap = 0.0
        for c in self.contacts.values():
            b2 = int(m.eq_obj2id[c.eq])
            p2 = d.xpos[b2] + d.xmat[b2].reshape(3, 3) @ m.eq_data[c.eq, 3:6]
            p1 = d.xpos[int(m.eq_obj1id[c.eq])]
            gap = max(gap, float(np.linalg.norm(p1 - p2)))
        return gap


@_jit.njit
def _contact_forces_jit(x, v, pe, ve, rh_w, rhd_w, g, yaw):  # pragma: no cover - numba
    """Eq. 2-4 (see the module docstring) for the 4 effectors: forces (4, 3) in world axes.
    ``x, v``: COM position and velocity; ``pe, ve`` (4, 3): effector positions and velocities;
    ``rh_w, rhd_w`` (4, 3): the targets r^ and their rates; ``g`` (4, 6): GAIN_KEYS gains."""
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.zeros((4, 3))
    for k in range(4):
        # world -> body frame (yaw removed)
        dx, dy, dz = pe[k, 0] - x[0], pe[k, 1] - x[1], pe[k, 2] - x[2]
        r = (c * dx + s * dy, -s * dx + c * dy, dz)
        dx, dy, dz = ve[k, 0] - v[0], ve[k, 1] - v[1], ve[k, 2] - v[2]
        rd = (c * dx + s * dy, -s * dx + c * dy, dz)
        rh = (c * rh_w[k, 0] + s * rh_w[k, 1], -s * rh_w[k, 0] + c * rh_w[k, 1], rh_w[k, 2])
        rhd = (c * rhd_w[k, 0] + s * rhd_w[k, 1], -s * rhd_w[k, 0] + c * rhd_w[k, 1], rhd_w[k, 2])
        ln = max(math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]), 1e-6)
        lnh = max(math.sqrt(rh[0] * rh[0] + rh[1] * rh[1] + rh[2] * rh[2]), 1e-6)
        lrate = (r[0] * rd[0] + r[1] * rd[1] + r[2] * rd[2]) / ln
        lrateh = (rh[0] * rhd[0] + rh[1] * rhd[1] + rh[2] * rhd[2]) / lnh
        fl = g[k, 0] * (lnh - ln) + g[k, 1] * (lrateh - lrate)
        f = [fl * r[0] / ln, fl * r[1] / ln, fl * r[2] / ln]
        for i, kk in ((0, 2), (1, 4)):           # pitch: x-z plane, roll: y-z plane
            rho2 = max(r[i] * r[i] + r[2] * r[2], 1e-8)
            rho2h = max(rh[i] * rh[i] + rh[2] * rh[2], 1e-8)
            ang = math.atan2(r[i], r[2])
            angh = math.atan2(rh[i], rh[2])
            err = (angh - ang + math.pi) % (2.0 * math.pi) - math.pi
            rate = (rd[i] * r[2] - r[i] * rd[2]) / rho2
            rateh = (rhd[i] * rh[2] - rh[i] * rhd[2]) / rho2h
            mag = g[k, kk] * err + g[k, kk + 1] * (rateh - rate)
            f[i] += mag * math.cos(ang)
            f[2] -= mag * math.sin(ang)
        out[k, 0] = c * f[0] - s * f[1]
        out[k, 1] = s * f[0] + c * f[1]
        out[k, 2] = f[2]
    return out


@_jit.njit
def _apply_forces_jit(xpos, qvel, xfrc, com_body, com_dof, eff_body, eff_dof, r0, r1, t, t0,
                      period, gains, yaw, buoy, fmax):  # pragma: no cover - numba
    """One step's forces into ``xfrc`` (MuJoCo's xfrc_applied): Eq. 2-4 on the effectors at
    time ``t`` (targets interpolated from ``r0`` to ``r1`` over ``period`` from ``t0``), each
    effector's component along r (effector - COM) at most ``fmax[k, 0]`` N and the component
    across r at most ``fmax[k, 1]`` N, their sum reversed on the COM (Eq. 1) with the buoyancy
    ``buoy`` (N, up)."""
    s = min(max((t - t0) / period, 0.0), 1.0)
    rh = r0 + s * (r1 - r0)
    rhd = (r1 - r0) / period if s < 1.0 else np.zeros_like(r0)
    pe = np.empty((4, 3))
    ve = np.empty((4, 3))
    for k in range(4):
        for a in range(3):
            pe[k, a] = xpos[eff_body[k], a]
            ve[k, a] = qvel[eff_dof[k] + a]
    x = xpos[com_body].copy()
    v = qvel[com_dof:com_dof + 3].copy()
    f = _contact_forces_jit(x, v, pe, ve, rh, rhd, gains, yaw)
    for k in range(4):
        r0_, r1_, r2_ = pe[k, 0] - x[0], pe[k, 1] - x[1], pe[k, 2] - x[2]
        ln = max(math.sqrt(r0_ * r0_ + r1_ * r1_ + r2_ * r2_), 1e-6)
        u = (r0_ / ln, r1_ / ln, r2_ / ln)
        fr = f[k, 0] * u[0] + f[k, 1] * u[1] + f[k, 2] * u[2]
        ft = (f[k, 0] - fr * u[0], f[k, 1] - fr * u[1], f[k, 2] - fr * u[2])
        nt = math.sqrt(ft[0] * ft[0] + ft[1] * ft[1] + ft[2] * ft[2])
        sr = fmax[k, 0] / abs(fr) if abs(fr) > fmax[k, 0] else 1.0
        st = fmax[k, 1] / nt if nt > fmax[k, 1] else 1.0
        for a in range(3):
            f[k, a] = sr * fr * u[a] + st * ft[a]
    for a in range(3):
        tot = 0.0
        for k in range(4):
            xfrc[eff_body[k], a] = f[k, a]
            tot += f[k, a]
        xfrc[com_body, a] = -tot
    xfrc[com_body, 2] += buoy



def _contact_forces_np(x, v, pe, ve, rh_w, rhd_w, g, yaw):
    """The numpy twin of :func:`_contact_forces_jit` (same numbers, the 4 effectors at once)."""
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])   # world -> body (yaw removed)
    r = (np.asarray(pe, float) - x) @ rot.T
    rd = (np.asarray(ve, float) - v) @ rot.T
    rh = np.asarray(rh_w, float) @ rot.T
    rhd = np.asarray(rhd_w, float) @ rot.T
    g = np.asarray(g, float)
    ln = np.maximum(np.linalg.norm(r, axis=1), 1e-6)
    lnh = np.maximum(np.linalg.norm(rh, axis=1), 1e-6)
    lrate = np.sum(r * rd, axis=1) / ln
    lrateh = np.sum(rh * rhd, axis=1) / lnh
    fl = g[:, 0] * (lnh - ln) + g[:, 1] * (lrateh - lrate)
    f = fl[:, None] * r / ln[:, None]
    for i, kk in ((0, 2), (1, 4)):           # pitch: x-z plane, roll: y-z plane
        rho2 = np.maximum(r[:, i] ** 2 + r[:, 2] ** 2, 1e-8)
        rho2h = np.maximum(rh[:, i] ** 2 + rh[:, 2] ** 2, 1e-8)
        ang = np.arctan2(r[:, i], r[:, 2])
        angh = np.arctan2(rh[:, i], rh[:, 2])
        err = np.mod(angh - ang + math.pi, 2.0 * math.pi) - math.pi
        rate = (rd[:, i] * r[:, 2] - r[:, i] * rd[:, 2]) / rho2
        rateh = (rhd[:, i] * rh[:, 2] - rh[:, i] * rhd[:, 2]) / rho2h
        mag = g[:, kk] * err + g[:, kk + 1] * (rateh - rate)
        f[:, i] += mag * np.cos(ang)
        f[:, 2] -= mag * np.sin(ang)
    return f @ rot                            # body -> world


def _apply_forces_np(xpos, qvel, xfrc, com_body, com_dof, eff_body, eff_dof, r0, r1, t, t0,
                     period, gains, yaw, buoy, fmax):
    """The numpy twin of :func:`_apply_forces_jit`."""
    s = min(max((t - t0) / period, 0.0), 1.0)
    rh = r0 + s * (r1 - r0)
    rhd = (r1 - r0) / period if s < 1.0 else np.zeros_like(r0)
    eff_body = np.asarray(eff_body)
    dofs = np.asarray(eff_dof)[:, None] + np.arange(3)
    x = xpos[com_body].copy()
    f = _contact_forces_np(x, qvel[com_dof:com_dof + 3].copy(),
                           xpos[eff_body], qvel[dofs], rh, rhd, gains, yaw)
    r = xpos[eff_body] - x
    u = r / np.maximum(np.linalg.norm(r, axis=1), 1e-6)[:, None]
    fr = np.sum(f * u, axis=1)
    ft = f - fr[:, None] * u
    nt = np.linalg.norm(ft, axis=1)
    fmax = np.asarray(fmax, float)
    sr = np.where(np.abs(fr) > fmax[:, 0], fmax[:, 0] / np.maximum(np.abs(fr), 1e-300), 1.0)
    st = np.where(nt > fmax[:, 1], fmax[:, 1] / np.maximum(nt, 1e-300), 1.0)
    f = (sr * fr)[:, None] * u + st[:, None] * ft
    xfrc[eff_body, :3] = f
    xfrc[com_body, :3] = -f.sum(axis=0)
    xfrc[com_body, 2] += buoy


# numba when installed and not switched off (KINECT_NUMBA=0), the numpy twins otherwise
_contact_forces = _jit.pick(_contact_forces_jit, _contact_forces_np)
_apply_forces = _jit.pick(_apply_forces_jit, _apply_forces_np)


__all__ = ['DynamicProcess', 'Contact', 'GAIN_KEYS', 'ARM_STRENGTH', 'SWING_STRENGTH']
