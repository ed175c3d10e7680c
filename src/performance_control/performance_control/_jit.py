"""numba where it is installed and enabled, the numpy formulation otherwise.

``skeleton_core.jit`` (branch ``perf``) is used when main has it; until then this local shim
offers the same three functions. ``KINECT_NUMBA=0`` in the environment selects the numpy twins;
a missing numba does too (the package imports and runs without it).
"""
from __future__ import annotations

import os
from typing import Callable

try:  # pragma: no cover - depends on which branch main has
    from skeleton_core.jit import enabled, njit, pick  # type: ignore  # noqa: F401
except ImportError:
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
        """``numba.njit(cache=True)`` of ``fn`` when numba is importable, else ``fn`` itself."""
        try:
            import numba
        except ImportError:
            return fn
        return numba.njit(cache=True, nogil=True)(fn)

    def pick(compiled: Callable, fallback: Callable) -> Callable:
        """``compiled`` when :func:`enabled`, else ``fallback`` (the numpy twin)."""
        return compiled if enabled() else fallback

__all__ = ['enabled', 'njit', 'pick']
