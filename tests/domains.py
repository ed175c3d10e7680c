"""DDS domains for test runs that share a machine: each domain a test module (or a graph a test
starts) uses is claimed with an exclusive lock (``flock`` on ``<tmp>/kp_test_domains/<id>.lock``)
for as long as it is used, so two suites run at once (two clones, two distros, CI beside a
developer) never put their nodes on one domain. They did: each module stepped its domain on from
the suite's base, two suites with close bases met on a domain, and a launch's lifecycle bring-up
found the other suite's ``/reconstruction`` already active and left its own unconfigured.

A lock is released when its file is closed (:func:`release`) or the process ends, however it ends;
child processes do not inherit it (Python's files are not inheritable). Domains 1-101 (the
ones whose ports fit below Linux's ephemeral range for the participants a suite has); when all
are taken the preferred one is shared, as before.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Dict, IO

try:
    import fcntl
except ImportError:   # not Linux / macOS: no locks, the preferred domain as before
    fcntl = None

LOCK_DIR = Path(tempfile.gettempdir()) / 'kp_test_domains'
FIRST, COUNT = 1, 101
_held: Dict[int, IO] = {}


def claim(preferred: int) -> int:
    """A domain no other process holds, the first free one from ``preferred`` on (wrapping in
    1..101), held by this process until :func:`release` or its end."""
    preferred = FIRST + (int(preferred) - FIRST) % COUNT
    if fcntl is None:
        return preferred
    try:
        LOCK_DIR.mkdir(exist_ok=True)
    except OSError:
        return preferred
    for i in range(COUNT):
        d = FIRST + (preferred - FIRST + i) % COUNT
        if d in _held:
            continue
        try:
            f = open(LOCK_DIR / f'{d}.lock', 'a')
        except OSError:
            return preferred
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.close()
            continue
        _held[d] = f
        return d
    return preferred


def release(domain: int) -> None:
    """Give ``domain`` back (closing its lock file releases the lock)."""
    f = _held.pop(int(domain), None)
    if f is not None:
        f.close()


@contextlib.contextmanager
def claimed(preferred: int):
    """:func:`claim` for a ``with`` block: the domain is given back when the block ends (a test
    that starts a graph of its own holds its domain only while that graph runs; a suite that kept
    every such claim to its end held ~50 of the 101, and two suites at once then ran out)."""
    d = claim(preferred)
    try:
        yield d
    finally:
        release(d)


def held() -> list:
    return sorted(_held)


def env_with(domain: int) -> dict:
    """``os.environ`` with ``ROS_DOMAIN_ID`` = ``domain`` (for a process a test starts)."""
    return dict(os.environ, ROS_DOMAIN_ID=str(domain))
