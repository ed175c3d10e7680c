"""Reconstruction methods A, B and C for the evaluation harness.

Each factory returns a streaming, one-user :class:`~.reconstructor.Reconstructor` (``name``,
``reset()``, ``process(frame) -> frame``) and accepts keyword overrides of any parameter
(``k``, ``pca_dims``, ``steps``, ``samples``, ``solver``, the energy weights, the reliability
parameters, ...) and an optional ``db`` (a MotionDatabase or (N, 20, 3) array; default: the built-in
/ CMU database from ``skeleton_core.database.load_or_build_default``).

:func:`register` registers them with ``skeleton_core.evaluation.register_method`` when that
harness is available (it is called on import, guarded).
"""
from __future__ import annotations

import functools
from typing import Callable, Dict

from .reconstructor import Reconstructor

_DEFAULT_DB = None


def default_database():
    """The default motion database (cached per process)."""
    global _DEFAULT_DB
    if _DEFAULT_DB is None:
        from skeleton_core.database import load_or_build_default
        _DEFAULT_DB = load_or_build_default()
    return _DEFAULT_DB


def make_method(method: str, db=None, **overrides) -> Reconstructor:
    r = Reconstructor(default_database() if db is None else db, method=method, **overrides)
    r.name = method
    return r


make_method_a: Callable[..., Reconstructor] = functools.partial(make_method, 'A')
make_method_b: Callable[..., Reconstructor] = functools.partial(make_method, 'B')
make_method_c: Callable[..., Reconstructor] = functools.partial(make_method, 'C')

FACTORIES: Dict[str, Callable[..., Reconstructor]] = {
    'A': make_method_a, 'B': make_method_b, 'C': make_method_c}


def register() -> bool:
    """Register A, B, C with the evaluation harness; False when the harness is not there."""
    try:
        from skeleton_core.evaluation import register_method
    except ImportError:
        return False
    for name, factory in FACTORIES.items():
        register_method(name, factory)
    return True


register()
