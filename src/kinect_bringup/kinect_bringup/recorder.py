"""``recorder`` node: records the pipeline's topics to an MCAP bag that ``ros2 bag play`` and Foxglove
open (rosbag2 itself is not available from the pip wheels). Messages are written as received (log
time = receive time, publish time = the message's header stamp when it has one).

Crash-safe: what was received is in the file within ``flush_period`` s (a timer flushes the chunk
being filled even when the input pauses), so a recorder killed with SIGKILL, by the OOM killer or
a power cut (``fsync``) leaves a bag that every reader reads up to its last complete message and
``ros2 run kinect_bringup recover_bag`` rewrites into a complete, indexed one (docs/recovery.md).

Recordings that rotate: with ``split_size_mb`` and/or ``split_duration_s`` the recording
``out/day.mcap`` becomes the folder ``out/day/`` of pieces ``day_0.mcap``, ``day_1.mcap``, ...,
each a complete bag (closed when the next one starts; the one being written is crash-safe as
above), which replay and ``process_bag`` play in order as one recording
(:mod:`skeleton_core.bag_split`).

Nothing of a replay lost while the graph comes up: with ``wait_for_publishers`` (the launch file
names the recorded topics its nodes publish) the recorder subscribes to the graph's input (the
driver's topics) only once its subscriptions to those topics have matched a publisher (at most
:data:`PUBLISHERS_WAIT_S`). A replay waits for the recorder's subscription to its input before its
first frame, so the reconstruction's output of that frame finds the recorder there: a publisher
discovered late would otherwise take the first frames' outputs past the recorder. Matching is
two-sided: the recorder's subscription seeing a publisher does not mean that the publisher has
met the subscription yet, and under load the publisher's side came later (the reconstruction's
output of a replay's first frame lost, 1 clean-clone test run in 6): the recorder reports
active :data:`MATCH_SETTLE_S` later (the publishers reach every subscriber their graph knows before
they publish, ``ManagedNode.reach_subscribers``).

The driver's first frame recorded: the launch file also names the driver's topics
(:data:`~kinect_bringup.graph.INPUTS`) in ``wait_for_publishers``; the recorder subscribes to them
as above and finishes its activation only once those subscriptions have met the driver's
publishers (at most :data:`INPUTS_WAIT_S`). The launch files activate the driver last, once every
other node is active, so it starts with the recorder listening."""
from __future__ import annotations

import importlib
import threading
import time
from pathlib import Path

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from skeleton_core.bag_split import pieces_dir
from skeleton_core.rosnode import ManagedNode, ParamSpec, Parameters, run_node
from skeleton_core.tf_ros import STATIC_LISTENER_QOS, TF_STATIC_TOPIC, take_waiting

from .graph import INPUTS, TOPICS

PUBLISHERS_WAIT_S = 10.0   # then the input is recorded anyway (with a warning naming the topics)
INPUTS_WAIT_S = 5.0        # the input's publishers named in wait_for_publishers: then active anyway
# once every awaited publisher is seen, the input waits this much longer: the publishers' side of
# the match (module docstring)
MATCH_SETTLE_S = 0.5
LATCHED = (TF_STATIC_TOPIC, '/kinect/tracker')   # transient local: nothing lost by joining late
LATCHED_TAKE_S = 1.0   # how often the latched topics' subscriptions are checked for a message


def _msg_class(msgtype: str):
    pkg, _, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{pkg}.msg'), name)


PARAMS = [
    ParamSpec('output', 'out/recording.mcap',
              'MCAP file to write (a finished bag there is overwritten; an unfinished one, left by '
              'a killed recorder, is moved aside)', read_only=True),
    ParamSpec('topics', list(TOPICS), 'topics to record (types from the graph table)',
              read_only=True),
    ParamSpec('flush_period', 0.25,
              'write what was received to the file at least this often (s): a killed recorder '
              'loses at most this much; 0 = only full 1 MiB chunks', range=(0.0, 60.0),
              read_only=True),
    ParamSpec('wait_for_publishers', [''],
              'recorded topics whose publishers the recorder waits for before it is active (set '
              'by the launch file: the topics of the nodes it starts; the input is subscribed '
              'once the outputs have theirs; [""] = none)', read_only=True),
    ParamSpec('fsync', True, 'also force each flush onto the disk (survives a power cut)',
              read_only=True),
    ParamSpec('split_size_mb', 0.0,
              'start a new piece when the current one holds this many MB (2**20 bytes; within '
              'one 1 MiB chunk): the recording becomes a folder of complete bags named after '
              'output; 0 = no size limit', range=(0.0, 1e6), read_only=True),
    ParamSpec('split_duration_s', 0.0,
              'start a new piece when the next message comes this long after the first one of '
              'the current piece (receive times); 0 = no duration limit', range=(0.0, 1e6),
              read_only=True),
]


class RecorderNode(ManagedNode):
    """Subscribes to every configured topic and appends each message to one MCAP file: opened on
    configure, written while active, closed (a complete bag) on cleanup / shutdown."""

    def __init__(self, **kwargs):
        super().__init__('recorder', **kwargs)
        self._lock = threading.Lock()
        self._writer = None
        self.counts = {}
        self.params = Parameters(self, PARAMS)

    def configure(self) -> None:
        from skeleton_core.bag_split import SplitBagWriter
        for topic in self.params['topics']:
            if topic not in TOPICS:
                raise ValueError(f'recorder: unknown topic {topic!r} (known: {sorted(TOPICS)})')
        self.path = Path(self.params['output']).expanduser().resolve()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._keep_unfinished()
        self._writer = SplitBagWriter(
            self.path, split_size_bytes=int(self.params['split_size_mb'] * 2 ** 20),
            split_duration_s=self.params['split_duration_s'], on_piece=self._piece_done,
            flush_period_s=self.params['flush_period'], fsync=self.params['fsync'])
        self.split = self._writer.policy.enabled
        self.counts = {topic: 0 for topic in self.params['topics']}
        self.diagnostics()

    def activate(self) -> None:
        if self.params['flush_period'] > 0:
            self.timer(min(0.5, self.params['flush_period']), self._poll)
        topics = list(self.params['topics'])   # (checked on configure)
        wait = [t for t in self.params['wait_for_publishers'] if t in topics]
        outputs = {t: self._subscribe(t) for t in wait if t not in INPUTS}
        self._latched_subs = {t: outputs.get(t) or self._subscribe(t) for t in LATCHED
                              if t in topics}
        # a latched topic sends its message once: one whose executor wake-up was lost (the
        # middleware can lose it for a subscription made in a transition) is taken by this timer
        self.timer(LATCHED_TAKE_S, self._take_latched)
        self._inputs = [t for t in topics if t not in outputs and t not in LATCHED]
        self._input_subs = {}
        seen_at = []

        def outputs_missing():
            left = [t for t, sub in outputs.items() if _publishers(sub) == 0]
            if not left and not seen_at:
                seen_at.append(time.monotonic())
            return left
        self.when_ready(outputs_missing, self._subscribe_inputs, PUBLISHERS_WAIT_S,
                        'no publisher; recording the input anyway (the first frames\' outputs '
                        'may be missing)')
        seen_at = seen_at or [time.monotonic()]

        def inputs_missing():
            left = [t for t in wait if t in self._input_subs
                    and _publishers(self._input_subs[t]) == 0]
            if not left and outputs and time.monotonic() - seen_at[0] < MATCH_SETTLE_S:
                return ['(the publishers\' side of the match)']
            return left
        # active once the input's subscriptions met their publishers (the driver, activated
        # last, then starts with this recorder listening) and the outputs' publishers had
        # MATCH_SETTLE_S to meet this recorder
        self.when_ready(inputs_missing, self._recording, INPUTS_WAIT_S,
                        'no publisher met; recording anyway (the first input frames may be '
                        'missing)')

    def _subscribe(self, topic: str):
        msgtype = TOPICS[topic]
        # raw=True: the serialized bytes go to the bag as received (no decode/encode); the
        # latched /tf_static as tf2 subscribes to it (every broadcaster's last message), and
        # the stream's tracker, latched too (skeleton_core.tracker)
        if topic == TF_STATIC_TOPIC:
            qos = STATIC_LISTENER_QOS
        elif topic == '/kinect/tracker':
            qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        else:
            qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        return self.subscription(_msg_class(msgtype), topic,
                                 lambda data, t=topic, mt=msgtype: self._on_msg(t, mt, data),
                                 qos, raw=True)

    def _subscribe_inputs(self) -> None:
        self._input_subs = {topic: self._subscribe(topic) for topic in self._inputs}

    def _recording(self) -> None:
        where = (f'pieces in {pieces_dir(self.path)}/ (split at '
                 + ' or '.join(x for x in (
                     f'{self.params["split_size_mb"]:g} MB' if self.params['split_size_mb'] else '',
                     f'{self.params["split_duration_s"]:g} s' if self.params['split_duration_s']
                     else '') if x) + ')') if self.split else str(self.path)
        self.get_logger().info(f'recording {len(self.counts)} topics to {where}')

    def cleanup(self) -> None:
        self.close()

    def _on_msg(self, topic, msgtype, msg):
        self.health.on_receive()
        now = self.get_clock().now().nanoseconds
        with self._lock:
            if self._writer is None:
                return
            self._writer.write_raw(topic, msg, now, msgtype=msgtype)  # CDR bytes as received
            self.counts[topic] += 1
        self.health.on_publish()

    def _piece_done(self, path):
        self.get_logger().info(f'finished piece {path.name} ({path.stat().st_size / 2 ** 20:.1f} '
                               'MB)')

    def _keep_unfinished(self):
        """An unfinished bag at the output path is the recording of a recorder that was killed
        (a restarted node, a respawn): moved aside, never overwritten. With splitting, the folder
        of pieces: moved aside when a piece is unfinished, else its old pieces are replaced."""
        from skeleton_core.bagio import BagError, finished
        if self.params['split_size_mb'] or self.params['split_duration_s']:
            self._keep_unfinished_pieces()
            return
        if not self.path.is_file():
            return
        try:
            if finished(self.path):
                return
        except BagError:
            return   # not a bag at all: overwritten as documented
        stamp = time.strftime('%Y%m%d-%H%M%S')
        aside = self.path.with_name(f'{self.path.stem}.unfinished-{stamp}{self.path.suffix}')
        self.path.rename(aside)
        self.get_logger().warning(
            f'{self.path.name} is an unfinished recording (a killed recorder\'s): kept as '
            f'{aside} (ros2 run kinect_bringup recover_bag {aside})')

    def _keep_unfinished_pieces(self):
        from skeleton_core.bagio import BagError, finished
        d = pieces_dir(self.path)
        if not d.is_dir():
            return
        old = sorted(d.glob(f'{d.name}_*.mcap'))
        try:
            cut = [p for p in old if not finished(p)]
        except BagError:
            cut = []
        if not cut:
            for p in old:
                p.unlink()
            return
        aside = d.with_name(f'{d.name}.unfinished-{time.strftime("%Y%m%d-%H%M%S")}')
        d.rename(aside)
        self.get_logger().warning(
            f'{d} holds an unfinished recording (a killed recorder\'s): kept as {aside} '
            f'(ros2 run kinect_bringup recover_bag {aside})')

    def _take_latched(self) -> None:
        """The latched topics' messages waiting on their subscriptions, recorded as if the
        executor had delivered them (which it does first, when its wake-up came)."""
        for topic, sub in self._latched_subs.items():
            for msg in take_waiting(sub):
                self._on_msg(topic, TOPICS[topic], msg)

    def _poll(self):
        with self._lock:
            if self._writer is not None:
                self._writer.poll()

    def close(self):
        with self._lock:
            if self._writer is not None:
                self._writer.__exit__(None, None, None)
                pieces = self._writer.pieces
                self._writer = None
                what = (f'{len(pieces)} pieces in {pieces_dir(self.path)}' if self.split
                        else str(self.path))
                self.get_logger().info(
                    f'wrote {what}: ' + ', '.join(f'{t} {n}' for t, n in self.counts.items()))


def _publishers(sub) -> int:
    """Publishers matched by ``sub`` (rclpy before Jazzy cannot tell: counted as one)."""
    count = getattr(sub, 'get_publisher_count', None)
    return count() if count is not None else 1


def main(args=None):
    return run_node(RecorderNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
