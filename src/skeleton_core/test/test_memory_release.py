"""skeleton_core.memory.release_freed_memory: pages freed in the middle of the C heap go back to
the OS (what the physics simulation calls after dropping a recompiled MuJoCo world)."""
import ctypes

import pytest

from skeleton_core.memory import release_freed_memory, rss_mb


def test_freed_heap_pages_are_returned():
    try:
        libc = ctypes.CDLL('libc.so.6')
        libc.malloc.restype = ctypes.c_void_p
        libc.malloc.argtypes = [ctypes.c_size_t]
        libc.free.argtypes = [ctypes.c_void_p]
    except (OSError, AttributeError):
        pytest.skip('no glibc')
    # 60 MB in 64 kB blocks (below the mmap threshold: on the heap), written so they are
    # resident; all freed but the last, which keeps the heap's top where it is
    blocks = [libc.malloc(64 * 1024) for _ in range(960)]
    for b in blocks:
        ctypes.memset(b, 1, 64 * 1024)
    for b in blocks[:-1]:
        libc.free(b)
    before = rss_mb()
    assert release_freed_memory()
    after = rss_mb()
    libc.free(blocks[-1])
    assert before - after > 30.0, f'{before:.1f} -> {after:.1f} MB'
