"""The user's segment lengths from two estimates weighed by their expected errors.

The segment output's lengths (:mod:`.segment_output`) are the mean observed lengths of the
segments while both ends are tracked. A Kinect reports a tracked joint a few cm away from the
joint centre (``length_offset_sigma``, m per axis), and that offset stays with the session: the
observed length of a segment is off by the component of ``o_child - o_parent`` along it, which
averaging frames does not remove. Its expected error variance is ``2 sigma^2`` (two independent
joint offsets, one axis each), halved when the left and right limbs share their mean
(``symmetric_lengths``: independent offsets on the two sides). On an upper arm of 28 cm with
offsets of 3 cm that is a 3 cm (11 %) error, larger than how much people differ.

The second estimate is the proportion of the body: the database clips' own bodies (before
retargeting; :func:`skeleton_data.database.length_ratios`) give per segment the mean and the
spread across people of length / standing height; times the user's measured height (whose
relative error is ``length_height_error``) that predicts the length with the variance
``(ratio * height)^2 * ((std / mean)^2 + length_height_error^2)``.

The output length is their inverse-variance (minimum expected error) combination::

    L = (L_obs * var_prior + L_prior * var_obs) / (var_obs + var_prior)

A segment never observed with both ends tracked takes the prior alone. With a database that lacks
the ratios (built before they were stored) the observed lengths are used as before.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from skeleton_core.model import MIRROR, NUM_SEGMENTS, SEGMENT_CHILDREN
from skeleton_core.params import check, param

# segments with a mirror image (limbs and girdle segments), whose lengths are shared
_MIRRORED = np.array([MIRROR[c] != c for c in SEGMENT_CHILDREN])


@dataclass
class LengthPriorConfig:
    """Parameters of :class:`LengthPrior` (their reconstruction parameter names)."""

    length_prior: bool = param(
        True, "segments: combine the observed segment lengths with the database bodies' "
        'proportions at the measured height, each weighted by its expected error '
        '(length_prior.py); off = observed lengths only')
    length_offset_sigma: float = param(
        0.03, 'length_prior: expected joint-centre offset of a tracked joint (m per axis), the '
        'error of an observed length', range=(1e-4, 1.0))
    length_offset_online: bool = param(
        True, 'length_prior: estimate the offset scale from the user\'s own observed lengths '
        'against the prior (method of moments over the observed segments) instead of '
        'length_offset_sigma')
    length_offset_min_segments: int = param(
        6, 'length_prior: observed segments (both ends reliable) needed before the prior is used '
        '(the user\'s size is fitted to them)', range=(1, NUM_SEGMENTS))


class LengthPrior:
    """``ratio_mean`` / ``ratio_std`` (19,): the database bodies' segment length / height."""

    def __init__(self, config: LengthPriorConfig, ratio_mean, ratio_std,
                 symmetric: bool = True):
        check(config)
        self.mean = np.asarray(ratio_mean, float).reshape(NUM_SEGMENTS)
        self.rel_std = np.asarray(ratio_std, float).reshape(NUM_SEGMENTS) / np.maximum(self.mean,
                                                                                        1e-9)
        if not (np.all(np.isfinite(self.mean)) and np.all(self.mean > 0)
                and np.all(np.isfinite(self.rel_std))):
            raise ValueError('length prior: the ratios must be finite and positive')
        sides = np.where(_MIRRORED & bool(symmetric), 2.0, 1.0)
        self.obs_factor = 2.0 / sides  # observed-length variance / offset variance per axis
        self.sigma2 = float(config.length_offset_sigma) ** 2
        self.online = bool(config.length_offset_online)
        self.min_segments = int(config.length_offset_min_segments)
        self.height = float('nan')  # the last size fitted (m, 'height' of the ratios)
        self.offset_sigma = float(config.length_offset_sigma)  # the last scale used (m)

    @classmethod
    def from_meta(cls, config: LengthPriorConfig, meta: Optional[dict],
                  symmetric: bool = True) -> Optional['LengthPrior']:
        """From a database's ``meta`` (None when off or the ratios are missing / unusable)."""
        if not config.length_prior or not meta:
            return None
        mean, std = meta.get('length_ratio_mean'), meta.get('length_ratio_std')
        if mean is None or std is None:
            return None
        try:
            return cls(config, mean, std, symmetric)
        except ValueError:
            return None

    def fuse(self, observed: np.ndarray, counts: np.ndarray) -> np.ndarray:
        """(19,) the combined lengths: ``observed`` the mean observed lengths, ``counts`` the
        number of reliable observations behind each (0: the prior alone). Unchanged while fewer
        than ``length_offset_min_segments`` segments are observed."""
        L = np.asarray(observed, float)
        seen = np.asarray(counts) > 0
        if int(seen.sum()) < self.min_segments:
            return L
        mu, rho2 = self.mean, self.rel_std ** 2
        s2 = self.sigma2
        h = float(np.dot(mu[seen], L[seen]) / np.dot(mu[seen], mu[seen]))
        for it in range(2):
            # the user's size: weighted least squares of the observed lengths on the ratios
            w = 1.0 / (self.obs_factor * s2 + (mu * h) ** 2 * rho2)
            wm = (w * mu)[seen]
            h = float(np.dot(wm, L[seen]) / np.dot(wm, mu[seen]))
            var_h = 1.0 / float(np.dot(wm, mu[seen]))
            var_prior = (mu * h) ** 2 * rho2 + mu * mu * var_h
            if self.online and it == 0:
                # the offset scale from the spread of the observed lengths about the prior
                z = (L - mu * h) ** 2 - var_prior
                s2 = max(float(np.sum(z[seen]) / np.sum(self.obs_factor[seen])), 0.0)
        self.offset_sigma = float(np.sqrt(s2))
        self.height = h
        var_obs = self.obs_factor * s2
        wp = np.where(seen, var_obs / np.maximum(var_obs + var_prior, 1e-12), 1.0)
        return (1.0 - wp) * L + wp * (mu * h)
