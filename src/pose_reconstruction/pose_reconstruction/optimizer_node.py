"""``optimizer`` node: methods B / C, the natural-posture-space optimizer (Shum et al. 2013).
``/kinect/skeletons_reliability`` -> ``/posture/reconstructed`` (SkeletonArray). Input skeletons
without a reliability get one estimated here (Eq. 1-8); ``method`` B ignores it."""
from __future__ import annotations

from typing import Any, Dict, Optional

from skeleton_core.params import ParamSpec, specs
from skeleton_core.rosnode import run_node

from skeleton_core.jit import lazy_module
from .node_common import (CORRECTION_SPECS, DATABASE_SPEC, RELIABILITY_NAMES, RELIABILITY_SPECS,
                          DatabaseNode, check_reliability_params, common_specs)
from .optimizer import OptimizerConfig
from .reconstructor import Reconstructor, ReconstructorConfig

SPECS = ([DATABASE_SPEC,
          ParamSpec('method', 'C', 'C: reliability-weighted (paper); B: every reliability 1',
                    choices=('B', 'C'))]
         + specs(OptimizerConfig) + specs(ReconstructorConfig))
CORE_NAMES = [s.name for s in SPECS if s.name not in ('database', 'method')]
PARAMS = (common_specs('/kinect/skeletons_reliability', '/posture/reconstructed') + SPECS
          + RELIABILITY_SPECS + CORRECTION_SPECS)


class OptimizerNode(DatabaseNode):
    def __init__(self, database_obj=None, **kwargs):
        super().__init__('optimizer', PARAMS, database_obj=database_obj, **kwargs)

    def validate(self, values: Dict[str, Any]) -> Optional[str]:
        return check_reliability_params(values)

    def make_processor(self, values: Dict[str, Any]):
        params = {k: values[k] for k in RELIABILITY_NAMES + CORE_NAMES}
        return Reconstructor(self.db, method=values['method'], **params, **self.user_terms)

    def kernels(self):
        return [lazy_module('pose_reconstruction.reliability_kernels').warm_up,
                lazy_module('pose_reconstruction.kernels').warm_up]   # Eq. 1-8, Eq. 15


def main(args=None) -> int:
    return run_node(OptimizerNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
