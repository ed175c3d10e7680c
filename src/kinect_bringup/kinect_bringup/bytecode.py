"""The workspace's Python bytecode, written once by ``make setup`` (``kinect_bringup.warm_kernels``)
instead of by the first start of the graph.

Every process of the graph imports the workspace's modules (and ``ros2 launch`` its launch files).
Without their ``__pycache__/*.pyc`` each one compiles them from source: the first run in a fresh
tree (and, where ``PYTHONDONTWRITEBYTECODE`` is set, every run) pays it in each process at once.
The venv's packages and the generated message modules have theirs from their install already.

    python -m kinect_bringup.bytecode          # compile; prints how many files were (re)compiled
"""
from __future__ import annotations

import compileall
import importlib.util
import os
import struct
import sys
from pathlib import Path
from typing import Iterable, List, Tuple


def workspace_dirs() -> Tuple[List[Path], List[Path]]:
    """(the package directories the workspace's Python packages are imported from, the
    directories of their installed launch files): the packages installed beside
    ``kinect_bringup`` (the same install base; the venv's ROS 2 packages are not)."""
    from ament_index_python.packages import get_package_prefix, get_resources
    base = Path(get_package_prefix('kinect_bringup')).parent
    packages, launch = [], []
    for name, prefix in sorted(get_resources('packages').items()):
        if Path(prefix).parent != base:
            continue
        spec = importlib.util.find_spec(name) if _importable(name) else None
        if spec is not None and spec.submodule_search_locations:
            packages += [Path(p) for p in spec.submodule_search_locations]
        d = Path(prefix) / 'share' / name / 'launch'
        if d.is_dir():
            launch.append(d)
    return packages, launch


def _importable(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, ValueError):
        return False


def sources(packages: Iterable[Path], launch: Iterable[Path]) -> List[Path]:
    """The .py files of ``packages`` (recursively; as imported: not through ``Path.resolve``)
    and the launch files in ``launch``."""
    out = []
    for d in packages:
        for root, dirs, files in os.walk(d):
            dirs[:] = [x for x in dirs if x != '__pycache__']
            out += [Path(root) / f for f in files if f.endswith('.py')]
    for d in launch:
        out += [f for f in d.iterdir() if f.name.endswith('.py')]
    return sorted(out)


def stale(files: Iterable[Path]) -> List[Path]:
    """The ``files`` whose bytecode the import system would not use: no ``.pyc`` where it
    looks (``importlib.util.cache_from_source`` of the path as imported), or one recorded for
    another mtime or size of the source (the default, timestamp-checked pycs)."""
    out = []
    for f in files:
        pyc = Path(importlib.util.cache_from_source(str(f)))
        try:
            head = pyc.read_bytes()[:16]
            st = f.stat()
        except OSError:
            out.append(f)
            continue
        if len(head) < 16 or head[:4] != importlib.util.MAGIC_NUMBER:
            out.append(f)
            continue
        flags, mtime, size = struct.unpack('<III', head[4:16])
        if flags == 0 and (mtime != int(st.st_mtime) & 0xFFFFFFFF or size != st.st_size & 0xFFFFFFFF):
            out.append(f)
    return out


def compile_workspace() -> Tuple[int, int]:
    """Compile every stale source of the workspace (:func:`workspace_dirs`); (files compiled,
    failures). Writes regardless of ``PYTHONDONTWRITEBYTECODE`` (that only stops the import
    system from writing; it still reads them)."""
    packages, launch = workspace_dirs()
    todo = stale(sources(packages, launch))
    failed = sum(not compileall.compile_file(str(f), quiet=2) for f in todo)
    return len(todo), failed


def main(argv=None) -> int:
    n, failed = compile_workspace()
    print(f'bytecode: {n} workspace file(s) compiled' + (f', {failed} failed' if failed else ''))
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
