"""Per-joint smoothing filters used as baselines: the Kinect SDK v1 joint filter and One Euro.

Both are streaming, vectorised over the 20 joints, and treat a NOT_TRACKED joint as invalid: its raw
position is passed through and that joint's filter restarts when it is seen again.

Holt double exponential (Kinect SDK v1)
---------------------------------------
The SDK's ``NuiTransformSmooth`` with ``NUI_TRANSFORM_SMOOTH_PARAMETERS`` is Holt's double
exponential smoothing with a jitter-reduction stage, a forward prediction and a clamp to the raw
data (Microsoft, "Skeletal Joint Smoothing White Paper", Kinect for Windows SDK 1.x; the same
algorithm as the SDK sample ``FilterDoubleExponential``). Per joint, with raw position ``x``:

1. jitter filter: ``d = |x - f_prev|``; if ``d <= jitter_radius`` the input is pulled towards the
   previous filtered value, ``x' = x d/r + f_prev (1 - d/r)``, else ``x' = x``;
2. Holt: ``f = x' (1 - smoothing) + (f_prev + b_prev) smoothing``,
   ``b = (f - f_prev) correction + b_prev (1 - correction)``;
3. prediction: ``y = f + b prediction``;
4. clamp: if ``|y - x| > max_deviation_radius``, pull ``y`` onto the sphere of that radius round ``x``.

The first frame outputs the raw value (trend 0); the second averages the two raw values. INFERRED
joints use twice the jitter and deviation radii, as in the SDK sample. SDK defaults: smoothing 0.5,
correction 0.5, prediction 0.5, jitter radius 0.05 m, max deviation radius 0.04 m.

One Euro filter (Casiez, Roussel & Vogel, CHI 2012)
---------------------------------------------------
A first-order low-pass whose cutoff rises with speed: ``fc = min_cutoff + beta |dx/dt|_filtered``,
``alpha = 1 / (1 + tau / Te)`` with ``tau = 1 / (2 pi fc)``. The speed is the 3-D speed of the joint
(so the filter is rotation invariant; the paper filters scalars) from successive *raw* positions (as in
the authors' reference implementation), smoothed with ``d_cutoff``.
Defaults (our tuning for joint positions in metres at 30 Hz, following the paper's procedure of
trading jitter at rest against lag): ``min_cutoff = 1.0 Hz``, ``beta = 3.0 s/m``, ``d_cutoff = 1.0 Hz``,
chosen on a 4 x 4 grid (min_cutoff 0.5-2.5 Hz, beta 0.5-10) on the sensor-model class-a streams of the
built-in *database* clips (not the dev clips used for evaluation): it lowers the Eq. 18 error
(6.90 vs raw 7.03 cm) and the mean acceleration by 75 % (6.3 vs 24.6 m/s^2) at a 5 % MPJPE cost
(lag); beta = 1 lagged more (MPJPE +14 %).
"""
from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

from .model import INFERRED, NOT_TRACKED, NUM_JOINTS

HOLT_DEFAULTS = dict(smoothing=0.5, correction=0.5, prediction=0.5, jitter_radius=0.05,
                     max_deviation_radius=0.04)
ONE_EURO_DEFAULTS = dict(min_cutoff=1.0, beta=3.0, d_cutoff=1.0)


def _states(tracking_state, n):
    if tracking_state is None:
        return np.full(n, 2, np.uint8)
    return np.asarray(tracking_state)


class HoltFilter:
    """Kinect SDK v1 double exponential joint filter (see module docstring)."""

    def __init__(self, smoothing: float = 0.5, correction: float = 0.5, prediction: float = 0.5,
                 jitter_radius: float = 0.05, max_deviation_radius: float = 0.04,
                 num_joints: int = NUM_JOINTS):
        if not 0.0 <= smoothing < 1.0:
            raise ValueError('smoothing must be in [0, 1)')
        if not 0.0 <= correction <= 1.0:
            raise ValueError('correction must be in [0, 1]')
        if prediction < 0.0 or jitter_radius <= 0.0 or max_deviation_radius <= 0.0:
            raise ValueError('prediction must be >= 0 and the radii > 0')
        self.smoothing, self.correction, self.prediction = smoothing, correction, prediction
        self.jitter_radius, self.max_deviation_radius = jitter_radius, max_deviation_radius
        self.n = num_joints
        self.reset()

    def reset(self):
        self.count = np.zeros(self.n, int)
        self.raw = np.zeros((self.n, 3))
        self.filtered = np.zeros((self.n, 3))
        self.trend = np.zeros((self.n, 3))

    def update(self, positions: np.ndarray, tracking_state: Optional[np.ndarray] = None
               ) -> np.ndarray:
        x = np.asarray(positions, float)
        st = _states(tracking_state, self.n)
        valid = st != NOT_TRACKED
        scale = np.where(st == INFERRED, 2.0, 1.0)[:, None]
        jr = self.jitter_radius * scale
        md = self.max_deviation_radius * scale
        a, c = self.smoothing, self.correction

        f = x.copy()
        b = np.zeros_like(x)
        second = valid & (self.count == 1)
        later = valid & (self.count >= 2)
        # second frame: average of the two raw values
        if second.any():
            f[second] = 0.5 * (x[second] + self.raw[second])
            b[second] = (f[second] - self.filtered[second]) * c + self.trend[second] * (1 - c)
        if later.any():
            fp, bp = self.filtered[later], self.trend[later]
            d = np.linalg.norm(x[later] - fp, axis=1, keepdims=True)
            w = np.where(d <= jr[later], d / jr[later], 1.0)
            xj = x[later] * w + fp * (1 - w)
            fl = xj * (1 - a) + (fp + bp) * a
            f[later] = fl
            b[later] = (fl - fp) * c + bp * (1 - c)
        y = f + b * self.prediction
        dev = np.linalg.norm(y - x, axis=1, keepdims=True)
        over = (dev > md)[:, 0]
        if over.any():
            k = md[over] / dev[over]
            y[over] = y[over] * k + x[over] * (1 - k)
        # history
        self.raw[valid] = x[valid]
        self.filtered[valid] = f[valid]
        self.trend[valid] = b[valid]
        self.count[valid] += 1
        self.count[~valid] = 0
        y[~valid] = x[~valid]
        return y


# what a filter's update may raise on one user's numbers (update_many: that user's alone)
_FILTER_ERRORS = (ValueError, ArithmeticError, IndexError)
# update_many stacks groups of at least this many filters: measured (20 rows, the reconstruction's
# options, CPU time), 2 stacked cost ~0.03-0.05 ms more than each alone, 3 the same, 6 save ~0.18
_STACK_MIN = 4


class OneEuroFilter:
    """One Euro filter on joint positions (see module docstring)."""

    def __init__(self, min_cutoff: float = 1.0, beta: float = 3.0, d_cutoff: float = 1.0,
                 num_joints: int = NUM_JOINTS, default_rate: float = 30.0,
                 lead_accel: float = 0.0,
                 accel_cutoff: float = 0.0, accel_beta: float = 0.0,
                 lead_speed: float = 0.0):
        if min_cutoff <= 0 or d_cutoff <= 0 or beta < 0:
            raise ValueError('cutoffs must be > 0 and beta >= 0')
        if lead_accel < 0 or accel_cutoff < 0 or accel_beta < 0:
            raise ValueError('lead_accel, accel_cutoff and accel_beta must be >= 0')
        if lead_speed < 0:
            raise ValueError('lead_speed must be >= 0')
        self.min_cutoff, self.beta, self.d_cutoff = min_cutoff, beta, d_cutoff
        # the lead's velocity: the low-pass output's, smoothed at d_cutoff; lead_accel: gain of
        # the acceleration term of the lead (see update)
        self.lead_accel = float(lead_accel)
        # accel_cutoff > 0: a second low-pass stage (Hz) on that acceleration (0 = none)
        self.accel_cutoff = float(accel_cutoff)
        self.accel_beta = float(accel_beta)
        # lead_speed > 0: the lead's gain |v|^2 / (|v|^2 + lead_speed^2) (see update)
        self.lead_speed = float(lead_speed)
        self.n = num_joints
        self.default_dt = 1.0 / default_rate
        self.reset()

    def reset(self):
        self.has = np.zeros(self.n, bool)
        self.all_started = False  # every row valid in the previous update
        self.x = np.zeros((self.n, 3))
        self.raw = np.zeros((self.n, 3))
        self.dx = np.zeros((self.n, 3))
        self.fdx = np.zeros((self.n, 3))
        self.fdd = np.zeros((self.n, 3))
        self.fdd2 = np.zeros((self.n, 3))
        self.t_ns: Optional[int] = None

    @staticmethod
    def _alpha(cutoff, dt):
        tau = 1.0 / (2 * np.pi * cutoff)
        return 1.0 / (1.0 + tau / dt)

    def _cutoff(self, speed: np.ndarray, cutoff_scale, speed_scale) -> np.ndarray:
        """Per-row cutoff from ``beta * |speed|`` (see :meth:`update`)."""
        if speed_scale is not None:
            cs = 1.0 if cutoff_scale is None else cutoff_scale
            return self.min_cutoff * cs + speed * speed_scale
        cutoff = self.min_cutoff + speed
        return cutoff if cutoff_scale is None else cutoff * cutoff_scale

    def update(self, positions: np.ndarray, tracking_state: Optional[np.ndarray] = None,
               stamp_ns: Optional[int] = None,
               cutoff_scale: Optional[np.ndarray] = None,
               speed_scale: Optional[np.ndarray] = None,
               lead: Optional[np.ndarray] = None) -> np.ndarray:
        """Filter one frame. ``cutoff_scale`` (n,) > 0 optionally multiplies each row's cutoff
        (lower = smoother for that row); with ``speed_scale`` (n,) as well, ``cutoff_scale``
        multiplies the minimum cutoff only and ``speed_scale`` the speed term: the cutoff is
        ``min_cutoff * cutoff_scale + beta * |speed| * speed_scale`` (1 keeps the speed term:
        smooth at rest, no extra lag in motion).

        ``lead`` (n,) in [0, 1] (prediction correction): the low-pass output of a row moving at a
        steady velocity ``v`` trails it by ``(1 - a) / a`` samples (``a`` the row's smoothing
        factor); ``lead`` times that lag is added back along the velocity of the low-pass output
        (smoothed with ``d_cutoff``), so a row with ``lead`` 1 has no lag on a ramp and keeps most
        of the smoothing at rest (the velocity of the smoothed signal is smooth; that of the raw
        input would bring its noise back). That velocity is the low-pass output's, smoothed at
        ``d_cutoff`` Hz: it trails the motion by its own low-pass lag
        ``tau_v``, so when the motion accelerates the lead falls short; ``lead_accel`` g > 0 adds
        ``g (tau + tau_v)`` times the acceleration (the velocity's derivative smoothed at
        ``d_cutoff``) to the velocity the lag is multiplied by: with g = 1 the lead is exact
        to first order on a constant acceleration too. That acceleration (a second derivative)
        carries most of the noise the lead adds: ``accel_cutoff`` > 0 passes it through a second
        low-pass at ``accel_cutoff + accel_beta |acceleration|`` Hz (a One Euro filter on the
        acceleration): at rest and in slow motion it is smoothed heavily (little jitter), in a
        large acceleration it follows (little lag); on a constant acceleration the stage changes
        nothing. ``lead_speed`` s > 0 scales the lead by ``|v|^2 / (|v|^2 + s^2)`` (``v`` the
        velocity it leads along): a row moving much faster than ``s`` keeps the whole lead, a
        slow one little of it. A slow row's lag is small (the low-pass lag times its speed: at
        most ``tau s / 2`` is left, ``tau`` the row's low-pass time constant), while the velocity
        estimate there is mostly the input's slow noise, which the full lead would add back.
        The filter's state stays the uncorrected low-pass."""
        x = np.asarray(positions, float)
        dt = self.default_dt
        if stamp_ns is not None and self.t_ns is not None and stamp_ns > self.t_ns:
            dt = (stamp_ns - self.t_ns) * 1e-9
        if stamp_ns is not None:
            self.t_ns = int(stamp_ns)
        if tracking_state is None and self.all_started:
            # every row valid and continuing: the same arithmetic without the masks
            out, (self.dx, self.fdx, self.fdd, self.fdd2, self.x) = self._advance(
                x, self.raw, self.dx, self.x, self.fdx, self.fdd, self.fdd2, dt, cutoff_scale,
                speed_scale, lead)
            self.raw = x.copy()
            return out
        st = _states(tracking_state, self.n)
        valid = st != NOT_TRACKED
        out = x.copy()
        cont = valid & self.has
        if cont.any():
            dx = (x[cont] - self.raw[cont]) / dt
            ad = self._alpha(self.d_cutoff, dt)
            edx = ad * dx + (1 - ad) * self.dx[cont]
            speed = self.beta * np.linalg.norm(edx, axis=1)
            cutoff = self._cutoff(
                speed, None if cutoff_scale is None else np.asarray(cutoff_scale, float)[cont],
                None if speed_scale is None else np.asarray(speed_scale, float)[cont])[:, None]
            a = self._alpha(cutoff, dt)
            out[cont] = a * x[cont] + (1 - a) * self.x[cont]
            self.dx[cont] = edx
            al = ad
            fdx = al * ((out[cont] - self.x[cont]) / dt) + (1 - al) * self.fdx[cont]
            if self.lead_accel > 0.0:
                self.fdd[cont] = al * ((fdx - self.fdx[cont]) / dt) + (1 - al) * self.fdd[cont]
                if self.accel_cutoff > 0.0:
                    aa = self._accel_alpha(self.fdd[cont], dt)
                    self.fdd2[cont] = aa * self.fdd[cont] + (1 - aa) * self.fdd2[cont]
            self.fdx[cont] = fdx
        start = valid & ~self.has
        self.dx[start] = 0.0
        self.fdx[start] = 0.0
        self.fdd[start] = 0.0
        self.fdd2[start] = 0.0
        self.x[valid] = out[valid]
        self.raw[valid] = x[valid]
        self.has = valid.copy()
        self.all_started = bool(valid.all())
        if lead is not None and cont.any():
            out[cont] += (np.asarray(lead, float)[cont][:, None] * ((1 - a) / a) * dt) * \
                self._lead_velocity(a, al, dt, self.fdx[cont], self.fdd[cont], self.fdd2[cont])
        return out

    def _advance(self, x, raw, dx, fx, fdx0, fdd, fdd2, dt, cutoff_scale, speed_scale, lead):
        """:meth:`update` of rows that are all valid and continuing, on the state arrays given
        (with a leading axis: several filters of these settings stacked, ``dt`` (u, 1)): the
        output and the new state (dx, fdx, fdd, fdd2, x)."""
        dtv = dt[..., None] if np.ndim(dt) else dt
        ad = self._alpha(self.d_cutoff, dtv)
        edx = ad * ((x - raw) / dtv) + (1 - ad) * dx
        speed = self.beta * np.sqrt(np.einsum('...k,...k->...', edx, edx))
        cutoff = self._cutoff(speed, cutoff_scale, speed_scale)
        a = (1.0 / (1.0 + (1.0 / (2 * np.pi * cutoff)) / dt))[..., None]
        out = a * x + (1 - a) * fx
        al = ad
        fdx = al * ((out - fx) / dtv) + (1 - al) * fdx0
        if self.lead_accel > 0.0:
            fdd = al * ((fdx - fdx0) / dtv) + (1 - al) * fdd
            if self.accel_cutoff > 0.0:
                aa = self._accel_alpha(fdd, dt)
                fdd2 = aa * fdd + (1 - aa) * fdd2
        state = (edx, fdx, fdd, fdd2, out.copy())
        if lead is not None:
            out += (np.asarray(lead, float)[..., None] * ((1 - a) / a) * dtv) * \
                self._lead_velocity(a, al, dtv, fdx, fdd, fdd2)
        return out, state

    def _settings(self) -> tuple:
        return (self.n, self.min_cutoff, self.beta, self.d_cutoff, self.lead_accel,
                self.accel_cutoff, self.accel_beta, self.lead_speed, self.default_dt)

    @staticmethod
    def update_many(filters: Sequence['OneEuroFilter'], positions: Sequence[np.ndarray],
                    stamps_ns: Sequence[Optional[int]],
                    cutoff_scales: Sequence[Optional[np.ndarray]],
                    speed_scales: Sequence[Optional[np.ndarray]],
                    leads: Sequence[Optional[np.ndarray]]) -> list:
        """``[f.update(x, None, t, c, s, l) for ...]`` of several distinct filters (several users'
        frames of one time), the same numbers: those whose every row continues (no tracking
        state: the unmasked arithmetic of :meth:`update`) with the same settings and the same
        optional arguments given, as stacked array operations (each element's operations as in
        :meth:`update`; ``_STACK_MIN`` of them at least), the others one by one. An element is
        the exception that filter's update raised (ValueError, ArithmeticError, IndexError; the
        others go on)."""
        out: list = [None] * len(filters)
        groups: dict = {}
        for i, f in enumerate(filters):
            if f.all_started:
                key = (f._settings(), cutoff_scales[i] is None, speed_scales[i] is None,
                       leads[i] is None)
                groups.setdefault(key, []).append(i)
        alone = set(range(len(filters)))
        for members in groups.values():
            if len(members) < _STACK_MIN:
                continue
            try:   # nothing of the filters changes unless the whole group succeeds
                res = OneEuroFilter._update_stacked(
                    [filters[i] for i in members], [positions[i] for i in members],
                    [stamps_ns[i] for i in members], [cutoff_scales[i] for i in members],
                    [speed_scales[i] for i in members], [leads[i] for i in members])
            except _FILTER_ERRORS:
                continue   # one filter's numbers broke the stack: each alone
            for i, r in zip(members, res):
                out[i] = r
            alone.difference_update(members)
        for i in sorted(alone):
            try:
                out[i] = filters[i].update(positions[i], None, stamps_ns[i], cutoff_scales[i],
                                           speed_scales[i], leads[i])
            except _FILTER_ERRORS as e:
                out[i] = e
        return out

    @staticmethod
    def _update_stacked(fs, positions, stamps_ns, cutoff_scales, speed_scales, leads) -> list:
        dts = []
        for f, stamp_ns in zip(fs, stamps_ns):   # each filter's step, as update
            dt = f.default_dt
            if stamp_ns is not None and f.t_ns is not None and stamp_ns > f.t_ns:
                dt = (stamp_ns - f.t_ns) * 1e-9
            dts.append(dt)
        # (np.array of a list of equal-shaped arrays: np.stack's array with less dispatch)
        x = np.array([np.asarray(p, float) for p in positions])
        raw, dx, fx, fdx, fdd, fdd2 = (np.array([getattr(f, k) for f in fs])
                                       for k in ('raw', 'dx', 'x', 'fdx', 'fdd', 'fdd2'))
        out, state = fs[0]._advance(
            x, raw, dx, fx, fdx, fdd, fdd2, np.array(dts)[:, None],
            None if cutoff_scales[0] is None else np.array(cutoff_scales),
            None if speed_scales[0] is None else np.array(speed_scales),
            None if leads[0] is None else np.array([np.asarray(ld, float) for ld in leads]))
        for u, (f, stamp_ns) in enumerate(zip(fs, stamps_ns)):   # the state, as update
            if stamp_ns is not None:
                f.t_ns = int(stamp_ns)
            f.dx, f.fdx, f.fdd, f.fdd2, f.x = (s[u] for s in state)
            f.raw = x[u].copy()
        return list(out)

    def _accel_alpha(self, fdd, dt):
        """Smoothing factor of the acceleration's second stage: cutoff ``accel_cutoff +
        accel_beta |acceleration|`` (a One Euro filter on the acceleration; ``dt`` a step or,
        stacked, (u, 1) steps)."""
        if self.accel_beta <= 0.0:
            return self._alpha(self.accel_cutoff, dt[..., None] if np.ndim(dt) else dt)
        mag = np.sqrt(np.einsum('...k,...k->...', fdd, fdd))
        return self._alpha(self.accel_cutoff + self.accel_beta * mag, dt)[..., None]

    def _lead_velocity(self, a, al, dt, fdx, fdd, fdd2):
        """The velocity the lead multiplies the low-pass lag by (see :meth:`update`), from the
        rows' smoothed velocity and accelerations."""
        if self.lead_accel <= 0.0:
            v = fdx
        else:
            lag = ((1 - a) / a + (1 - al) / al) * dt
            v = fdx + (self.lead_accel * lag) * (fdd2 if self.accel_cutoff > 0.0 else fdd)
        if self.lead_speed > 0.0:
            m2 = np.einsum('...k,...k->...', v, v)
            v = v * (m2 / (m2 + self.lead_speed * self.lead_speed))[..., None]
        return v
