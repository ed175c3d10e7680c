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


def robust_mean(x: np.ndarray) -> float:
    """The mean of the samples ``x`` (1-D, finite) within ``_MAD_K`` scaled MADs (at least
    ``_MIN_DEV``) of their median; NaN for no samples."""
    x = np.asarray(x, float)
    if x.size == 0:
        return float('nan')
    med = float(np.median(x))
    mad = 1.4826 * float(np.median(np.abs(x - med)))
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
        self.reset()

    def reset(self) -> None:
        """Forget the estimate (not the count of restarts)."""
        self._buf = np.full((self.samples, NUM_SEGMENTS), np.nan)
        self.counts = np.zeros(NUM_SEGMENTS, int)
        self.done = np.zeros(NUM_SEGMENTS, bool)   # a segment's estimate is good enough
        self._elapsed: Optional[float] = None   # s since the first trusted observation
        self.frozen: Optional[np.ndarray] = None
        self._evidence = 0.0                    # the averaged disagreement with the frozen lengths
        self._evidence_n = 0

    @property
    def estimate(self) -> np.ndarray:
        """(19,) the robust mean of each segment's samples (NaN where none)."""
        return np.array([robust_mean(self._buf[:c, s]) for s, c in enumerate(self.counts)])

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

    def observe(self, lengths, trusted, dt: float = 1.0 / 30.0) -> bool:
        """One frame: ``lengths`` (19,) observed segment lengths (m), ``trusted`` (19,) bool.
        Returns True when the evidence says this is another person: the estimate restarted,
        with this frame as its first sample."""
        ln = np.asarray(lengths, float)
        ok = np.asarray(trusted, bool) & np.isfinite(ln) & (ln > 1e-3)
        if self.frozen is not None:
            if self.change <= 0.0 or int(ok.sum()) < MIN_SEGMENTS:
                return False
            d = abs(float(np.median(np.log(ln[ok] / self.frozen[ok]))))
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
        if self._elapsed is not None:
            self._elapsed += dt
        elif ok.any():
            self._elapsed = 0.0
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
                    self.done[s] = float(np.std(x, ddof=1)) <= self.tolerance * np.sqrt(n)
