"""Controllers whose Eq. 1 runs inside MuJoCo (``actuator_pd``, ``mocap_constraints``): Python
updates their targets, Eq. 2 and the foot pins once per span of ``slow_control_every`` steps
(default: the whole advance, <= 50 steps) and ``mj_step`` runs the span's steps in C."""
from __future__ import annotations

from typing import NamedTuple

import mujoco
import numpy as np

from .base import Controller


class Span(NamedTuple):
    """One span's targets: ``t`` its middle, ``span`` its length (s); ``sj`` the interpolation
    shares at its start, middle and end (numbers when the characters share their frame times,
    else (3, N*20, 1)); ``share`` the shares at the middle by character (for Eq. 2);
    ``p_t`` / ``v_t`` the targets at the middle; ``pts`` the joint points now."""

    t: float
    span: float
    sj: object
    share: object
    p_t: np.ndarray
    v_t: np.ndarray
    pts: np.ndarray


class ChunkedController(Controller):
    """Base of the controllers stepping spans in C; subclasses set the span's controls."""

    def advance(self, world, nsteps: int) -> None:
        m, d = world.model, world.data
        self.before_spans(world)
        spans = -(-nsteps // (int(world.config.slow_control_every) or 50))  # equal spans
        for i in range(spans):
            nstep = (nsteps * (i + 1)) // spans - (nsteps * i) // spans
            self._span(world, nstep)
            mujoco.mj_step(m, d, nstep=nstep)
            world.time = float(d.time)

    def before_spans(self, world) -> None:
        """Once per advance, before its spans."""

    def _span(self, w, nstep: int) -> None:
        w.data.xfrc_applied[:] = 0.0
        span = nstep * w.model.opt.timestep
        t = w.time + 0.5 * span
        tg = w.tg
        if tg is not None:
            if tg['uniform'] is not None:
                t0, per = tg['uniform']
                sj = [min(max((x - t0) / per, 0.0), 1.0) for x in (w.time, t, w.time + span)]
                share = sj[1]
                v_t = tg['V'] if sj[1] < 1.0 else tg['V'] * 0.0
            else:
                sh = w.frame_shares((w.time, t, w.time + span))
                sj = sh[:, w.ix.jchar, None]
                share = sh[1]
                v_t = tg['V'] * (sj[1] < 1.0)
            p_t = tg['P0'] + sj[1] * tg['dP']
            s = Span(t, span, sj, share, p_t, v_t, w.joint_points())
            self.control_span(w, s)
            w.pins.update(s.p_t, s.v_t, s.pts)
        w.apply_pushes(t)

    def control_span(self, world, s: Span) -> None:
        """Set the controls (actuator states, mocap targets, Eq. 2 torques) for the span."""
        raise NotImplementedError


__all__ = ['ChunkedController', 'Span']
