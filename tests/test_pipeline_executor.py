"""The one-process pipeline's executor choice (`pipeline --executor`): ``auto`` takes rclpy's
events executor where it exists and falls back to the single-threaded one (Humble) instead of
failing; asked for by name, a missing events executor is the one-line error."""
import pytest

rclpy = pytest.importorskip('rclpy')

from rclpy.executors import SingleThreadedExecutor  # noqa: E402

from kinect_bringup import pipeline  # noqa: E402
from skeleton_core import compat  # noqa: E402


@pytest.fixture
def default_context():
    rclpy.init()
    yield
    rclpy.try_shutdown()


def _no_events_executor(**kwargs):
    raise RuntimeError('the events executor needs rclpy.experimental.EventsExecutor (ROS 2 Jazzy '
                       'or newer; this is humble)')


def test_auto_is_the_events_executor_where_rclpy_has_it(default_context):
    try:
        from rclpy.experimental import EventsExecutor  # noqa: F401
    except ImportError:
        pytest.skip('no EventsExecutor in this ROS 2 (Humble): the fallback test covers it')
    ex, kind = pipeline.make_executor('auto')
    try:
        assert kind == 'events' and not isinstance(ex, SingleThreadedExecutor), type(ex)
        assert 'Events' in type(ex).__name__, type(ex)
    finally:
        ex.shutdown()
    assert pipeline.build_parser().parse_args([]).executor == 'auto'


def test_auto_falls_back_to_single_without_the_events_executor(default_context, monkeypatch):
    monkeypatch.setattr(compat, 'events_executor', _no_events_executor)
    ex, kind = pipeline.make_executor('auto')
    try:
        assert kind == 'single' and isinstance(ex, SingleThreadedExecutor)
    finally:
        ex.shutdown()
    with pytest.raises(RuntimeError, match='Jazzy or newer'):
        pipeline.make_executor('events')
