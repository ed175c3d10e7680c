"""A driver source added through the source interface alone (a Source subclass with its
parameters on a ``config_class``, and its registration): the driver node offers it as a
``source`` value, declares its parameters (read-only, described), builds it from them and publishes
its skeletons over real DDS."""
from dataclasses import dataclass

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

from rclpy.exceptions import ParameterException  # noqa: E402
from rclpy.node import Node  # noqa: E402
from skeleton_core.rosnode import bring_up  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from skeleton_msgs.msg import SkeletonArray  # noqa: E402

from skeleton_core.conversions import SkeletonFrame, frames_from_array_msg  # noqa: E402
from skeleton_core.model import NUM_JOINTS, TRACKED, standard_body  # noqa: E402
from skeleton_core.params import param  # noqa: E402

from kinect_driver import sources  # noqa: E402
from kinect_driver.sources import Source, SourceOutput  # noqa: E402

from ros_helpers import Spinner, wait_until  # noqa: E402


@dataclass
class StandingConfig:
    standing_users: int = param(2, 'users standing side by side', range=(1, 6))
    standing_height: float = param(0.0, 'lift of every user (m)', range=(0.0, 1.0))


class StandingSource(Source):
    """Every user in the standard rest posture, at 50 Hz."""

    name = 'standing'
    config_class = StandingConfig
    period_s = 0.02

    def __init__(self, config=None, frame_id='kinect_link'):
        self.config = config or StandingConfig()
        self.frame_id = frame_id
        self.polls = 0

    def poll(self, now_ns):
        self.polls += 1
        rest = standard_body().rest_positions()
        frames = [SkeletonFrame(positions=rest + [2.0, 0.8 * k, self.config.standing_height],
                                tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                                user_id=k + 1, stamp_ns=now_ns, frame_id=self.frame_id)
                  for k in range(self.config.standing_users)]
        return [SourceOutput(stamp_ns=now_ns, frames=frames, frame_id=self.frame_id)]

    def describe(self):
        return f'{self.config.standing_users} standing user(s)'


@pytest.fixture
def registered(monkeypatch):
    monkeypatch.setattr(sources, '_registered', {})
    sources.register_source('standing', StandingSource)
    yield


def test_unknown_sources_are_refused_with_the_registered_names(registered):
    assert 'standing' in sources.source_names()
    assert sources.source_class('standing') is StandingSource
    with pytest.raises(sources.SourceError, match='standing'):
        sources.source_class('nothing')


def test_a_registered_source_runs_through_the_driver_node(registered, rclpy_context):
    from kinect_driver.driver_node import DriverNode, driver_params

    specs = {s.name: s for s in driver_params()}
    assert 'standing' in specs['source'].choices
    assert specs['standing_users'].read_only and specs['standing_users'].range == (1, 6)
    assert specs['standing_users'].description.startswith('standing: ')

    with pytest.raises((ValueError, ParameterException)):  # validated like every parameter
        DriverNode(context=rclpy_context, parameter_overrides=[
            Parameter('source', value='standing'), Parameter('standing_users', value=9)])
    driver = bring_up(DriverNode(context=rclpy_context, parameter_overrides=[
        Parameter('source', value='standing'), Parameter('standing_users', value=3),
        Parameter('standing_height', value=0.25), Parameter('frame_id', value='cam')]))
    source = driver.source   # (released by cleanup)
    got = []
    sink = Node('standing_sink', context=rclpy_context)
    sink.create_subscription(SkeletonArray, '/kinect/skeletons', got.append, 10)
    spinner = Spinner(rclpy_context, driver, sink)
    try:
        assert wait_until(lambda: len(got) >= 5, 10.0), 'no skeletons from the standing source'
    finally:
        spinner.stop()
        sink.destroy_node()
        driver.destroy_node()
    assert isinstance(source, StandingSource) and source.polls >= 5
    assert driver.truth_pub is None     # the source has no ground truth
    frames = frames_from_array_msg(got[-1])
    assert [f.user_id for f in frames] == [1, 2, 3]
    assert got[-1].header.frame_id == 'cam'
    rest = standard_body().rest_positions()
    np.testing.assert_allclose(frames[1].positions, rest + [2.0, 0.8, 0.25], atol=1e-6)
