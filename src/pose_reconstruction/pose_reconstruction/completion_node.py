"""``completion`` node: method A, database completion (Shum & Ho 2012).
``/kinect/skeletons_reliability`` -> ``/posture/completed`` (SkeletonArray). Missing / unreliable
joints (reliability below ``reliable_threshold``) and their orientations are substituted from the
nearest database posture in a ``pca_dims``-dimensional PCA space. Input skeletons without a
reliability get one estimated here (Eq. 1-8)."""
from __future__ import annotations

from typing import Any, Dict, Optional

from skeleton_core.params import specs
from skeleton_core.rosnode import run_node

from .completion import CompletionConfig
from .node_common import (DATABASE_SPEC, RELIABILITY_NAMES, RELIABILITY_SPECS, DatabaseNode,
                          check_reliability_params, common_specs)
from .reconstructor import Reconstructor, ReconstructorConfig

SPECS = ([DATABASE_SPEC] + specs(CompletionConfig)
         + specs(ReconstructorConfig, only=['use_input_reliability']))
_NAMES = [s.name for s in SPECS if s.name != 'database'] + RELIABILITY_NAMES
PARAMS = (common_specs('/kinect/skeletons_reliability', '/posture/completed') + SPECS
          + RELIABILITY_SPECS)


class CompletionNode(DatabaseNode):
    def __init__(self, database_obj=None, **kwargs):
        super().__init__('completion', PARAMS, database_obj=database_obj, **kwargs)

    def validate(self, values: Dict[str, Any]) -> Optional[str]:
        return check_reliability_params(values)

    def make_processor(self, values: Dict[str, Any]):
        return Reconstructor(self.db, method='A', **{k: values[k] for k in _NAMES})


def main(args=None) -> int:
    return run_node(CompletionNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
