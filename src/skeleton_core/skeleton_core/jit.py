"""Compiled hot loops: numba where it is installed and enabled, the numpy formulation otherwise.

Every compiled kernel in the workspace has a numpy twin that computes the same numbers (a test
compares them); :func:`pick` chooses one when its module is imported. ``KINECT_NUMBA=0`` in the
environment runs the numpy twins (the test suite passes either way). Kernels are compiled on the
first call and cached on disk beside their module (``cache=True``), so a node pays the compile
once per source change, not once per start.
"""
from __future__ import annotations

import os
from typing import Callable

_OFF = ('0', 'false', 'no', 'off')


def enabled() -> bool:
    """True when numba is importable and ``KINECT_NUMBA`` does not switch it off."""
    if os.environ.get('KINECT_NUMBA', '1').strip().lower() in _OFF:
        return False
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def njit(fn: Callable) -> Callable:
    """``numba.njit(cache=True)`` of ``fn`` when numba is importable (whether or not it is
    enabled: tests compile it to compare), else ``fn`` itself (plain Python, for tests only)."""
    try:
        import numba
    except ImportError:
        return fn
    return numba.njit(cache=True, nogil=True)(fn)


def pick(compiled: Callable, fallback: Callable) -> Callable:
    """``compiled`` when :func:`enabled`, else ``fallback`` (the numpy twin)."""
    return compiled if enabled() else fallback


__all__ = ['enabled', 'njit', 'pick']
