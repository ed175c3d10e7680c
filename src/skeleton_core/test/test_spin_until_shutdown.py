"""spin_until_shutdown (skeleton_core.rosnode): a node process leaves its spin once its context
is shut down even when the wake-up of the wait never comes (the pip wheels lose it in about 1 of
10 SIGTERMs: the process then waited forever). DDS-free: a stand-in executor whose wait is never
woken and a context shut down from another thread, as rclpy's signal handler does."""
import threading
import time

import pytest

pytest.importorskip('rclpy')

from skeleton_core.rosnode import SPIN_SLICE_S, spin_until_shutdown  # noqa: E402


class _Context:
    def __init__(self):
        self._down = threading.Event()

    def ok(self):
        return not self._down.is_set()

    def shutdown(self):
        self._down.set()


class _DeafExecutor:
    """Waits out every timeout: no guard condition ever wakes it."""
    def __init__(self):
        self.waits = []

    def spin_once(self, timeout_sec=None):
        assert timeout_sec is not None, 'a wait without a timeout never ends when the wake-up is lost'
        self.waits.append(timeout_sec)
        time.sleep(timeout_sec)


def test_a_lost_wake_up_costs_at_most_one_slice():
    ctx, ex = _Context(), _DeafExecutor()
    done = threading.Event()
    t = threading.Thread(target=lambda: (spin_until_shutdown(ex, ctx), done.set()), daemon=True)
    t.start()
    time.sleep(3 * SPIN_SLICE_S)
    assert not done.is_set()          # spinning while the context is up
    ctx.shutdown()                    # the signal handler's shutdown, no wake-up
    assert done.wait(timeout=10 * SPIN_SLICE_S), 'still spinning after the context was shut down'
    assert ex.waits and all(w == SPIN_SLICE_S for w in ex.waits)
