"""One rigid skeleton per user: a robust, tracker-agnostic estimate of the user's segment lengths.

Bones do not change length. The reconstruction (methods B and C, :mod:`.segment_output`) gives
every output posture of a user the same 19 segment lengths; this module estimates them.

* **Evidence**: only *trusted* segments (both ends at or above the reliability threshold) are
  sampled; an occluded, inferred or rejected joint adds nothing, whatever the tracker.
* **Estimate**: per segment, its first trusted lengths; their robust mean (the mean of the
  samples within 3 scaled median absolute deviations of their median, at least 5 mm): a glitch of
  a few frames does not move it. A segment takes samples until its estimate is good enough: at
  least ``min_samples`` and a standard error (sample std / sqrt(n)) at most ``tolerance``, or
  ``samples`` at most. A steady sensor (the real Kinect v2's frame-to-frame length noise is
  ~4 mm) converges in ``min_samples`` frames, so the output's lengths change only in the first
  0.1 s of a user; a noisy one averages more frames (on the sensor-model streams 3 frames cost
  up to 2 points of Eq. 18 on class a against 15).
* **While converging** the output has the *expected final* estimate (:meth:`BoneLengthEstimator.
  predicted`), not the running mean: the samples so far weighed with what the remaining ones are
  expected to average, each segment's mean shrunk towards the body proportions at the user's
  size (one scale from every observed segment; the proportions' spread the most likely on the
  user, so a user or sensor layout they do not fit is hardly shrunk). Its noise is measured on
  the user (pooled over the segments) and, for the first frame, on the sensor's earlier users
  (:class:`SensorLengthNoise`). Once a segment is done, or no more samples can come, it is the
  estimate itself: the converged lengths are the same as without the prediction. On the
  synthetic Azure Kinect bag (1.2 cm joint noise) the whole-track bone-length std of the 1.3 s
  user went from 79 % to 87 % below the tracker's, of the 2-5 s users from 84-90 % to 92 %.
* **Frozen**: when every segment has its samples, or ``settle_s`` seconds after the first trusted
  observation (a segment still unseen then keeps the caller's fallback, e.g. the length prior's
  proportions at the user's size). From then on the lengths are constant.
* **Another person under the same id** (a tracker that re-uses an id): after freezing, each
  frame with at least ``MIN_SEGMENTS`` trusted segments gives ``|median log(observed /
  frozen)|`` over them (a size change: robust to a few segments the sensor gets wrong, which
  the median of the absolute values was not -- on the sensor-model class c / d streams it
  restarted on occlusions and confident failures); its exponential average over ``change_s``
  seconds above ``change`` for at least ``change_s`` means the evidence says this is someone
  else: the estimate starts again from that frame (:attr:`restarts` counts it). Defaults 12 % /
  3 s (signed statistic, 2 s: 1 false restart in 130 sensor-model streams of seeds 0 and 1;
  the sensor's own pose-dependent length changes are a few %). A person of nearly the same size
  is not told apart: the tracker's new id is the evidence then.

:func:`skeleton_bone_lengths` is the importable helper for consumers of the rigid output (e.g.
a URDF publisher): the 19 lengths of one posture, by segment name.
"""
from __future__ import annotations

from typing import Dict, Optional

import numpy as np

from skeleton_core.model import (JOINT_NAMES, NUM_SEGMENTS, SEGMENT_CHILD_INDEX,
                                 SEGMENT_PARENT_INDEX)

from .profile import SEGMENT_NAMES

# a frame's evidence about another person needs this many trusted segments
MIN_SEGMENTS = 6
# the robust mean keeps samples within this many scaled MADs of the median (and within _MIN_DEV)
_MAD_K = 3.0
_MIN_DEV = 0.005
# the predicted final estimate (BoneLengthEstimator.predicted): the pseudo-samples of the pooled
# noise in each segment's, the relative spreads of a user's segments about the proportions tried
_NOISE_DOF = 2.0
_SPREADS = np.geomspace(0.02, 0.5, 12)


def median(x: np.ndarray) -> float:
    """``float(np.median(x))`` of a 1-D array (the same number: the middle sample, or the mean
    of the two middle ones; NaN for a NaN sample or none), without ``np.median``'s wrapper
    (about 10x its sort on the 1-20 samples of a frame's segments)."""
    x = np.sort(x)   # NaN sorts last
    m = x.shape[0]
    if m == 0 or x[m - 1] != x[m - 1]:
        return float('nan')
    h = m // 2
    return float(x[h]) if m % 2 else float((x[h - 1] + x[h]) / 2.0)


def sample_std(x: np.ndarray) -> float:
    """``float(np.std(x, ddof=1))`` of a 1-D array of at least two samples, the same number
    (numpy's own reductions: the mean, the squared deviations' sum, over ``n - 1``) without its
    wrapper's cost."""
    n = x.shape[0]
    d = x - np.add.reduce(x) / n
    return float(np.sqrt(np.add.reduce(d * d) / (n - 1)))


def robust_mean(x: np.ndarray) -> float:
    """The mean of the samples ``x`` (1-D, finite) within ``_MAD_K`` scaled MADs (at least
    ``_MIN_DEV``) of their median; NaN for no samples."""
    x = np.asarray(x, float)
    if x.size == 0:
        return float('nan')
    med = median(x)
    mad = 1.4826 * median(np.abs(x - med))
    keep = np.abs(x - med) <= max(_MAD_K * mad, _MIN_DEV)
    return float(x[keep].mean())


def skeleton_bone_lengths(positions) -> Dict[str, float]:
    """The 19 segment lengths (m) of one posture (20, 3), by segment name (``'HipCenter-Spine'``,
    ...; :data:`skeleton_core.model.SEGMENT_CHILDREN` order). On the reconstruction's output
    (``/posture/reconstructed``, methods B and C) these are the user's constant lengths."""
    p = np.asarray(positions, float)
    if p.shape != (len(JOINT_NAMES), 3):
        raise ValueError(f'expected positions of shape ({len(JOINT_NAMES)}, 3), got {p.shape}')
    L = np.linalg.norm(p[SEGMENT_CHILD_INDEX] - p[SEGMENT_PARENT_INDEX], axis=1)
    return {n: float(v) for n, v in zip(SEGMENT_NAMES, L)}


def lengths_text(lengths) -> str:
    """``'HipCenter-Spine=0.1234 Spine-ShoulderCenter=...'`` (m), or ``'estimating'`` for None
    (a diagnostics value)."""
    if lengths is None:
        return 'estimating'
    return ' '.join(f'{n}={float(v):.4f}' for n, v in zip(SEGMENT_NAMES, lengths))


class SensorLengthNoise:
    """The frame-to-frame segment length noise of one sensor, pooled over the users it has
    seen (shared by their estimators, :attr:`BoneLengthEstimator.noise_memory`): what a new
    user's first frames are taken to have before their own samples tell (the first frame,
    before any, has nothing else). ``variance`` (m^2) is NaN until a user's lengths were
    frozen."""

    def __init__(self):
        self.ss = 0.0    # sum of squared deviations from each segment's mean
        self.dof = 0     # their degrees of freedom

    def add(self, ss: float, dof: int) -> None:
        """A user's pooled sum of squares ``ss`` (m^2) over ``dof`` degrees of freedom."""
        if dof > 0 and np.isfinite(ss) and ss >= 0:
            self.ss += float(ss)
            self.dof += int(dof)

    @property
    def variance(self) -> float:
        return self.ss / self.dof if self.dof > 0 else float('nan')


class BoneLengthEstimator:
    """One user's segment lengths (module docstring). ``samples``: trusted observations per
    segment; ``settle_s``: freeze at the latest this long after the first trusted observation
    (0 = only when every segment has its samples); ``change``: the relative length difference
    taken as another person (0 = never re-estimate); ``change_s``: how long it must persist."""

    def __init__(self, samples: int = 15, settle_s: float = 2.0, change: float = 0.12,
                 change_s: float = 3.0, min_samples: int = 3, tolerance: float = 0.003):
        if samples < 1 or min_samples < 1 or tolerance < 0:
            raise ValueError('samples and min_samples must be >= 1, tolerance >= 0')
        if settle_s < 0 or change < 0 or change_s <= 0:
            raise ValueError('settle_s and change must be >= 0, change_s > 0')
        self.samples = int(samples)
        self.min_samples = min(int(min_samples), self.samples)
        self.tolerance = float(tolerance)
        self.settle_s = float(settle_s)
        self.change = float(change)
        self.change_s = float(change_s)
        self.restarts = 0
        # the sensor's noise seen on earlier users (SensorLengthNoise, shared), or None
        self.noise_memory: Optional[SensorLengthNoise] = None
        self.reset()

    def reset(self) -> None:
        """Forget the estimate (not the count of restarts)."""
        self._buf = np.full((self.samples, NUM_SEGMENTS), np.nan)
        self.counts = np.zeros(NUM_SEGMENTS, int)
        self.done = np.zeros(NUM_SEGMENTS, bool)   # a segment's estimate is good enough
        self._elapsed: Optional[float] = None   # s since the first trusted observation
        self._frames = 0                        # frames observed since then
        self._estimate_key = -1                 # the samples behind self._estimate
        self._estimate = np.full(NUM_SEGMENTS, np.nan)
        self._dt = 1.0 / 30.0                   # the last frame step (s)
        self.frozen: Optional[np.ndarray] = None
        self._evidence = 0.0                    # the averaged disagreement with the frozen lengths
        self._evidence_n = 0

    @property
    def estimate(self) -> np.ndarray:
        """(19,) the robust mean of each segment's samples (NaN where none)."""
        key = int(self.counts.sum())   # samples only accumulate until reset()
        if self._estimate_key != key:
            self._estimate = np.array([robust_mean(self._buf[:c, s])
                                       for s, c in enumerate(self.counts)])
            self._estimate_key = key
        return self._estimate.copy()

    def expected_counts(self, noise2: np.ndarray) -> np.ndarray:
        """(19,) how many samples each segment is expected to have when it is final, given its
        length noise variance ``noise2`` (19,; m^2): the samples the stopping rule needs
        (``min_samples`` to ``samples``, a standard error of ``tolerance``), at most as many as
        the segment's trusted rate so far brings before ``settle_s``; its count when done."""
        n = self.counts.astype(float)
        tol2 = max(self.tolerance, 1e-6) ** 2
        need = np.clip(np.ceil(noise2 / tol2), self.min_samples, self.samples)
        if self.settle_s > 0 and self._elapsed is not None and self._frames > 0:
            left = max(0.0, self.settle_s - self._elapsed) / self._dt
            need = np.minimum(need, n + np.floor(left * n / self._frames))
        return np.where(self.done, n, np.maximum(need, n))

    def _sum_squares(self) -> tuple:
        """(19,) each segment's sum of squared deviations from its mean (m^2), (19,) their
        degrees of freedom."""
        n = self.counts
        x = self._buf   # NaN beyond each segment's samples
        with np.errstate(invalid='ignore'):
            mean = np.where(n > 0, np.nansum(x, axis=0) / np.maximum(n, 1), 0.0)
        d = np.where(np.isfinite(x), x - mean, 0.0)
        ss = np.where(n >= 2, np.sum(d * d, axis=0), 0.0)
        return ss, np.maximum(n - 1, 0)

    def noise_variances(self) -> np.ndarray:
        """(19,) each segment's frame-to-frame length variance (m^2): its sample variance
        shrunk towards the variance pooled over every segment (``_NOISE_DOF`` pseudo-samples),
        that one towards the sensor's on earlier users (:attr:`noise_memory`, one frame's worth:
        ``NUM_SEGMENTS`` pseudo-samples); 0 (nothing predicted) before either is known."""
        ss, dof = self._sum_squares()
        prior = self.noise_memory.variance if self.noise_memory is not None else float('nan')
        if np.isfinite(prior):
            pooled = float((ss.sum() + NUM_SEGMENTS * prior) / (dof.sum() + NUM_SEGMENTS))
        else:
            pooled = float(ss.sum() / dof.sum()) if dof.sum() > 0 else 0.0
        return (ss + _NOISE_DOF * pooled) / (dof + _NOISE_DOF)

    def excess_variances(self) -> np.ndarray:
        """(19,) how much more each segment's estimate varies now than it will when final (m^2):
        ``noise^2 (1/n - 1/N)`` with ``N`` :meth:`expected_counts` (0 where done or unseen)."""
        n = self.counts.astype(float)
        noise2 = self.noise_variances()
        N = self.expected_counts(noise2)
        ex = noise2 * (1.0 / np.maximum(n, 1.0) - 1.0 / np.maximum(N, 1.0))
        return np.where((n > 0) & ~self.done, np.maximum(ex, 0.0), 0.0)

    def predicted(self, proportions) -> np.ndarray:
        """(19,) the expected final estimate of each segment (NaN where none observed): its
        samples so far weighed with what its remaining ones (:meth:`expected_counts`) are
        expected to average, predicted from the whole body: the segment's mean shrunk towards
        ``proportions`` ((19,) or (k, 19) candidates, any scale; None = no prediction, the
        estimate itself) at the user's size (the median of mean / proportion over the observed
        segments), weighed by the mean's standard error and the segments' relative spread about
        the proportions (the most likely of ``_SPREADS`` on the user's observed segments; of
        several candidates, the most likely). A segment farther than 3 standard deviations from
        them (a joint the sensor places elsewhere) is not shrunk. Equal to :attr:`estimate`
        where a segment is done, once no more samples can come, and before the noise is known
        (the first frame of a sensor's first user)."""
        m = self.estimate
        n = self.counts.astype(float)
        seen = n > 0
        if not seen.any() or proportions is None:
            return m
        noise2 = self.noise_variances()
        N = self.expected_counts(noise2)
        se2 = np.where(seen, noise2 / np.maximum(n, 1.0), np.inf)
        best = None
        for r in np.atleast_2d(np.asarray(proportions, float)):
            ok = seen & np.isfinite(r) & (r > 0)
            if not ok.any():
                continue
            c = median(m[ok] / r[ok]) * r
            # the relative spread of the segments' true means about the proportions: the most
            # likely on the observed means (a robust normal likelihood: a segment beyond 3
            # standard deviations counts as at 3), and the proportions that are most likely
            e2 = ((m - c) ** 2)[ok]
            var = se2[ok][None] + (_SPREADS[:, None] * c[ok][None]) ** 2
            nll = np.sum(np.log(var) + np.minimum(e2[None] / var, 9.0), axis=1)
            i = int(np.argmin(nll))
            if best is None or nll[i] < best[0]:
                best = (float(nll[i]), float(_SPREADS[i]) ** 2, c, ok)
        if best is None:
            return m
        _, tau2, c, ok = best
        v = tau2 * c * c
        shrink = ok & ((m - c) ** 2 <= 9.0 * (se2 + v))
        mu = np.where(shrink, (m * v + c * se2) / (v + se2), m)
        rest = np.where(seen, N - n, 0.0)
        return np.where(seen, (n * m + rest * mu) / np.maximum(n + rest, 1.0), m)

    def complete(self) -> bool:
        """Every segment's estimate is good enough, or ``settle_s`` has passed since the first
        sample."""
        if self.done.all():
            return True
        return (self.settle_s > 0 and self._elapsed is not None
                and self._elapsed >= self.settle_s)

    def freeze(self, lengths) -> None:
        """From now on the user's lengths are ``lengths`` (19,; the caller's final lengths, e.g.
        after a length prior); observations only test them for another person."""
        self.frozen = np.asarray(lengths, float).copy()
        self._evidence = 0.0
        self._evidence_n = 0
        if self.noise_memory is not None and self.counts.any():
            ss, dof = self._sum_squares()
            self.noise_memory.add(float(ss.sum()), int(dof.sum()))

    def observe(self, lengths, trusted, dt: float = 1.0 / 30.0) -> bool:
        """One frame: ``lengths`` (19,) observed segment lengths (m), ``trusted`` (19,) bool.
        Returns True when the evidence says this is another person: the estimate restarted,
        with this frame as its first sample."""
        ln = np.asarray(lengths, float)
        ok = np.asarray(trusted, bool) & np.isfinite(ln) & (ln > 1e-3)
        if self.frozen is not None:
            if self.change <= 0.0 or int(ok.sum()) < MIN_SEGMENTS:
                return False
            d = abs(median(np.log(ln[ok] / self.frozen[ok])))
            a = 1.0 - np.exp(-max(dt, 1e-4) / self.change_s)
            self._evidence += a * (d - self._evidence)
            self._evidence_n += 1
            # persistent: averaged over change_s and seen for at least that long
            if self._evidence > self.change and self._evidence_n * max(dt, 1e-4) >= self.change_s:
                self.restarts += 1
                self.reset()
                self._add(ln, ok, dt)
                return True
            return False
        self._add(ln, ok, dt)
        return False

    def _add(self, ln: np.ndarray, ok: np.ndarray, dt: float) -> None:
        self._dt = max(float(dt), 1e-4)
        if self._elapsed is not None:
            self._elapsed += dt
        elif ok.any():
            self._elapsed = 0.0
        if self._elapsed is not None:
            self._frames += 1
        take = ok & ~self.done
        if take.any():
            idx = np.nonzero(take)[0]
            self._buf[self.counts[idx], idx] = ln[idx]
            self.counts[idx] += 1
            for s in idx:
                n = self.counts[s]
                if n >= self.samples:
                    self.done[s] = True
                elif n >= self.min_samples:
                    x = self._buf[:n, s]
                    self.done[s] = sample_std(x) <= self.tolerance * np.sqrt(n)
