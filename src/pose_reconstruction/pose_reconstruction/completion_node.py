"""``completion`` node: method A, database completion (Shum & Ho 2012).
``/kinect/skeletons_reliability`` -> ``/posture/completed`` (SkeletonArray). Missing / unreliable
joints (reliability below ``reliable_threshold``) and their orientations are substituted from the
nearest database posture in a ``pca_dims``-dimensional PCA space. Input skeletons without a
reliability get one estimated here (Eq. 1-8)."""
from __future__ import annotations

from typing import Any, Dict, Optional

from skeleton_core.rosnode import ParamSpec, run_node

from .node_common import (RELIABILITY_NAMES, RELIABILITY_SPECS, DatabaseNode,
                          check_reliability_params, common_specs)
from .reconstructor import Reconstructor

SPECS = [
    ParamSpec('database', '', "motion database file ('' = built-in / CMU default)"),
    ParamSpec('pca_dims', 7, 'PCA dimensions of the database search (Shum & Ho: 7 of 60)', (1, 60)),
    ParamSpec('reliable_threshold', 0.5,
              'joints with a reliability below this are substituted from the database', (0.0, 1.0)),
    ParamSpec('substitution', 'offset', 'offset: hang substituted joints off their parent with the '
              "user's bone length; absolute: the match's position (paper)",
              choices=('offset', 'absolute')),
    ParamSpec('use_input_reliability', True,
              'use the reliability field of the input when it is filled (else estimate it)'),
]


class CompletionNode(DatabaseNode):
    def __init__(self, database_obj=None, **kwargs):
        specs = (common_specs('/kinect/skeletons_reliability', '/posture/completed') + SPECS
                 + RELIABILITY_SPECS)
        super().__init__('completion', specs, database_obj=database_obj, **kwargs)

    def validate(self, values: Dict[str, Any]) -> Optional[str]:
        return check_reliability_params(values)

    def make_processor(self, values: Dict[str, Any]):
        params = {k: values[k] for k in RELIABILITY_NAMES}
        return Reconstructor(self.db, method='A', pca_dims=values['pca_dims'],
                             reliable_threshold=values['reliable_threshold'],
                             substitution=values['substitution'],
                             use_input_reliability=values['use_input_reliability'], **params)


def main(args=None) -> int:
    return run_node(CompletionNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
