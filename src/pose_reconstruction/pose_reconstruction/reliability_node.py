"""``reliability`` node: fills the per-joint reliability (Shum et al. 2013, Eq. 1-8) of every
skeleton. ``/kinect/skeletons`` -> ``/kinect/skeletons_reliability`` (SkeletonArray), one
:class:`~.reliability.ReliabilityEstimator` per user. Positions, orientations, tracking states and
stamps pass through unchanged."""
from __future__ import annotations

from typing import Any, Dict, Optional

import numpy as np

from skeleton_core.rosnode import run_node

from . import reliability_kernels
from .node_common import (RELIABILITY_NAMES, RELIABILITY_SPECS, SkeletonArrayNode,
                          check_reliability_params, common_specs)
from .reliability import ReliabilityEstimator


class _ReliabilityProcessor:
    def __init__(self, **params):
        self.estimator = ReliabilityEstimator(**params)

    def reset(self) -> None:
        self.estimator.reset()

    def process(self, frame):
        r = self.estimator.update(frame.positions, frame.tracking_state)
        return frame.copy(reliability=np.asarray(r, np.float32))


PARAMS = common_specs('/kinect/skeletons', '/kinect/skeletons_reliability') + RELIABILITY_SPECS


class ReliabilityNode(SkeletonArrayNode):
    def __init__(self, **kwargs):
        super().__init__('reliability', PARAMS, **kwargs)

    def validate(self, values: Dict[str, Any]) -> Optional[str]:
        return check_reliability_params(values)

    def make_processor(self, values: Dict[str, Any]):
        return _ReliabilityProcessor(**{k: values[k] for k in RELIABILITY_NAMES})

    def kernels(self):
        return [reliability_kernels.warm_up]   # Eq. 1-8


def main(args=None) -> int:
    return run_node(ReliabilityNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
