"""Azure Kinect / Orbbec Femto source: the body markers of the Azure Kinect ROS driver (no rclpy).

``microsoft/Azure_Kinect_ROS_Driver`` (or Orbbec's K4A wrapper under it) runs the Body Tracking
SDK and publishes ``body_tracking_data`` (``visualization_msgs/MarkerArray``, one message per
capture, 32 SPHERE markers per body; :mod:`skeleton_data.k4abt` says exactly what it holds and
how its joints and axes become the model's). This source subscribes to it -- the node creates
the subscriptions a source asks for (:attr:`Source.subscriptions`) and hands it the serialized
messages -- and publishes every capture on ``/kinect/skeletons`` with the tracker
``azure_kinect_bt``.

The topic is resolved in the driver node's namespace: ``body_tracking_data`` is
``/body_tracking_data`` for one camera and ``/kinect_k/body_tracking_data`` for driver k of
``sensors:=N`` (start the Azure driver k in namespace ``kinect_k``); another name is a remapping
(``-r body_tracking_data:=/camera/body_tracking_data``). Bodies come and go as the
SDK sees them (user id = the SDK's body id); a capture's markers split over messages are joined;
malformed input is counted and warned once (never raised).
"""
from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Callable, List, Optional, Tuple

from skeleton_core.params import param

from .base import Source, SourceError, SourceOutput


def _topic_ok(v):
    return None if v and ' ' not in v else 'azure_topic must be a topic name'


@dataclass
class AzureKinectConfig:
    """Parameters of :class:`AzureKinectSource`."""

    azure_topic: str = param('body_tracking_data', "the Azure Kinect ROS driver's body markers "
                             '(visualization_msgs/MarkerArray), relative to the driver\'s '
                             'namespace (another name: remap it, -r body_tracking_data:=...)',
                             validator=_topic_ok, public=False)
    azure_depth_tilt_deg: float = param(
        6.0, 'how far the depth camera looks down from the housing (deg; the Azure Kinect and '
        'Femto: 6)', range=(-30.0, 30.0), public=False)


class AzureKinectSource(Source):
    name = 'azure_kinect'
    config_class = AzureKinectConfig
    tracker = 'azure_kinect_bt'
    period_s = 1.0 / 60.0   # polled twice per camera frame: a capture waits at most ~17 ms

    def __init__(self, config: Optional[AzureKinectConfig] = None, frame_id: str = 'kinect_link',
                 log: Optional[Callable[[str], None]] = None,
                 clock_ns: Optional[Callable[[], int]] = None):
        self.config = config or AzureKinectConfig()
        self.frame_id = frame_id
        self._log = log or (lambda text: None)
        self._clock = clock_ns
        self._inbox: collections.deque = collections.deque(maxlen=300)   # (bytes, receive ns)
        self.stream = None
        self.last_frame_ns = 0

    @classmethod
    def from_config(cls, config, frame_id: str, log=None, clock_ns=None) -> 'AzureKinectSource':
        return cls(config=config, frame_id=frame_id, log=log, clock_ns=clock_ns)

    def open(self) -> None:
        from skeleton_data.k4abt import K4abtError, MarkerStream
        try:
            self.stream = MarkerStream(self.frame_id, tilt_deg=self.config.azure_depth_tilt_deg,
                                       warn=self._log, live=True)
        except K4abtError as e:
            raise SourceError(str(e)) from None

    def subscriptions(self) -> List[Tuple[str, str, Callable[[bytes], None]]]:
        """What the node subscribes to for this source: (topic, type, callback of the bytes)."""
        return [(self.config.azure_topic, 'visualization_msgs/msg/MarkerArray', self.receive)]

    def receive(self, data: bytes, now_ns: Optional[int] = None) -> None:
        """A serialized MarkerArray (from the subscription's thread)."""
        t = now_ns if now_ns is not None else (self._clock() if self._clock else 0)
        self._inbox.append((bytes(data), t))
        self.last_frame_ns = t

    def poll(self, now_ns: int) -> List[SourceOutput]:
        if self.stream is None:
            return []
        out = []
        while self._inbox:
            data, t = self._inbox.popleft()
            out += self.stream.feed(data, t)
        # a capture whose markers stopped coming without a later one (joints split over messages)
        out += self.stream.flush(now_ns, hold_ns=int(2 * self.period_s * 1e9))
        return [SourceOutput(stamp_ns=stamp, frames=frames, frame_id=self.frame_id)
                for stamp, frames in out]

    def describe(self) -> str:
        return f'subscribed to {self.config.azure_topic} (Azure Kinect ROS driver body markers)'

    def status(self) -> dict:
        return dict(self.stream.counts) if self.stream is not None else {}

    def close(self) -> None:
        self._inbox.clear()
        self.stream = None
