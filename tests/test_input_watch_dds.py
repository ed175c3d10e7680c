"""ManagedNode.subscription(watch=True) over real DDS: a stream input whose publisher is matched
but sends nothing (what a restarted node sees when the shared-memory transport delivers into the
dead process's segment, docs/recovery.md) is one warning naming the input and a WARN on
/diagnostics; an input receiving messages is neither. The delay is shortened in-process; the test
waits for the report with a generous deadline, never for a time."""
import os
import time

import pytest

import domains  # noqa: E402  (tests/domains.py)

rclpy = pytest.importorskip('rclpy')

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from std_msgs.msg import String  # noqa: E402

import skeleton_core.input_watch as input_watch  # noqa: E402
import skeleton_core.rosnode as rosnode  # noqa: E402
from ros_helpers import Spinner, wait_until  # noqa: E402
from skeleton_core.rosnode import ManagedNode, bring_up  # noqa: E402

pytestmark = pytest.mark.ros

TOPIC = '/input_watch_test/stream'


class _Log:
    """The node's logger, with every warning and info line kept."""

    def __init__(self, real):
        self.real, self.warnings, self.infos = real, [], []

    def warning(self, text, **kw):
        self.warnings.append(text)
        return self.real.warning(text, **kw)

    def info(self, text, **kw):
        self.infos.append(text)
        return self.real.info(text, **kw)

    def __getattr__(self, name):
        return getattr(self.real, name)


class _Watched(ManagedNode):
    def __init__(self, **kwargs):
        super().__init__('input_watch_test', **kwargs)
        self.log = _Log(super().get_logger())
        self.received = 0

    def get_logger(self):   # (the base's constructor logs before ours has run)
        return self.__dict__.get('log') or super().get_logger()

    def configure(self):
        self.diagnostics()

    def activate(self):
        self.subscription(String, TOPIC, self._on_input, 10, watch=True)

    def _on_input(self, msg):
        self.received += 1


@pytest.fixture
def graph(monkeypatch):
    monkeypatch.setattr(rosnode, 'WATCH_PERIOD_S', 0.2)
    with domains.claimed(int(os.environ.get('ROS_DOMAIN_ID', '0')) + 31) as domain:
        ctx = rclpy.Context()
        rclpy.init(context=ctx, domain_id=domain)
        node = _Watched(context=ctx)
        source = rclpy.create_node('input_watch_source', context=ctx)
        pub = source.create_publisher(String, TOPIC, 10)
        diags = []
        source.create_subscription(DiagnosticArray, '/diagnostics',
                                   lambda m: diags.extend(m.status), 50)
        spinner = Spinner(ctx, node, source)
        try:
            yield node, source, pub, diags
        finally:
            spinner.stop()
            node.destroy_node()
            source.destroy_node()
            rclpy.try_shutdown(context=ctx)


def _warned(diags):
    return [s for s in list(diags) if s.level == DiagnosticStatus.WARN
            and any(kv.key == f'silent_input[{TOPIC}]' for kv in s.values)]


def test_a_matched_publisher_that_sends_nothing_is_reported(graph, monkeypatch):
    monkeypatch.setattr(input_watch, 'SILENT_AFTER_S', 1.0)
    node, source, pub, diags = graph
    bring_up(node)
    assert wait_until(lambda: node.log.warnings, 60.0), 'no warning about the silent input'
    assert len(node.log.warnings) == 1
    line = node.log.warnings[0]
    assert line.startswith(f'input {TOPIC}: 1 publisher matched for ') and 'nothing received' in line
    assert 'docs/recovery.md' in line
    assert wait_until(lambda: _warned(diags), 60.0), 'no WARN on /diagnostics'
    assert 'nothing received' in _warned(diags)[-1].message
    # once per episode: no second warning while it stays silent
    n = len(node.health.silent_inputs)
    assert wait_until(lambda: False, 1.0) is False and len(node.log.warnings) == 1 and n == 1
    # the first message is a recovery: one info line, the diagnostics cleared
    assert wait_until(lambda: (pub.publish(String(data='x')), node.received)[1] > 0, 60.0, 0.2)
    assert wait_until(lambda: any('receiving now' in i for i in node.log.infos), 60.0)
    assert node.health.silent_inputs == {} and len(node.log.warnings) == 1


def test_an_input_receiving_messages_is_not_reported(graph, monkeypatch):
    monkeypatch.setattr(input_watch, 'SILENT_AFTER_S', 5.0)
    node, source, pub, diags = graph
    timer = source.create_timer(0.05, lambda: pub.publish(String(data='x')))
    bring_up(node)
    watch = next(w for _, w in node._watched)
    # watched for longer than the delay, with the publisher matched all along
    assert wait_until(lambda: watch.publishers > 0 and node.received > 0, 60.0)
    start = time.monotonic()
    assert wait_until(lambda: watch.silent_for(time.monotonic()) > 2 * watch.silent_after_s
                      and time.monotonic() - start > watch.silent_after_s, 120.0)
    timer.cancel()
    assert node.received > 20 and not watch.silent
    assert not [w for w in node.log.warnings if 'nothing received' in w]
    assert not _warned(diags) and node.health.silent_inputs == {}


def test_the_watch_ends_with_the_active_state(graph, monkeypatch):
    monkeypatch.setattr(input_watch, 'SILENT_AFTER_S', 1.0)
    node, source, pub, diags = graph
    bring_up(node)
    assert node._watched and node._watch_timer is not None
    assert wait_until(lambda: node.health.silent_inputs, 60.0)
    node.trigger_deactivate()
    assert node._watched == [] and node._watch_timer is None and node.health.silent_inputs == {}
