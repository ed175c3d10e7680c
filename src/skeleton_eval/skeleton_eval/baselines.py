"""Baseline methods: the Kinect skeleton as reported and the two usual joint filters. They are
registered in :mod:`.registry` as ``raw``, ``holt`` and ``one_euro``."""
from __future__ import annotations

from skeleton_core.conversions import SkeletonFrame
from skeleton_core.filters import HOLT_DEFAULTS, ONE_EURO_DEFAULTS, HoltFilter, OneEuroFilter


class RawMethod:
    """The Kinect skeleton unchanged."""

    name = 'raw'

    def reset(self):
        pass

    def process(self, frame: SkeletonFrame) -> SkeletonFrame:
        return frame


class HoltMethod:
    """Kinect SDK v1 double exponential joint filter (filters.HoltFilter)."""

    name = 'holt'

    def __init__(self, **params):
        self.params = {**HOLT_DEFAULTS, **params}
        self.filter = HoltFilter(**self.params)

    def reset(self):
        self.filter.reset()

    def process(self, frame: SkeletonFrame) -> SkeletonFrame:
        return frame.copy(positions=self.filter.update(frame.positions, frame.tracking_state))


class OneEuroMethod:
    """One Euro filter per joint (filters.OneEuroFilter)."""

    name = 'one_euro'

    def __init__(self, **params):
        self.params = {**ONE_EURO_DEFAULTS, **params}
        self.filter = OneEuroFilter(**self.params)

    def reset(self):
        self.filter.reset()

    def process(self, frame: SkeletonFrame) -> SkeletonFrame:
        return frame.copy(positions=self.filter.update(frame.positions, frame.tracking_state,
                                                       frame.stamp_ns))
