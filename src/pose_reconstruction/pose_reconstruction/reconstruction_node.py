"""``reconstruction`` node: reliability, completion (method A) and optimizer (B / C) in one node.

``/kinect/skeletons`` -> ``/posture/reconstructed``, and, while something subscribes to them,
``/kinect/skeletons_reliability`` and ``/posture/completed``: the same three outputs as the
``reliability``, ``completion`` and ``optimizer`` nodes, without the two DDS hops (serialise,
wake up another process, deserialise) between them, and without computing the completion when
nobody consumes it. The reliability is estimated once per user, inside the optimizer's
:class:`~.reconstructor.Reconstructor`, and handed to the completion.

Parameters are the three nodes' own, prefixed with the node name (``reliability.d_min``,
``optimizer.k``; :func:`fused_parameters` maps the three nodes' YAML files onto them), plus one
shared ``database``, ``reliable_threshold``, the correction / profile files and the topics.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Dict, Optional

from skeleton_core.params import specs
from skeleton_core.rosnode import ParamSpec, run_node

from skeleton_core.jit import lazy_module

from . import completion_node, optimizer_node
from .node_common import (CORRECTION_SPECS, DATABASE_SPEC, RELIABILITY_SPECS, DatabaseNode,
                          check_reliability_params, common_specs)
from .fused import FusedProcessor, section
from .posture_space import QueryConfig

# the split nodes' settings that are one here (one database, one reliable_threshold for both
# methods), or have no meaning here (the reliability always comes from this node's own estimate)
_NOT_FUSED = ('database', 'use_input_reliability', 'reliable_threshold')
THRESHOLD_SPEC = specs(QueryConfig, only=['reliable_threshold'])[0]
_SECTIONS = {
    'reliability': RELIABILITY_SPECS,
    'completion': [s for s in completion_node.SPECS if s.name not in _NOT_FUSED],
    'optimizer': [s for s in optimizer_node.SPECS if s.name not in _NOT_FUSED],
}


def _prefixed(section: str, spec: ParamSpec) -> ParamSpec:
    return dataclasses.replace(spec, name=f'{section}.{spec.name}')


PARAMS = (common_specs('/kinect/skeletons', '/posture/reconstructed') + [
    ParamSpec('reliability_topic', '/kinect/skeletons_reliability',
              'SkeletonArray with the reliability filled (published while subscribed)',
              read_only=True),
    ParamSpec('completed_topic', '/posture/completed',
              'method A output (computed and published only while subscribed)', read_only=True),
    DATABASE_SPEC, THRESHOLD_SPEC,
] + CORRECTION_SPECS + [_prefixed(sec, s) for sec, specs in _SECTIONS.items() for s in specs])
_SHARED = ('qos_depth', 'user_timeout_s', 'time_jump_reset_s', 'database',
           'reliable_threshold') + tuple(
    s.name for s in CORRECTION_SPECS)


def fused_parameters(reliability: Dict[str, Any], completion: Dict[str, Any],
                     optimizer: Dict[str, Any]) -> Dict[str, Any]:
    """This node's parameters from the three split nodes' (e.g. their YAML files' values)."""
    out: Dict[str, Any] = {}
    for name, values in (('reliability', reliability), ('completion', completion),
                         ('optimizer', optimizer)):
        names = {s.name for s in _SECTIONS[name]}
        out.update({f'{name}.{k}': v for k, v in values.items() if k in names})
    for k in _SHARED:
        for values in (completion, optimizer):  # the optimizer's value wins
            if k in values:
                out[k] = values[k]
    return out


class ReconstructionNode(DatabaseNode):
    def __init__(self, database_obj=None, **kwargs):
        super().__init__('reconstruction', PARAMS, database_obj=database_obj,
                         outputs=('output_topic', 'reliability_topic', 'completed_topic'), **kwargs)

    def validate(self, values: Dict[str, Any]) -> Optional[str]:
        return check_reliability_params(section(values, 'reliability'))

    def make_processor(self, values: Dict[str, Any]):
        return FusedProcessor(self.db, values, self.user_terms)

    def kernels(self):
        return [lazy_module('pose_reconstruction.reliability_kernels').warm_up,
                lazy_module('pose_reconstruction.kernels').warm_up]   # Eq. 1-8, Eq. 15

    def diagnostics_extra(self) -> Dict[str, Any]:
        extra = super().diagnostics_extra()
        extra['completion_subscribed'] = self._pubs[2].get_subscription_count() > 0
        return extra


def main(args=None) -> int:
    return run_node(ReconstructionNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
