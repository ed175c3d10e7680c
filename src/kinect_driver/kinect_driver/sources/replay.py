"""Replay source: a recorded bag or a CSV skeleton file, at recorded or scaled speed.

* **Bag** (``.mcap`` file; a folder of pieces -- a split recording, a rosbag2 directory -- or a
  comma-separated list of pieces, played in order as one recording): the ``skeleton_msgs/msg/SkeletonArray``
  messages of ``topic`` (default ``/kinect/skeletons``; if the bag has exactly one SkeletonArray
  topic and ``topic`` is empty, that one). Messages are replayed as their recorded CDR bytes, so
  subscribers receive exactly what was recorded (the node re-stamps them only with ``restamp``).
  Timing follows the bag's receive (log) times. sqlite3 (``.db3``) bags are not read: convert them
  with ``ros2 bag convert`` to MCAP.
* **CSV** (``.csv``): the format of :mod:`kinect_driver.csv_format`; timing follows ``stamp_ns``.
* **Azure Kinect ROS driver recordings** (``ros2 bag record /body_tracking_data ...``): a bag
  without a SkeletonArray topic whose ``*body_tracking_data`` topic holds the driver's
  ``visualization_msgs/MarkerArray`` (or ``replay_topic`` naming such a topic) plays as skeletons,
  converted by :mod:`skeleton_data.k4abt` at their recorded times, with the tracker
  ``azure_kinect_bt``; nothing to set. A bag of several cameras' markers: driver k of
  ``sensors:=N`` (frame ``kinect_k_link``) takes ``/kinect_k/body_tracking_data``.

The skeleton tracker a bag declares (``/kinect/tracker``, :mod:`skeleton_core.tracker`) becomes
the source's ``tracker``: the node publishes it latched before the first frame, so the
reconstruction picks the correction learned for it. A CSV file declares none.

Every other topic of the bag is replayed too, as ``ros2 bag play`` would (ground truth on
``/kinect/ground_truth`` included), at its recorded time among the skeletons, except the topics
in ``replay_skip_topics`` (by default those the node graph produces itself from the skeletons:
replaying a recorded reconstruction beside the live one would mix the two).
``replay_other_topics=False`` replays only the skeleton topic. ``wait_for_subscribers`` and
``wait_timeout_s`` are applied by the driver node (nothing lost while the graph comes up).

``rate`` scales the speed (2.0 = twice as fast); ``loop`` starts again after the last message (one
median message interval after it). Outputs are due when ``(t_recorded - t_first) / rate`` has
elapsed since the first poll; a poll releases everything due up to half a period ahead, so a
30 Hz recording polled at 30 Hz gives one message per poll.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from skeleton_core import tracker as T
from skeleton_core.bag_split import bag_pieces, pieces_topics, read_pieces
from skeleton_core.bagio import BagError
from skeleton_core.conversions import stamp_to_ns
from skeleton_core.params import param

from skeleton_data import k4abt as K4

from ..csv_format import CsvFormatError, read_csv
from .base import Source, SourceError, SourceOutput

SKELETON_ARRAY = 'skeleton_msgs/msg/SkeletonArray'
# topics the node graph produces itself (and the ROS infrastructure's): not replayed by default
GRAPH_OUTPUTS = ('/kinect/skeletons_reliability', '/posture/completed', '/posture/reconstructed',
                 '/character/skeletons', '/viz/markers', '/physics/objects', '/diagnostics',
                 '/rosout', '/parameter_events', '/tf', '/tf_static')


@dataclass
class ReplayConfig:
    """Parameters of :class:`ReplaySource`."""

    replay_file: str = param('', 'bag (.mcap file, a folder of pieces of a split recording '
                             'or a rosbag2 directory, or comma-separated pieces in order) or CSV '
                             'file')
    replay_topic: str = param('/kinect/skeletons', "SkeletonArray topic in the bag ('' = the "
                              "bag's only SkeletonArray topic)")
    rate: float = param(1.0, 'speed factor (2 = twice as fast)', range=(0.05, 20.0))
    loop: bool = param(False, 'start again after the last message')
    replay_other_topics: bool = param(
        True, "also play the bag's other topics (ground truth, ...) as recorded, except "
        'replay_skip_topics', public=False)
    replay_skip_topics: list = param(list(GRAPH_OUTPUTS), 'topics not replayed (by default '
                                     'those the node graph produces itself)', public=False)
    wait_for_subscribers: int = param(
        0, 'before the first frame, wait until /kinect/skeletons has this many subscribers (any '
        'source), and after it until they acknowledged it (a replay; the launch file and pipeline '
        'set the graph\'s count; 0 = start at once, like ros2 bag play)', range=(0, 100))
    wait_timeout_s: float = param(30.0, 'play anyway (with a warning) after waiting this long '
                                  'for subscribers (s)', range=(0.0, 3600.0), public=False)


class ReplaySource(Source):
    name = 'replay'
    config_class = ReplayConfig
    recorded = True

    def __init__(self, path: Optional[str] = None, config: Optional[ReplayConfig] = None,
                 frame_id: str = 'kinect_link', topic: Optional[str] = None,
                 rate: Optional[float] = None, loop: Optional[bool] = None,
                 play_other_topics: Optional[bool] = None,
                 skip_topics: Optional[Sequence[str]] = None, warn=None):
        cfg = config or ReplayConfig()
        self.config = cfg
        self.play_other_topics = bool(cfg.replay_other_topics if play_other_topics is None
                                      else play_other_topics)
        self.skip_topics = set(cfg.replay_skip_topics if skip_topics is None else skip_topics)
        self.other_topics: Dict[str, str] = {}   # replayed besides ``topic``: name -> type
        self.frames = 0                          # skeleton messages
        self._warn = warn
        self.path = str(cfg.replay_file if path is None else path)
        self.topic = cfg.replay_topic if topic is None else topic
        self.rate = float(cfg.rate if rate is None else rate)
        self.loop = bool(cfg.loop if loop is None else loop)
        self.frame_id = frame_id
        self._items: List[Tuple[int, SourceOutput]] = []   # (recorded time ns, output)
        self._next = 0
        self._start_ns: Optional[int] = None
        self._lap = 0
        self._lap_ns = 0
        self.kind = ''
        self.pieces: List[Path] = []

    # ------------------------------------------------------------------------------------
    def open(self) -> None:
        if self.rate <= 0:
            raise SourceError(f'rate must be > 0, got {self.rate}')
        if not self.path:
            raise SourceError('source:=replay needs replay_file:=<bag.mcap | skeletons.csv>')
        if ',' in self.path:   # a list of pieces, in order
            self._open_bag(self.path)
            return self._timing()
        p = Path(self.path).expanduser()
        if not p.exists():
            raise SourceError(f'cannot read replay file {p}: no such file')
        if p.suffix.lower() == '.csv':
            self._open_csv(p)
        elif p.suffix.lower() == '.db3' or (p.is_dir() and list(p.glob('*.db3'))):
            raise SourceError(f'cannot read replay file {p}: sqlite3 bags are not supported '
                              f'(convert it to MCAP with ros2 bag convert)')
        else:
            self._open_bag(p)
        self._timing()

    def _timing(self) -> None:
        p = self.path
        if not self._items:
            raise SourceError(f'replay file {p} holds no skeleton frames'
                              + (f' on {self.topic}' if self.kind == 'bag' else ''))
        t = np.array([t for t, _ in self._items], dtype=np.int64)
        dt = np.diff(np.array([t for t, o in self._items if not o.topic], dtype=np.int64))
        dt = dt[dt > 0]
        median = float(np.median(dt)) if dt.size else 1e9 / 30.0
        self.period_s = median / 1e9 / self.rate
        self._lap_ns = int(t[-1] - t[0] + median)
        self._next = 0
        self._start_ns = None

    def _open_bag(self, p) -> None:
        """A bag: one file, a folder of pieces (a split recording) or a comma-separated list of
        pieces, played as one recording."""
        self.kind = 'bag'
        try:
            self.pieces = bag_pieces(p)
            topics = pieces_topics(self.pieces, warn=self._warn)
        except BagError as e:
            raise SourceError(str(e)) from None
        arrays = sorted(t for t, (ty, _) in topics.items() if ty == SKELETON_ARRAY)
        topic = self.topic
        if not topic and len(arrays) == 1:
            topic = arrays[0]
        markers = K4.body_tracking_topics(topics)
        # an Azure Kinect ROS driver recording (ros2 bag record /body_tracking_data)
        if topic in topics and topics[topic][0] == K4.MARKER_ARRAY:
            return self._open_markers(p, topics, topic)
        if topic not in topics and not arrays and markers:
            if len(markers) > 1:
                # several cameras in one bag: driver k of sensors:=N (frame kinect_k_link) takes
                # /kinect_k/body_tracking_data
                ns = self.frame_id[:-len('_link')] if self.frame_id.endswith('_link') else ''
                markers = [t for t in markers if ns and t.startswith(f'/{ns}/')] or markers
            if len(markers) > 1:
                raise SourceError(f'replay bag {p} has several body-marker topics '
                                  f'({", ".join(markers)}): name one with replay_topic:=')
            return self._open_markers(p, topics, markers[0])
        if topic not in topics:
            raise SourceError(f'replay bag {p} has no topic {topic!r} (SkeletonArray topics: '
                              f'{", ".join(arrays) or "none"})')
        if topics[topic][0] != SKELETON_ARRAY:
            raise SourceError(f'replay bag {p}: {topic} holds {topics[topic][0]}, not '
                              f'{SKELETON_ARRAY}')
        self.topic = topic
        # the tracker the bag declares: the node publishes it latched before the first frame
        try:
            self.tracker = T.from_bag(self.pieces[0], warn=self._warn)
            T.check(self.tracker)
        except BagError as e:
            raise SourceError(str(e)) from None
        except T.TrackerError as e:
            raise SourceError(f'replay bag {p}: {e}') from None
        if self.play_other_topics:
            self.other_topics = {t: ty for t, (ty, n) in sorted(topics.items())
                                 if t not in (topic, T.TOPIC) and t not in self.skip_topics
                                 and n > 0 and ty}
        items = []
        try:
            for m in read_pieces(self.pieces, topics=[topic, *self.other_topics],
                                 decode=[topic], warn=self._warn):
                if m.topic == topic:
                    items.append((m.stamp_ns, SourceOutput(
                        stamp_ns=stamp_to_ns(m.msg.header.stamp), raw=m.data,
                        frame_id=m.msg.header.frame_id)))
                else:
                    items.append((m.stamp_ns, SourceOutput(stamp_ns=m.stamp_ns, raw=m.data,
                                                           topic=m.topic, msgtype=m.msgtype)))
        except BagError as e:
            raise SourceError(str(e)) from None
        self._items = items
        self.frames = sum(1 for _, o in items if not o.topic)
        if not self.frames:
            self._items = []

    def _open_markers(self, p, topics, topic: str) -> None:
        """The body markers of the Azure Kinect ROS driver (skeleton_data.k4abt), turned into
        skeletons at their recorded times; the tracker is ``azure_kinect_bt`` unless the bag
        declares one."""
        self.topic = topic
        try:
            self.tracker = T.check(T.from_bag(self.pieces[0], warn=self._warn) or K4.TRACKER)
        except T.TrackerError as e:
            raise SourceError(f'replay bag {p}: {e}') from None
        if self.play_other_topics:
            # (every camera's body markers are skeletons on a driver's /kinect/skeletons)
            self.other_topics = {t: ty for t, (ty, n) in sorted(topics.items())
                                 if t not in (topic, T.TOPIC, '/kinect/skeletons')
                                 and not K4.is_body_tracking_topic(t, ty)
                                 and t not in self.skip_topics and n > 0 and ty}
        items = []
        warn = self._warn or (lambda text: None)
        stream = K4.MarkerStream(self.frame_id, warn=lambda text: warn(f'replay: {text}'),
                                 live=False)
        try:
            def marker_messages():
                for m in read_pieces(self.pieces, topics=[topic, *self.other_topics], decode=False,
                                     warn=self._warn):
                    if m.topic == topic:
                        yield m.data, m.stamp_ns
                    else:
                        items.append((m.stamp_ns, SourceOutput(stamp_ns=m.stamp_ns, raw=m.data,
                                                               topic=m.topic, msgtype=m.msgtype)))
            for log_ns, stamp, frames in K4.bag_captures(marker_messages(), stream=stream):
                items.append((log_ns, SourceOutput(stamp_ns=stamp, frames=frames,
                                                   frame_id=self.frame_id)))
        except BagError as e:
            raise SourceError(str(e)) from None
        items.sort(key=lambda it: it[0])   # stable: a capture after the messages logged with it
        self._items = items
        self.kind = 'bag'
        self.markers = stream.counts
        self.frames = sum(1 for _, o in items if not o.topic)
        if not self.frames:
            self._items = []

    def _open_csv(self, p: Path) -> None:
        self.kind = 'csv'
        try:
            rows = read_csv(p, frame_id=self.frame_id)
        except CsvFormatError as e:
            raise SourceError(str(e)) from None
        self._items = [(stamp, SourceOutput(stamp_ns=stamp, frames=frames, frame_id=self.frame_id))
                       for stamp, frames in rows]
        self.frames = len(self._items)

    # ------------------------------------------------------------------------------------
    def poll(self, now_ns: int) -> List[SourceOutput]:
        if self.finished or not self._items:
            return []
        if self._start_ns is None:
            self._start_ns = now_ns
        t0 = self._items[0][0]
        elapsed = (now_ns - self._start_ns) * self.rate + 0.5 * self.period_s * 1e9 * self.rate
        out = []
        while True:
            if self._next >= len(self._items):
                if not self.loop:
                    self.finished = True
                    break
                self._next = 0
                self._lap += 1
            t_rec, item = self._items[self._next]
            due = (t_rec - t0) + self._lap * self._lap_ns
            if due > elapsed:
                break
            out.append(item)
            self._next += 1
        return out

    @classmethod
    def from_config(cls, config, frame_id: str, log=None, clock_ns=None) -> 'ReplaySource':
        return cls(config=config, frame_id=frame_id, warn=log)

    def delay(self, ns: int) -> None:
        """Hold the replay's clock by ``ns`` (the node waited that long after the first frame):
        what follows keeps its recorded spacing instead of coming out in a burst."""
        if self._start_ns is not None:
            self._start_ns += int(ns)

    @property
    def count(self) -> int:
        """Skeleton frames (messages of ``topic``)."""
        return self.frames

    def describe(self) -> str:
        return f'{self.path} ({self.count} frames, rate {self.rate:g}' + \
            (', loop)' if self.loop else ')') + \
            (f'; also replaying {", ".join(self.other_topics)}' if self.other_topics else '')

    def status(self) -> dict:
        return {'replay_file': self.path, 'messages': len(self._items), 'frames': self.frames,
                'other_topics': ', '.join(self.other_topics), 'lap': self._lap,
                'position': self._next}
