"""ManagedNode.reach_subscribers (skeleton_core.rosnode): before a publish, a subscriber the graph
knows and the publisher has not matched yet (DDS discovery is two-sided: a recorder started after
the node sees the publisher before the publisher has met it) is waited for, so that the frame's
output reaches it; a subscriber that never matches costs one wait per change of the graph's
count, not one per message. DDS-free: stand-ins for the graph and the publisher's match count."""
import time

import pytest

pytest.importorskip('rclpy')

import skeleton_core.rosnode as R  # noqa: E402


class _Log:
    def __init__(self):
        self.warnings = []

    def warning(self, text):
        self.warnings.append(text)


class _Node:
    """What reach_subscribers uses of the node: the graph's count and the logger."""
    reach_subscribers = R.ManagedNode.reach_subscribers

    def __init__(self, known):
        self.known = known
        self.log = _Log()
        self._reach_gave_up = {}

    def count_subscribers(self, topic):
        return self.known

    def get_logger(self):
        return self.log


class _Pub:
    """Matches its subscribers ``after`` polls of its count (None: never)."""
    topic_name = '/posture/reconstructed'

    def __init__(self, matched, after=None, then=None):
        self.matched, self.after, self.then, self.polls = matched, after, then, 0

    def get_subscription_count(self):
        self.polls += 1
        if self.after is not None and self.polls > self.after:
            self.matched = self.then
        return self.matched


def test_nothing_missing_costs_no_wait():
    node, pub = _Node(known=2), _Pub(matched=2)
    t = time.monotonic()
    node.reach_subscribers([pub])
    assert time.monotonic() - t < 0.05 and pub.polls == 1 and not node.log.warnings


def test_a_subscriber_not_yet_reached_is_waited_for():
    node, pub = _Node(known=2), _Pub(matched=1, after=5, then=2)
    node.reach_subscribers([pub])
    assert pub.matched == 2 and pub.polls > 5 and not node.log.warnings


def test_a_subscriber_that_never_matches_costs_one_wait_per_graph_change(monkeypatch):
    monkeypatch.setattr(R, 'REACH_WAIT_S', 0.1)
    node, pub = _Node(known=3), _Pub(matched=2)
    t = time.monotonic()
    node.reach_subscribers([pub])
    assert 0.1 <= time.monotonic() - t < 1.0
    assert len(node.log.warnings) == 1 and '/posture/reconstructed' in node.log.warnings[0]
    t = time.monotonic()
    for _ in range(10):   # the same graph: no wait again
        node.reach_subscribers([pub])
    assert time.monotonic() - t < 0.05 and len(node.log.warnings) == 1
    node.known = 4        # the graph changed: one wait again
    t = time.monotonic()
    node.reach_subscribers([pub])
    assert time.monotonic() - t >= 0.1 and len(node.log.warnings) == 2


def test_a_subscriber_that_left_ends_the_wait(monkeypatch):
    # the publisher unmatched a leaving subscriber before the graph dropped it
    monkeypatch.setattr(R, 'REACH_WAIT_S', 5.0)
    node, pub = _Node(known=2), _Pub(matched=1)
    orig = node.count_subscribers
    calls = []

    def count(topic):
        calls.append(topic)
        return orig(topic) if len(calls) < 4 else 1
    node.count_subscribers = count
    t = time.monotonic()
    node.reach_subscribers([pub])
    assert time.monotonic() - t < 1.0 and not node.log.warnings
