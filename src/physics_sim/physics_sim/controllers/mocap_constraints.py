"""``mocap_constraints``: the positional PD is replaced by one soft ``connect`` equality per joint
between the body point and a mocap body moved along the target; the spring-damper is the
constraint's ``solref`` (time constant, damping ratio) and is solved implicitly by MuJoCo's
constraint solver, so it stays stable at any stiffness the time step can resolve. Eq. 2 torques are
kept as in the paper. Force clamping is then done by the solver's impedance, not max_force."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .registry import register
from .chunked import ChunkedController


@register
class MocapConstraints(ChunkedController):
    name = 'mocap_constraints'

    def character_params(self, config, params):
        c = config
        return replace(params, mocap_targets=True,
                       track_solref=(c.track_timeconst, c.track_dampratio),
                       track_solimp=(c.track_impedance, c.track_impedance, 0.001))

    def bind(self, world) -> None:
        self.mocap = (np.concatenate([c.mocap_ids for c in world.chars]).astype(int)
                      if world.chars else np.zeros(0, int))

    def control_span(self, w, s) -> None:
        c = w.config
        lead = 2.0 * c.track_impedance * c.track_timeconst * c.track_dampratio ** 2
        w.data.mocap_pos[self.mocap] = s.p_t + lead * s.v_t
        w.data.xfrc_applied[w.ix.sb, 3:] += w.twist_torques(s.t, w.tg, s.pts, share=s.share)


__all__ = ['MocapConstraints']
