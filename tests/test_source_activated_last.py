"""The launch files activate the sensor's driver only once every other node of the launch is up
(kinect_bringup.launch_nodes), so no output misses the first frame: the wait, without DDS."""
import threading
import time

import pytest

pytest.importorskip('launch_ros')

from kinect_bringup import launch_nodes as ln  # noqa: E402


class _Context:
    is_shutdown = False


def test_the_source_waits_for_every_consumer():
    ctx = _Context()
    up = {name: threading.Event() for name in ('/reconstruction', '/physics', '/recorder')}
    ln._CONSUMERS[ctx] = up
    order = []

    def come_up():
        for name, event in up.items():
            time.sleep(0.05)
            order.append(name)
            event.set()
    threading.Thread(target=come_up).start()
    ln._wait_for_consumers(ctx, '/driver', order.append)
    order.append('/driver')
    assert order == ['/reconstruction', '/physics', '/recorder', '/driver']


def test_a_consumer_that_never_comes_up_holds_the_source_only_so_long(monkeypatch):
    monkeypatch.setattr(ln, 'SOURCE_WAIT_S', 0.2)
    ctx, logged = _Context(), []
    ln._CONSUMERS[ctx] = {'/physics': threading.Event()}
    t = time.monotonic()
    ln._wait_for_consumers(ctx, '/driver', logged.append)
    assert 0.2 <= time.monotonic() - t < 2.0
    assert len(logged) == 1 and '/physics' in logged[0] and '/driver' in logged[0]


def test_drivers_alone_have_nothing_to_wait_for():
    t = time.monotonic()
    ln._wait_for_consumers(_Context(), '/kinect_1/driver', print)
    assert time.monotonic() - t < 0.5


def test_only_the_driver_is_a_source():
    assert ln.managed_node(package='kinect_driver', executable='driver', name='driver')._source
    assert not ln.managed_node(package='physics_sim', executable='physics', name='physics')._source
