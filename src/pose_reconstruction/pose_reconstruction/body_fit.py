"""Heading and height when few joints are reliable (e.g. hands and feet only, Table III).

No segment has two reliable ends, so no length, height or (with the hips and shoulders
unreliable) heading can be measured, and the positions reported for the unreliable joints must
not decide them (:mod:`.reconstructor`):

* height — until a frame has every joint tracked, the median over the first ``height_frames``
  such frames of a scale-invariant database fit (:meth:`.search.DatabaseSearch.knn_scaled`) becomes
  the reliability estimator's height prior;
* heading — the last heading of the reliable torso is kept (at the start, the best of
  ``yaw_search`` headings against the database) and turned each frame by ``yaw_rate`` times the
  rotation that best fits the reliable joints to the database
  (:meth:`.search.DatabaseSearch.database_yaw`, the ``yaw_neighbours`` best postures averaged).

Both need at least three reliable joints.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from skeleton_core.geometry import facing_yaw
from skeleton_core.model import (HIP_LEFT, HIP_RIGHT, SEGMENT_CHILD_INDEX, SEGMENT_PARENT_INDEX,
                                 SHOULDER_LEFT, SHOULDER_RIGHT)
from skeleton_core.params import check, param

MIN_FIT_JOINTS = 3  # the fewest points that fix a rotation and a scale


def torso_weight(w: np.ndarray) -> float:
    """The weight of the better of the hip and shoulder lines (a line counts with the smaller
    reliability of its two joints): what the heading is measured from."""
    return max(min(w[HIP_LEFT], w[HIP_RIGHT]), min(w[SHOULDER_LEFT], w[SHOULDER_RIGHT]))


@dataclass
class BodyFitConfig:
    """Parameters of :class:`BodyFit` (their reconstruction parameter names)."""

    height_frames: int = param(
        30, 'no frame with every joint tracked yet: frames of scale-invariant database fits '
        "whose median is taken as the user's height (query scale, standard-body lengths), then "
        'kept; 0 = off (standard height)', range=(0, 100000), public=False)
    yaw_rate: float = param(
        0.5, 'few reliable joints (hips, shoulders and every segment unreliable): fraction per '
        'frame of the heading correction that best fits the reliable joints to the database; '
        '0 = keep the last heading', range=(0.0, 1.0), public=False)
    yaw_search: int = param(
        12, 'few reliable joints from the first frame: headings tried against the database '
        '(from the one the unreliable torso gives); 0 = take that one', range=(0, 360),
        public=False)
    yaw_neighbours: int = param(
        5, 'few reliable joints: database postures whose best rotations (each a weighted 2-D '
        'Procrustes of the reliable joints) are averaged into the heading correction',
        range=(1, 1000), public=False)


class BodyFit:
    """One user's heading and height fits against the database (module docstring)."""

    def __init__(self, search, preparer, reliability, reliable_threshold: float,
                 config: BodyFitConfig):
        check(config)
        self.search = search
        self.preparer = preparer
        self.reliability = reliability
        self.reliable_threshold = float(reliable_threshold)
        self.height_frames = int(config.height_frames)
        self.yaw_rate = float(config.yaw_rate)
        self.yaw_search = int(config.yaw_search)
        self.yaw_neighbours = int(config.yaw_neighbours)
        self.reset()

    def reset(self) -> None:
        self.yaw_state: Optional[float] = None
        self.height_fits: list = []
        self.height_done = self.height_frames == 0

    def height_settled(self) -> bool:
        return self.height_done or self.reliability.height_measured

    def few_reliable(self, w: np.ndarray) -> tuple:
        """``(few, fit_ok)``: the torso is unreliable and no segment has two reliable ends; at
        least three joints are reliable (a heading / scale fit needs them: two leave the rotation
        about their line and, with the translation free, the scale undetermined)."""
        rel = w >= self.reliable_threshold
        few = (torso_weight(w) < self.reliable_threshold
               and not (rel[SEGMENT_PARENT_INDEX] & rel[SEGMENT_CHILD_INDEX]).any())
        return few, int(rel.sum()) >= MIN_FIT_JOINTS

    def heading_in(self, obs: np.ndarray, w: np.ndarray, height: float,
                   translate: bool, few: Optional[tuple] = None) -> Optional[float]:
        """The heading to prepare this frame's query with, in the few-reliable-joints regime:
        the one kept from earlier frames (searched at the start). None outside that regime.
        ``few``: :meth:`few_reliable` of ``w`` when already known."""
        few, fit_ok = self.few_reliable(w) if few is None else few
        if not few:
            return None
        if self.yaw_state is None and self.yaw_search > 0 and fit_ok:
            self.yaw_state = self.search_yaw(obs, w, height, translate)
        return self.yaw_state

    def update(self, query: np.ndarray, w: np.ndarray, height: float, yaw: float,
               translate: bool, few: Optional[tuple] = None) -> None:
        """After this frame's query (prepared at heading ``yaw``): correct the kept heading from
        the database, and fit the height while it is not known. ``few``: :meth:`few_reliable`
        of ``w`` when already known."""
        few, fit_ok = self.few_reliable(w) if few is None else few
        theta = None
        if few and fit_ok and self.yaw_rate > 0.0:
            theta = self.database_yaw(query, w, translate, scaled=not self.height_settled())
        self.yaw_state = yaw if theta is None else yaw - self.yaw_rate * theta
        if not self.height_settled():
            self.fit_height(query, w, height, translate)

    def database_yaw(self, query: np.ndarray, w: np.ndarray, centre: bool,
                     scaled: bool = False) -> Optional[float]:
        """:meth:`.search.DatabaseSearch.database_yaw` with this user's settings."""
        return self.search.database_yaw(query, w, centre, scaled, self.yaw_neighbours,
                                        self.reliable_threshold)

    def search_yaw(self, obs: np.ndarray, w: np.ndarray, height: float,
                    translate: bool) -> float:
        """The heading, among ``yaw_search`` evenly spaced ones, whose query is nearest to the
        database: for a user whose torso has not been reliable yet. The unreliable hip and
        shoulder lines are only a hypothesis: the spacing starts at the heading they give. The
        distance is that of the nearest neighbour, scale-invariant while the height is not known
        (:meth:`.search.DatabaseSearch.knn_scaled`), else Eq. 9."""
        yaw0 = float(facing_yaw(obs, np.maximum(w, 1e-3)))
        best, best_d = yaw0, np.inf
        wr = np.where(w >= self.reliable_threshold, w, 0.0)
        for yaw in yaw0 + np.arange(self.yaw_search) * (2.0 * np.pi / self.yaw_search):
            q = self.preparer.prepare(obs, w, height, yaw=float(yaw)).query
            if self.height_settled():
                d = float(self.search.knn_search(q, w, translate=translate)[1][0])
            else:
                d = float(self.search.knn_scaled(q, wr, translate, (height / 2.3, height))[1][0])
            if d < best_d:
                best, best_d = float(yaw), d
        return best

    def fit_height(self, query: np.ndarray, w: np.ndarray, height: float,
                    translate: bool) -> None:
        """While the sensor has not measured the user's height (no frame with every joint
        tracked), estimate it from the database: the scale-invariant KNN search (Eq. 9 minimised
        over a uniform scale of the query's reliable joints) gives the scale at which the
        query's reliable joints best match a database posture of the standard body; the user
        is ``height / scale`` tall (the query was scaled by standard / ``height``). The median
        over the first ``height_frames`` such frames becomes the reliability estimator's height
        prior (query scale and standard-body lengths), then stays. Only frames where no segment
        has two reliable ends count: then no length can be measured, and every reliable joint
        is below an unreliable one, so the query scaled all of them by the height (a joint below
        reliable ones is retargeted to the standard lengths instead and says nothing about the
        user's size)."""
        rel = w >= self.reliable_threshold
        if rel.sum() < MIN_FIT_JOINTS or (rel[SEGMENT_PARENT_INDEX] & rel[SEGMENT_CHILD_INDEX]).any():
            return
        lo, hi = 1.0, 2.3   # the reliability estimator's height range
        _, dist, s = self.search.knn_scaled(query, np.where(rel, w, 0.0), translate,
                                          (height / hi, height / lo))
        inv = 1.0 / (dist + 1e-6)
        scale = float(inv @ s / inv.sum())
        self.height_fits.append(height / scale)
        self.reliability.set_height_prior(float(np.median(self.height_fits)))
        if len(self.height_fits) >= self.height_frames:
            self.height_done = True
