"""Process resources and their trend (pure Python, no rclpy): resident memory, open files, and the
slope of a series after warm-up -- how a node reports its memory on /diagnostics and how the soak
and the tests judge growth.

Growth is judged as a slope (MB per second, or per user that came and went), never as a
percentage after warm-up: a steady 1 MB/s is 20 % over a few minutes but 20 GB over a lab day,
and a percentage over a short run hides it. The slope is Theil-Sen's (the median of the
slopes between pairs of samples): the resident memory also follows the load (a physics world with
more visitors is bigger), and a few such steps move the median far less than a least-squares
line.

    from skeleton_core.memory import rss_mb, slope
    samples.append((time.monotonic(), rss_mb()))
    mb_per_s = slope([t for t, _ in samples], [m for _, m in samples], warmup=0.25)
"""
from __future__ import annotations

import os
from typing import Optional, Sequence

import numpy as np

_PAGE = os.sysconf('SC_PAGE_SIZE') if hasattr(os, 'sysconf') else 4096


def rss_mb(pid: Optional[int] = None) -> float:
    """Resident set size of a process (default: this one) in MB (2**20 bytes); NaN when it cannot
    be read (the process is gone, or no /proc and no psutil)."""
    try:
        with open(f'/proc/{pid or "self"}/statm') as f:
            return int(f.read().split()[1]) * _PAGE / 2 ** 20
    except (OSError, ValueError, IndexError):
        pass
    try:
        import psutil
        return psutil.Process(pid).memory_info().rss / 2 ** 20
    except Exception:  # noqa: BLE001 - no psutil, or the process is gone
        return float('nan')


def open_files(pid: Optional[int] = None) -> int:
    """Open file descriptors of a process (default: this one); -1 when unknown."""
    try:
        return len(os.listdir(f'/proc/{pid or "self"}/fd'))
    except OSError:
        return -1


def slope(t: Sequence[float], y: Sequence[float], warmup: float = 0.0,
          max_points: int = 400) -> float:
    """Theil-Sen slope (units of y per unit of t) of the samples after the first ``warmup`` share
    of the time span; NaN with fewer than 3 samples there. At most ``max_points`` evenly spaced
    samples are used (the pairs grow with their square)."""
    t = np.asarray(t, float)
    y = np.asarray(y, float)
    ok = np.isfinite(t) & np.isfinite(y)
    t, y = t[ok], y[ok]
    if t.size < 3:
        return float('nan')
    keep = t >= t.min() + warmup * (t.max() - t.min())
    t, y = t[keep], y[keep]
    if t.size < 3:
        return float('nan')
    if t.size > max_points:
        idx = np.linspace(0, t.size - 1, max_points).round().astype(int)
        t, y = t[idx], y[idx]
    i, j = np.triu_indices(t.size, 1)
    dt = t[j] - t[i]
    good = dt > 0
    if not np.any(good):
        return float('nan')
    return float(np.median((y[j] - y[i])[good] / dt[good]))


__all__ = ['rss_mb', 'open_files', 'slope']


_LIBC = None


def release_freed_memory() -> bool:
    """Hand the C heap's free pages back to the OS (glibc ``malloc_trim(0)``): after large
    native objects of varying size are freed (a MuJoCo model recompiled when a user arrives or
    leaves), the allocator keeps the freed pages in its arenas and the RSS only ever rises in
    steps. A few ms; call it after such a release, never per frame. False where there is no
    glibc (nothing done)."""
    global _LIBC
    if _LIBC is None:
        try:
            import ctypes
            _LIBC = ctypes.CDLL('libc.so.6')
            _LIBC.malloc_trim.argtypes = [ctypes.c_size_t]
        except (OSError, AttributeError):
            _LIBC = False
    if not _LIBC:
        return False
    _LIBC.malloc_trim(0)
    return True
