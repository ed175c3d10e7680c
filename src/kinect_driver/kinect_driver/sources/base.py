"""What every skeleton source provides (no rclpy): frames of users to publish, and one-line errors."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, List, Optional

from skeleton_core.conversions import SkeletonFrame


class SourceError(RuntimeError):
    """A problem a user can fix, in one line (no traceback). ``retryable``: the condition may clear
    by itself (sensor not plugged in yet, unplugged), so the node may wait and try again."""

    def __init__(self, message: str, retryable: bool = False):
        super().__init__(message)
        self.retryable = retryable


@dataclass
class SourceOutput:
    """One sensor frame: all users seen at capture time ``stamp_ns``."""

    stamp_ns: int
    frames: List[SkeletonFrame] = field(default_factory=list)
    truth: Optional[List[SkeletonFrame]] = None   # ground truth (synthetic source only)
    raw: Optional[bytes] = None                   # recorded CDR bytes of the SkeletonArray (replay)
    frame_id: str = ''
    # replay of another topic of the bag (ground truth, ...): published as recorded on ``topic``
    topic: str = ''
    msgtype: str = ''


@dataclass
class NoConfig:
    """A source without parameters of its own."""


class Source:
    """Base class. ``open()`` raises :class:`SourceError`; ``poll(now_ns)`` returns the outputs due
    by ``now_ns`` (called every ``period_s`` by the node); ``prepare()`` is called after they are
    published, to get the next output ready (a simulated sensor computes its next frame there, so
    that the simulation's own cost is not part of the measured capture-to-output latency);
    ``close()`` releases everything.

    ``config_class``: a dataclass whose fields, declared with ``skeleton_core.params.param``, are
    the source's parameters (they become read-only parameters of the driver node); the node builds
    the source with :meth:`from_config`."""

    name = 'source'
    config_class: type = NoConfig
    period_s = 1.0 / 30.0
    finished = False  # a non-looping replay that played everything
    recorded = False  # stamps are recorded ones (replay): no capture-to-output latency
    has_truth = False  # outputs may carry the ground truth (SourceOutput.truth)
    retry_s = 0.0     # > 0: a retryable SourceError at open() is retried this often (s)
    # the skeleton tracker the frames come from (skeleton_core.tracker.TRACKERS; '' = unknown),
    # published by the node on /kinect/tracker (latched) once the source is open
    tracker = ''

    @classmethod
    def from_config(cls, config, frame_id: str, log: Optional[Callable[[str], None]] = None,
                    clock_ns: Optional[Callable[[], int]] = None) -> 'Source':
        """The source for a ``config_class`` instance (override to take ``log`` / ``clock_ns``)."""
        return cls(config=config, frame_id=frame_id)

    def describe(self) -> str:
        """A few words for the node's start-up log line (after it opened)."""
        return ''

    def open(self) -> None:
        pass

    def poll(self, now_ns: int) -> List[SourceOutput]:
        raise NotImplementedError

    def prepare(self) -> None:
        pass

    def close(self) -> None:
        pass

    def status(self) -> dict:
        return {}
