"""Virtual joints pinning the feet to the floor (Shum & Ho 2012, Sec. 6.1): a foot whose target is
on the floor and slow is pinned where it is (a ``connect`` equality to the world); it is released
when the target lifts or slides away, or when the pin conflicts with the targets (pulls harder
than ``pin_max_force`` or is stretched beyond ``conflict_release``)."""
from __future__ import annotations

import weakref
from typing import List

import numpy as np
from skeleton_core.model import NUM_JOINTS


class FootPins:
    """The foot pins of every character of one world."""

    def __init__(self, world):
        """``world``: the :class:`~physics_sim.world.World` whose feet these are (held weakly: a
        world and its pins in a reference cycle outlive the world until a full garbage
        collection, and a world holds a MuJoCo model and data of several MB that Python's
        collector does not see -- a world dropped per visitor piled up)."""
        self._world = weakref.ref(world)
        self.feet: List[tuple] = []    # (character index, joint, PinState)
        self.idx = np.zeros(0, int)    # stacked joint row of every foot
        self.eq = np.zeros(0, int)     # its pin equality id
        self.active = np.zeros(0, bool)
        self.manual = np.zeros(0, bool)
        self._pts = None

    @property
    def world(self):
        return self._world()

    def pack(self) -> None:
        """After every rebuild (the PinState objects live as long as their characters)."""
        chars = self.world.chars
        self.feet = [(i, j, ch.pins[j]) for i, ch in enumerate(chars) for j in ch.pins]
        self.idx = np.array([i * NUM_JOINTS + j for i, j, _ in self.feet], int)
        self.eq = np.array([chars[i].pin_eq[j] for i, j, _ in self.feet], int)
        self.refresh()

    def refresh(self) -> None:
        """After the targets were repacked: the pins' flags and points as the characters hold them."""
        self.active = np.array([pin.active for _, _, pin in self.feet], bool)
        self.manual = np.array([pin.manual for _, _, pin in self.feet], bool)
        self._pts = None

    def set(self, ch, j: int, on: bool, point=None) -> None:
        w = self.world
        e = ch.pin_eq[j]
        if on:
            w.model.eq_data[e, 3:6] = point
        w.data.eq_active[e] = 1 if on else 0
        te = ch.track_eq.get(j, -1)
        if te >= 0:  # constraint controller: the pin replaces the foot's tracking spring
            w.data.eq_active[te] = 0 if on else 1

    def update(self, p_t, v_t, pts) -> None:
        """Pin a foot whose target is on the floor and slow; release it when the target lifts or
        slides away. Scalar code: two feet per character, where numpy's per-call cost would
        dominate."""
        fi = self.idx
        if fi.size:
            self.update_feet(p_t[fi], v_t[fi], pts[fi])

    def update_feet(self, xt, vt, xf) -> None:
        """:meth:`update` of the feet's rows only (``p_t[idx]``, ``v_t[idx]``, ``pts[idx]``):
        a caller that has them without the other joints' rows."""
        w = self.world
        c = w.config
        fi = self.idx
        if fi.size == 0:
            return
        floor = w.floor
        act = self.active
        any_act = any(pin.active for _, _, pin in self.feet)
        xt = xt.tolist()
        ht = [x[2] - floor for x in xt]
        speed2 = [v[0] * v[0] + v[1] * v[1] + v[2] * v[2] for v in vt.tolist()]
        slow2 = c.pin_speed * c.pin_speed
        if not any_act and not (c.pin_feet and any(h < c.pin_height and s2 < slow2
                                                   for h, s2 in zip(ht, speed2))):
            return  # nothing pinned and no foot target on the floor: nothing can change
        # the simulated foot must be on the floor and slow too: pinning a flailing foot would
        # stop it dead in one step (an impulse the solver cannot absorb)
        d = w.data
        forces = self.forces(c.pin_max_force).tolist() if any_act else None
        pin_pts = self.points().tolist() if any_act else None
        cv = arm = None
        changes = []
        for n, (i, j, pin) in enumerate(self.feet):
            if pin.active:
                dx, dy = xt[n][0] - pin_pts[n][0], xt[n][1] - pin_pts[n][1]
                up = (ht[n] > c.pin_release_height or not c.pin_feet
                      or dx * dx + dy * dy > c.pin_release_distance ** 2)
                if forces[n] > c.pin_max_force:  # conflicting constraints: let go before the
                    w.counters['constraint_conflict'] += 1   # solver blows up
                    w.counters['virtual_joint_released'] += 1
                    changes.append(n)
                elif up and not pin.manual:
                    changes.append(n)
            elif c.pin_feet and not pin.manual and ht[n] < c.pin_height and speed2[n] < slow2:
                if cv is None:   # the simulated feet's velocities, only when one may be pinned
                    cv = d.cvel[w.ix.jb[fi]].tolist()
                    arm = (xf - d.subtree_com[w.ix.jroot[fi]]).tolist()
                wv, v, r = cv[n][:3], cv[n][3:], arm[n]
                vs = (v[0] + wv[1] * r[2] - wv[2] * r[1], v[1] + wv[2] * r[0] - wv[0] * r[2],
                      v[2] + wv[0] * r[1] - wv[1] * r[0])
                if (float(xf[n, 2]) - floor < c.pin_height + 0.03
                        and vs[0] * vs[0] + vs[1] * vs[1] + vs[2] * vs[2] < 4.0 * slow2):
                    changes.append(n)
        for n in changes:
            i, j, pin = self.feet[n]
            if not pin.active:
                pin.active = True
                pin.point = xf[n].copy()
                self.set(w.chars[i], j, True, pin.point)
                w.counters['pins'] += 1
            else:
                pin.active = pin.manual = False
                self.set(w.chars[i], j, False)
                self.manual[n] = False
            act[n] = pin.active
            self._pts = None

    def forces(self, below: float = 0.0) -> np.ndarray:
        """Magnitude (N) of each foot pin's constraint force in the last step (0 if inactive).
        With ``below`` > 0, all zeros when no equality row can reach it (|F| <= sqrt(3) max |row|):
        the caller only asks which pins pull harder than that."""
        w = self.world
        d = w.data
        out = np.zeros(len(self.feet))
        ne = int(d.ne)   # equality rows come first in the constraint arrays, by equality id
        if ne and below > 0.0 and 1.7320508075688772 * np.abs(d.efc_force[:ne]).max() <= below:
            ne = 0
        if ne:
            f2 = np.bincount(d.efc_id[:ne], d.efc_force[:ne] ** 2, minlength=w.model.neq)
            out = np.sqrt(f2[self.eq]) * self.active
        return out

    def points(self) -> np.ndarray:
        if self._pts is None or len(self._pts) != len(self.feet):
            self._pts = np.array([pin.point for _, _, pin in self.feet]).reshape(-1, 3)
        return self._pts

    def check(self, pts_now: np.ndarray) -> None:
        """Stretched pins are conflicts (counted), released when badly stretched."""
        w = self.world
        c = w.config
        act = [n for n, (_, _, pin) in enumerate(self.feet) if pin.active]
        if not act:
            return
        gap_v = pts_now[self.idx] - self.points()
        gaps = np.sqrt(np.sum(gap_v * gap_v, axis=1)).tolist()
        for n in act:
            i, j, pin = self.feet[n]
            if gaps[n] > c.conflict_tolerance:
                w.counters['constraint_conflict'] += 1
            if gaps[n] > c.conflict_release:
                pin.active = pin.manual = False
                self.set(w.chars[i], j, False)
                self._pts = None
                w.counters['virtual_joint_released'] += 1


__all__ = ['FootPins']
