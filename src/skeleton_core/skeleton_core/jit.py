"""Compiled hot loops: numba where it is installed and enabled, the numpy formulation otherwise.

Every compiled kernel in the workspace has a numpy twin that computes the same numbers (a test
compares them); :func:`pick` chooses one when its module is imported. ``KINECT_NUMBA=0`` in the
environment runs the numpy twins (the test suite passes either way). Kernels are compiled on the
first call and cached on disk beside their module (``cache=True``), so a node pays the compile
once per source change, not once per start.
"""
from __future__ import annotations

import importlib.util
import os
import sys
from typing import Callable

_OFF = ('0', 'false', 'no', 'off')


def _import_numba():
    """``numba`` (ImportError when it is not installed). numba imports the ``coverage`` package
    whenever it is installed (its support for measuring the coverage of compiled code), 0.1 s of
    CPU in every process that loads a kernel; when no coverage measurement runs in this process
    (``coverage`` not imported before numba), numba is imported without it."""
    if 'numba' in sys.modules:
        return sys.modules['numba']
    hide = 'coverage' not in sys.modules
    if hide:
        sys.modules['coverage'] = None   # an ImportError for numba's optional import
    try:
        import numba
    finally:
        if hide and 'coverage' in sys.modules and sys.modules['coverage'] is None:
            del sys.modules['coverage']
    return numba


def enabled() -> bool:
    """True when numba is importable and ``KINECT_NUMBA`` does not switch it off."""
    if os.environ.get('KINECT_NUMBA', '1').strip().lower() in _OFF:
        return False
    try:
        _import_numba()
    except ImportError:
        return False
    return True


def njit(fn: Callable) -> Callable:
    """``numba.njit(cache=True)`` of ``fn`` when numba is importable (whether or not it is
    enabled: tests compile it to compare), else ``fn`` itself (plain Python, for tests only)."""
    try:
        numba = _import_numba()
    except ImportError:
        return fn
    return numba.njit(cache=True, nogil=True)(fn)


def lazy_module(name: str):
    """The module ``name``, executed on its first attribute access (``importlib.util.LazyLoader``;
    a normal module from then on). A module of kernels imported this way costs nothing until a
    kernel runs: a process that only reads a node's declarations (the launch files map the
    reconstruction's parameters) does not import numba."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    if spec is None:
        raise ImportError(f'no module named {name!r}')
    spec.loader = importlib.util.LazyLoader(spec.loader)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def pick(compiled: Callable, fallback: Callable) -> Callable:
    """``compiled`` when :func:`enabled`, else ``fallback`` (the numpy twin)."""
    return compiled if enabled() else fallback


__all__ = ['enabled', 'lazy_module', 'njit', 'pick']
