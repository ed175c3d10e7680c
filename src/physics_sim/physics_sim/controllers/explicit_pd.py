"""``explicit_pd``: the papers' scheme (Shum & Ho 2012 Sec. 6; Shum et al. 2013 Sec. VII). Eq. 1
forces at every joint point and Eq. 2 torques about every segment axis, applied as external forces
(``xfrc_applied``) and integrated explicitly. Eq. 1 is evaluated from the current state at every
physics step (:func:`physics_sim.controller.explicit_pd_wrenches`, compiled where numba is
available); Eq. 2 torques and the foot pins every ``slow_control_every`` steps (default 4)."""
from __future__ import annotations

import mujoco

from ..controller import explicit_pd_wrenches
from .registry import register
from .base import Controller


@register
class ExplicitPD(Controller):
    name = 'explicit_pd'

    def __init__(self):
        self._twist = None
        self._count = 0

    def targets_changed(self, world) -> None:
        self._twist = None      # recomputed on the next step
        self._count = 0

    def advance(self, world, nsteps: int) -> None:
        m, d = world.model, world.data
        for _ in range(nsteps):
            mujoco.mj_step1(m, d)   # kinematics + velocities of the current state
            self._control(world)    # forces from the current state (not one step old)
            mujoco.mj_step2(m, d)
            world.time = float(d.time)

    def _control(self, w) -> None:
        d, c = w.data, w.config
        g = c.gains
        xfrc = d.xfrc_applied
        xfrc[:] = 0.0
        t = w.time
        tg = w.tg
        if tg is not None:
            ix = w.ix
            explicit_pd_wrenches(xfrc, d.site_xpos, ix.js, d.cvel, d.subtree_com, d.xipos, ix.jb,
                                 ix.jroot, tg['P0'], tg['dP'], tg['V'], w.frame_shares((t,))[0],
                                 ix.jchar, g.ke, g.kd, g.max_force, ix.ub, ix.sum_rows)
            self._count += 1
            if self._twist is None or self._count >= (c.slow_control_every or 4):
                self._count = 0
                p_t, v_t = w.targets_at(t)
                pts = w.joint_points()
                self._twist = w.twist_torques(t, tg, pts)
                w.pins.update(p_t, v_t, pts)
            xfrc[ix.sb, 3:] += self._twist
        w.apply_pushes(t)


__all__ = ['ExplicitPD']
