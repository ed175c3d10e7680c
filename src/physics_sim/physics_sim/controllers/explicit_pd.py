"""``explicit_pd``: the papers' scheme (Shum & Ho 2012 Sec. 6; Shum et al. 2013 Sec. VII). Eq. 1
forces at every joint point and Eq. 2 torques about every segment axis, applied as external forces
and integrated explicitly: body wrenches handed to MuJoCo as generalized forces
(``qfrc_applied``, :func:`physics_sim.controller.wrench_qfrc`; ``xfrc_applied`` without numba).
Eq. 1 is evaluated from the current state at every physics step
(:func:`physics_sim.controller.explicit_pd_wrenches`, compiled where numba is available); Eq. 2
torques and the foot pins every ``slow_control_every`` steps (default 4)."""
from __future__ import annotations

import mujoco
import numpy as np

from skeleton_core import jit

from ..controller import explicit_pd_step, explicit_pd_wrenches, twist_torques, wrench_qfrc
from .registry import register
from .base import Controller


@register
class ExplicitPD(Controller):
    name = 'explicit_pd'

    def __init__(self):
        self._twist = None
        self._count = 0
        self._share = None    # (N,) every character's interpolation share, refilled per step
        self._sb = None       # the segment bodies' rows of xfrc_applied (a slice when contiguous)
        # compiled: the wrenches are summed here and handed to MuJoCo as generalized forces
        self._wr = None       # (nbody, 6) like xfrc_applied, or None: xfrc_applied itself
        self._bodies = None   # the bodies that get a wrench
        self._pushed = True   # xfrc_applied may hold pushes (cleared at the next step)
        self._sc_site = self._sp_site = self._foot_sites = None

    def bind(self, world) -> None:
        ix = world.ix
        n = len(world.chars)
        self._share = np.zeros(n)
        sb = ix.sb
        # the same additions as indexing with sb, without the gather and scatter at every step
        contiguous = len(sb) > 0 and np.array_equal(sb, np.arange(sb[0], sb[0] + len(sb)))
        self._sb = slice(int(sb[0]), int(sb[0]) + len(sb)) if contiguous else sb
        if jit.enabled():
            self._wr = np.zeros_like(world.data.xfrc_applied)
            self._bodies = np.union1d(ix.jb, sb).astype(np.int64)
        else:
            self._wr = self._bodies = None
        # the joint sites of every segment's ends and of the feet (the joint points: Eq. 2's axes
        # and the pins read them from site_xpos; World.joint_points gathers the same rows)
        self._sc_site = self._sp_site = self._foot_sites = None
        if ix.js is not None and ix.axis_site is None:
            self._sc_site, self._sp_site = ix.js[ix.sc], ix.js[ix.sp]
            self._foot_sites = ix.js[world.pins.idx]
        # the compiled step's fixed arguments: views of this model's and data's arrays (their
        # memory lives as long as the data; a rebuild binds again), fetched once, not per step
        m, d = world.model, world.data
        self._head = (d.qfrc_applied, self._wr, d.site_xpos, ix.js, d.cvel, d.subtree_com,
                      d.xipos, ix.jb, ix.jroot)
        self._tail = (self._bodies, m.body_dofadr, m.body_dofnum, m.body_parentid,
                      m.dof_parentid, m.body_rootid, d.cdof)

    def targets_changed(self, world) -> None:
        self._twist = None      # recomputed on the next step
        self._count = 0

    def advance(self, world, nsteps: int) -> None:
        m, d = world.model, world.data
        step1, step2, control = mujoco.mj_step1, mujoco.mj_step2, self._control
        for _ in range(nsteps):
            step1(m, d)         # kinematics + velocities of the current state
            control(world)      # forces from the current state (not one step old)
            step2(m, d)
            world.time = float(d.time)

    def _control(self, w) -> None:
        d, c = w.data, w.config
        g = c.gains
        t = w.time
        tg = w.tg
        if self._wr is not None and tg is not None:
            self._control_compiled(w, d, c, g, t, tg)
            return
        xfrc = d.xfrc_applied
        xfrc[:] = 0.0         # the pushes' (apply_pushes)
        wr = self._wr
        if wr is None:
            wr = xfrc
        else:
            wr[:] = 0.0
        if tg is not None:
            ix = w.ix
            share = w.share_at(t)
            shares = self._shares(share, tg)
            explicit_pd_wrenches(wr, d.site_xpos, ix.js, d.cvel, d.subtree_com, d.xipos, ix.jb,
                                 ix.jroot, tg['P0'], tg['dP'], tg['V'], shares,
                                 ix.jchar, g.ke, g.kd, g.max_force, ix.ub, ix.sum_rows)
            self._slow(w, c, t, tg, share)
            wr[ix.sb if self._sb is None else self._sb, 3:] += self._twist
        if self._wr is not None:
            m = w.model
            wrench_qfrc(d.qfrc_applied, wr, self._bodies, m.body_dofadr, m.body_dofnum,
                        m.body_parentid, m.dof_parentid, m.body_rootid, d.cdof, d.xipos,
                        d.subtree_com)
        if w.shared.pushes:
            w.apply_pushes(t)

    def _shares(self, share, tg):
        """Every character's interpolation share (N,): ``share`` itself, or a plain number
        spread over the characters (the kernels take it per character)."""
        if not isinstance(share, float):
            return share
        shares = self._share
        if shares is None or len(shares) != len(tg['T0']):
            shares = self._share = np.zeros(len(tg['T0']))
        shares.fill(share)
        return shares

    def _slow(self, w, c, t, tg, share) -> None:
        """Eq. 2 torques and the foot pins, every ``slow_control_every`` steps (after Eq. 1: the
        pins see the same state either way)."""
        self._count += 1
        if self._twist is None or self._count >= (c.slow_control_every or 4):
            self._count = 0
            p_t, v_t = w.targets_at(t, share)
            pts = w.joint_points()
            self._twist = w.twist_torques(t, tg, pts, share=share)
            w.pins.update(p_t, v_t, pts)

    def _slow_compiled(self, w, d, c, g, t, tg, share, shares) -> None:
        """:meth:`_slow` from MuJoCo's arrays: the twist kernel reads the joint points from the
        sites themselves and the pins get their feet's rows only (the same numbers, without
        interpolating and gathering every joint's rows)."""
        self._count += 1
        if self._twist is not None and self._count < (c.slow_control_every or 4):
            return
        self._count = 0
        ix = w.ix
        n = len(ix.sb)
        if self._twist is None or len(self._twist) != n:
            self._twist = np.empty((n, 3))
        twist_torques(self._twist, d.xquat, ix.sb, ix.tw_m, tg['Q0w'], tg['dQw'], shares,
                      ix.schar, d.site_xpos, self._sc_site, self._sp_site, tg['W'], d.cvel,
                      g.twist_ke * ix.tw_i, g.twist_kd * ix.tw_i, float(g.max_torque))
        fi = w.pins.idx
        if fi.size:
            if isinstance(share, float):
                xt = tg['P0'][fi] + share * tg['dP'][fi]
                vt = tg['V'][fi] * (share < 1.0)
            else:
                sj = share[ix.jchar[fi]][:, None]
                xt, vt = tg['P0'][fi] + sj * tg['dP'][fi], tg['V'][fi] * (sj < 1.0)
            w.pins.update_feet(xt, vt, d.site_xpos[self._foot_sites])

    def _control_compiled(self, w, d, c, g, t, tg) -> None:
        """The compiled step (:func:`physics_sim.controller.explicit_pd_step`): Eq. 2 and the
        pins first when due (they read the state of this step, which Eq. 1 does not change),
        then Eq. 1, the torques and the generalized forces in one call."""
        if self._pushed:      # xfrc_applied holds only the pushes here: cleared after them
            d.xfrc_applied[:] = 0.0
            self._pushed = False
        ix = w.ix
        share = w.share_at(t)
        shares = self._shares(share, tg)
        if self._sc_site is not None:
            self._slow_compiled(w, d, c, g, t, tg, share, shares)
        else:
            self._slow(w, c, t, tg, share)
        explicit_pd_step(*self._head, tg['P0'], tg['dP'], tg['V'], shares, ix.jchar, g.ke, g.kd,
                         g.max_force, ix.sb, self._twist, *self._tail)
        if w.shared.pushes:
            w.apply_pushes(t)
            self._pushed = True


__all__ = ['ExplicitPD']
