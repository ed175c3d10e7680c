"""The user's segment lengths from two estimates weighed by their expected errors.

The segment output's lengths (:mod:`.segment_output`) are the mean observed lengths of the
segments while both ends are tracked. A Kinect reports a tracked joint a few cm away from the
joint centre, and that offset stays with the session: the observed length of a segment is off by
the component of ``o_child - o_parent`` along it, which averaging frames does not remove. With
offsets of ``sigma`` m per axis its error variance is ``2 sigma^2`` (two independent joint
offsets, one axis each), halved when the left and right sides are both observed and share their
mean (``symmetric_lengths``). On an upper arm of 28 cm with offsets of 3 cm that is 3 cm (11 %),
more than people differ in their proportions.

**The offset scale** is measured on the user (``length_offset_online``): the two sides of a body
have the same lengths but independent offsets, so the observed left-minus-right difference of a
mirrored segment has the variance ``4 sigma^2``; ``sigma^2`` is the mean of ``(L_left -
L_right)^2 / 4`` over the mirrored pairs observed on both sides (``length_offset_sigma`` until one
is, or when off).

**The prior** is the body's proportions: the database clips' own bodies (before retargeting;
:func:`skeleton_data.database.length_ratios`) give per segment the mean ``r`` and the spread
across clips ``s`` of length / standing height. The user's size ``h`` is fitted to the observed
segments (weighted least squares of the observed lengths on ``r``; variance ``var_h``), so the prior
needs no separately measured height (in the occlusion classes the legs are rarely all tracked).
Its variance is ``var_prior = k (r h)^2 (s / r)^2 + r^2 var_h``. ``k >= 1`` checks the prior against
the user: the squared differences ``z = (L_obs - r h)^2`` have the expectation ``var_obs +
var_prior``, so ``k = max(1, sum(z - var_obs - r^2 var_h) / sum((r h)^2 (s / r)^2))`` over the
observed segments. A sensor whose joints sit elsewhere on the body than the database's (another
skeleton layout: other proportions, the same on both sides) raises ``k`` and the prior loses its
weight, where offsets (independent per side) do not.

**The layout.** The proportions must be those of the joint centres the input has. With a
learned sensor correction applied (:mod:`.correction`) the input's joints sit where the
correction's reference puts them (the Vicon Plug-in-Gait centres on UI-PRMD), not where the
database's bodies do; the correction then carries its reference's proportions (mean and spread
over its training subjects, :func:`.correction.reference_proportions`) and they replace the
database's (the hands, which that reference lacks, keep the database's). On the real UI-PRMD
recordings the database's proportions moved the corrected lengths away from what the sensor
measures (the hip segments by ~0.7 cm, the neck ~0.7 cm; docs/research, accuracy, round 5).

**Converging lengths.** While the observed lengths are still being estimated their means vary
more than they will when final (a few noisy or settling first frames); the caller passes that
excess variance per side (:meth:`.BoneLengthEstimator.excess_variances`), and the offset scale
(the left/right differences less it), the size fit, ``k`` and the outlier test take it in, so
they are judged as on the final lengths (the sampling noise of the first means otherwise reads as
joint-centre offsets, inflating the offset scale and moving every output length). The output
weights stay the final ones; with no excess (converged) nothing changes. A side that is wrong
but steady for its first frames (a real Kinect v2 leg settling over 2-4 frames) shows no
excess and still inflates the scale until its later samples come.

The output length is the inverse-variance (minimum expected error) combination::

    L = (L_obs * var_prior + r h * var_obs) / (var_obs + var_prior)

A segment whose observed length lies more than ``length_prior_outlier`` standard deviations
(``sqrt(var_obs + var_prior)``) from ``r h`` keeps its observed length and is left out of the size
fit and of ``k`` (a joint the sensor places elsewhere on that segment than the database's bodies:
the real Kinect v2 spine, 18 cm longer than the CMU one). A segment never observed with both ends
tracked (on either side) takes ``r h``; with fewer than
``length_offset_min_segments`` observed segments, or a database without the ratios (built before
they were stored), the observed lengths are used as before.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from skeleton_core.model import MIRROR, NUM_SEGMENTS, SEGMENT_CHILDREN
from skeleton_core.params import check, param

# the mirror image of each segment (itself on the midline)
_MIRROR_SEG = np.array([SEGMENT_CHILDREN.index(MIRROR[c]) for c in SEGMENT_CHILDREN])
_MIRRORED = _MIRROR_SEG != np.arange(NUM_SEGMENTS)
# the least offset variance (m^2 per axis) measured once the sampling variance is taken out
_MIN_SIGMA2 = 1e-8


@dataclass
class LengthPriorConfig:
    """Parameters of :class:`LengthPrior` (their reconstruction parameter names)."""

    length_prior: bool = param(
        True, "segments: combine the observed segment lengths with the database bodies' "
        "proportions at the user's fitted size, each weighted by its expected error "
        '(length_prior.py); off = observed lengths only', public=False)
    length_offset_sigma: float = param(
        0.03, 'length_prior: expected joint-centre offset of a tracked joint (m per axis), the '
        'error of an observed length (with length_offset_online: until measured)',
        range=(1e-4, 1.0), public=False)
    length_offset_online: bool = param(
        True, 'length_prior: measure the offset scale on the user, from the differences between '
        'the observed left and right lengths of the mirrored segments', public=False)
    length_prior_outlier: float = param(
        3.0, 'length_prior: a segment whose observed length is farther from the prior than this '
        'many standard deviations (offsets and prior spread) keeps its observed length and is '
        'left out of the size fit', range=(0.5, 1e6), public=False)
    length_offset_min_segments: int = param(
        6, 'length_prior: observed segments (both ends reliable) needed before the prior is used '
        "(the user's size is fitted to them)", range=(1, NUM_SEGMENTS), public=False)


class LengthPrior:
    """``ratio_mean`` / ``ratio_std`` (19,): the database bodies' segment length / height;
    ``symmetric``: the left and right sides share their lengths."""

    def __init__(self, config: LengthPriorConfig, ratio_mean, ratio_std,
                 symmetric: bool = True):
        check(config)
        self.mean = np.asarray(ratio_mean, float).reshape(NUM_SEGMENTS)
        std = np.asarray(ratio_std, float).reshape(NUM_SEGMENTS)
        if not (np.all(np.isfinite(self.mean)) and np.all(self.mean > 0)
                and np.all(np.isfinite(std)) and np.all(std >= 0)):
            raise ValueError('length prior: the ratios must be finite and positive')
        self.rel_var = (std / self.mean) ** 2
        self.symmetric = bool(symmetric)
        self.sigma2 = float(config.length_offset_sigma) ** 2
        self.online = bool(config.length_offset_online)
        self.min_segments = int(config.length_offset_min_segments)
        self.outlier2 = float(config.length_prior_outlier) ** 2
        self.outliers = np.zeros(NUM_SEGMENTS, bool)  # the last segments left to the sensor
        self.offset_sigma = float(config.length_offset_sigma)  # the last scale used (m)
        self.height = float('nan')  # the last size fitted (m)
        self.prior_scale = float('nan')  # the last k

    @classmethod
    def from_meta(cls, config: LengthPriorConfig, meta: Optional[dict],
                  symmetric: bool = True,
                  layout: Optional[dict] = None) -> Optional['LengthPrior']:
        """From a database's ``meta`` (None when off or the ratios are missing / unusable).
        ``layout``: the meta of a sensor correction applied to the input; where it carries its
        reference's proportions (:func:`.correction.reference_proportions`) they replace the
        database's (module docstring, "The layout")."""
        if not config.length_prior or not meta:
            return None
        mean, std = meta.get('length_ratio_mean'), meta.get('length_ratio_std')
        if mean is None or std is None:
            return None
        try:
            mean, std = layout_ratios(mean, std, layout)
            return cls(config, mean, std, symmetric)
        except (ValueError, TypeError):
            return None

    def offset_variance(self, sides: np.ndarray, seen: np.ndarray,
                        excess: Optional[np.ndarray] = None) -> float:
        """``sigma^2`` (m^2 per axis) from the left/right differences of the observed lengths
        ``sides`` (19,) where ``seen`` (module docstring), less ``excess`` (19,), the sampling
        variance of each side's length beyond its final one (the estimate still converging);
        the parameter when not measurable."""
        pair = _MIRRORED & seen & seen[_MIRROR_SEG]
        if not self.online or not pair.any():
            return self.sigma2
        d = sides[pair] - sides[_MIRROR_SEG][pair]
        d2 = d * d
        if excess is not None:
            d2 = d2 - excess[pair] - excess[_MIRROR_SEG][pair]
        return max(float(np.mean(d2)) / 4.0, _MIN_SIGMA2)

    def fuse(self, sides: np.ndarray, counts: np.ndarray,
             excess: Optional[np.ndarray] = None) -> np.ndarray:
        """(19,) the output lengths from ``sides`` (19,) the mean observed length of each segment
        (any value where ``counts`` is 0) and ``counts`` (19,) the reliable observations behind
        them (module docstring). ``excess`` (19,; m^2): while the lengths are still being
        estimated, how much more each side's length varies now than it will when final
        (:meth:`.BoneLengthEstimator.excess_variances`): the offset scale, the user's size, the
        prior's check and the outliers are then judged as they will be on the final lengths
        (without it, a few noisy first frames inflated the offset scale ten-fold and moved every
        output length); 0 once final."""
        L = np.asarray(sides, float)
        seen = np.asarray(counts) > 0
        ex = np.zeros(NUM_SEGMENTS) if excess is None else np.where(
            seen, np.nan_to_num(np.asarray(excess, float), nan=0.0), 0.0)
        s2 = self.offset_variance(L, seen, ex)
        nobs = np.ones(NUM_SEGMENTS)  # sides behind each observed length
        if self.symmetric:
            other = L[_MIRROR_SEG]
            both = seen & seen[_MIRROR_SEG] & _MIRRORED
            L = np.where(both, 0.5 * (L + other), np.where(seen, L, other))
            ex = np.where(both, 0.25 * (ex + ex[_MIRROR_SEG]),
                          np.where(seen, ex, ex[_MIRROR_SEG]))
            nobs = np.where(both, 2.0, 1.0)
            seen = seen | seen[_MIRROR_SEG]
        if int(seen.sum()) < self.min_segments:
            if self.symmetric:  # as without the prior
                L = 0.5 * (np.asarray(sides, float) + np.asarray(sides, float)[_MIRROR_SEG])
            return L
        r = self.mean
        var_obs = 2.0 * s2 / nobs
        var_now = var_obs + ex   # the observed lengths' error as they are now
        k = 1.0
        use = seen.copy()
        h = float(np.dot(r[use], L[use]) / np.dot(r[use], r[use]))
        var_p0 = (r * h) ** 2 * self.rel_var
        var_h = 0.0
        for _ in range(3):
            # segments the prior cannot describe (beyond length_prior_outlier standard
            # deviations): observed lengths only, and left out of the size and of k
            zs = (L - r * h) ** 2 / (var_now + k * var_p0 + r * r * var_h)
            use = seen & (zs <= self.outlier2)
            if int(use.sum()) < self.min_segments:
                use = seen
            # the user's size: weighted least squares of the observed lengths on the ratios
            wr = (r / (var_now + k * var_p0))[use]
            h = float(np.dot(wr, L[use]) / np.dot(wr, r[use]))
            var_h = 1.0 / float(np.dot(wr, r[use]))
            var_p0 = (r * h) ** 2 * self.rel_var
            # the prior checked against the user: its spread at least as the database's
            z = (L - r * h) ** 2 - var_now - r * r * var_h
            k = max(1.0, float(np.sum(z[use]) / max(float(np.sum(var_p0[use])), 1e-12)))
        var_prior = k * var_p0 + r * r * var_h
        self.offset_sigma, self.height, self.prior_scale = float(np.sqrt(s2)), h, k
        self.outliers = seen & ~use
        wp = np.where(use, var_obs / np.maximum(var_obs + var_prior, 1e-12), 0.0)
        wp = np.where(seen, wp, 1.0)
        return (1.0 - wp) * L + wp * (r * h)


def layout_ratios(mean, std, layout: Optional[dict]) -> tuple:
    """(mean, std) (19,) of the database's ratios ``mean`` / ``std`` with the segments a
    correction's ``layout`` meta describes replaced by its reference's proportions, rescaled to
    the database's sum over those segments (the prior fits the user's size, so only proportions
    matter), their spread at least the database's relative spread; the database's values where
    the reference has no segment (the hands), and all of them without a usable layout."""
    mean = np.asarray(mean, float).reshape(NUM_SEGMENTS).copy()
    std = np.asarray(std, float).reshape(NUM_SEGMENTS).copy()
    if not layout:
        return mean, std
    lm, ls = layout.get('reference_length_ratio_mean'), layout.get('reference_length_ratio_std')
    if lm is None or ls is None or len(lm) != NUM_SEGMENTS or len(ls) != NUM_SEGMENTS:
        return mean, std
    lm = np.array([np.nan if v is None else v for v in lm], float)
    ls = np.array([np.nan if v is None else v for v in ls], float)
    have = np.isfinite(lm) & (lm > 0) & np.isfinite(ls) & (ls >= 0)
    if not have.any():
        return mean, std
    scale = mean[have].sum() / lm[have].sum()
    rel = std / mean  # the database bodies' relative spread across people
    mean[have] = lm[have] * scale
    # a correction's few training subjects underestimate how proportions vary between people:
    # their spread, at least the database bodies' relative spread
    std[have] = np.maximum(ls[have] * scale, mean[have] * rel[have])
    return mean, std
