"""What the ``reconstruction`` node computes per user, without rclpy: reliability (Eq. 1-8),
method B / C and, when wanted, method A, from one skeleton.

Parameters are the reliability, completion and optimizer nodes' own, prefixed with the node name
(``reliability.d_min``, ``completion.pca_dims``, ``optimizer.k``), and one ``reliable_threshold``
for both methods.
"""
from __future__ import annotations

from typing import Any, Dict, Optional, Sequence

from .reconstructor import USER_ERRORS, Reconstructor, process_batch


def section(values: Dict[str, Any], name: str) -> Dict[str, Any]:
    """The unprefixed parameters of one section (``'optimizer'`` -> ``{'k': 30, ...}``)."""
    head = name + '.'
    return {k[len(head):]: v for k, v in values.items() if k.startswith(head)}


class FusedProcessor:
    """One user: the optimizer's Reconstructor (which estimates the reliability) and, once the
    completion is wanted, a method-A Reconstructor fed with that reliability.

    ``process(frame, wanted) -> (reconstructed, with reliability or None, completed or None)``;
    ``wanted`` = (True, reliability wanted, completion wanted)."""

    def __init__(self, db, values: Dict[str, Any], user_terms: Optional[Dict[str, Any]] = None):
        self._db = db
        rel = section(values, 'reliability')
        if 'reliable_threshold' in values:   # one threshold for both methods
            rel = dict(rel, reliable_threshold=values['reliable_threshold'])
        terms = dict(user_terms or {})  # correction, correction_stage, input_tracker, profile
        self.rec = Reconstructor(db, use_input_reliability=False,
                                 **section(values, 'optimizer'), **rel, **terms)
        self._comp_args = dict(method='A', use_input_reliability=True,
                               **section(values, 'completion'), **rel, **terms)
        self.comp: Optional[Reconstructor] = None  # built when first wanted

    @property
    def bone_lengths(self):
        """(19,) the user's constant segment lengths (m) of the reconstruction, None before."""
        return self.rec.bone_lengths

    @property
    def rigid_output(self) -> bool:
        return self.rec.rigid_output

    @property
    def bone_length_restarts(self) -> int:
        return self.rec.bone_length_restarts

    def reset(self) -> None:
        self.rec.reset()
        if self.comp is not None:
            self.comp.reset()

    def process(self, frame, wanted: Sequence[bool]):
        out = self.rec.process(frame)
        if not (wanted[1] or wanted[2]):
            return out, None, None
        return self._more(frame, out, wanted)

    def _more(self, frame, out, wanted: Sequence[bool]):
        """The reliability and completion outputs beside the reconstruction ``out``."""
        rel = frame.copy(reliability=out.reliability)
        comp = None
        if wanted[2]:
            if self.comp is None:
                self.comp = Reconstructor(self._db, **self._comp_args)
            comp = self.comp.process(rel)
        return out, (rel if wanted[1] else None), comp

    @staticmethod
    def process_batch(procs: Sequence['FusedProcessor'], frames, wanted: Sequence[bool]) -> list:
        """:meth:`process` of several users' frames of one message (one processor each), the
        optimizer runs of the users solved together (:func:`~.reconstructor.process_batch`): the
        outputs of ``[p.process(f, wanted) for p, f in zip(procs, frames)]``, each element a
        tuple or the exception that user's frame raised. A processor given twice (two skeletons
        with one user id) is processed one frame after the other."""
        if len({id(p) for p in procs}) < len(procs):
            out = []
            for p, f in zip(procs, frames):
                try:
                    out.append(p.process(f, wanted))
                except USER_ERRORS as e:
                    out.append(e)
            return out
        recs = process_batch([p.rec for p in procs], frames)
        out = []
        for p, f, rec in zip(procs, frames, recs):
            if isinstance(rec, Exception) or not (wanted[1] or wanted[2]):
                out.append(rec if isinstance(rec, Exception) else (rec, None, None))
                continue
            try:
                out.append(p._more(f, rec, wanted))
            except USER_ERRORS as e:
                out.append(e)
        return out
