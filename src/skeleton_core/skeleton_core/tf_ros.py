"""TF over DDS without tf2_ros: ``tf2_msgs/TFMessage`` <-> :mod:`skeleton_core.tf`, the static
broadcaster's QoS, and a listener that keeps a :class:`~skeleton_core.tf.TfBuffer` up to date.

``/tf_static`` is latched as tf2 does it: each static broadcaster publishes *all* its transforms
in one message (QoS reliable, transient_local, depth 1) and a late subscriber (transient_local,
depth 100, as tf2's listener) receives every broadcaster's last message.
"""
from __future__ import annotations

from typing import Callable, Iterable, List, Optional, Tuple

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from .tf import TfBuffer, Transform, transforms_from_msg

TF_STATIC_TOPIC = '/tf_static'
STATIC_BROADCASTER_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                                    reliability=ReliabilityPolicy.RELIABLE,
                                    durability=DurabilityPolicy.TRANSIENT_LOCAL)
STATIC_LISTENER_QOS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                                 reliability=ReliabilityPolicy.RELIABLE,
                                 durability=DurabilityPolicy.TRANSIENT_LOCAL)


def to_tf_message(items: Iterable[Tuple[str, str, Transform]], stamp=None):
    """A ``tf2_msgs/TFMessage`` of ``(parent, child, Transform)`` items (``stamp``: a
    ``builtin_interfaces/Time``; default zero, as static transforms are valid at any time)."""
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage
    out = []
    for parent, child, t in items:
        m = TransformStamped()
        if stamp is not None:
            m.header.stamp = stamp
        m.header.frame_id = parent
        m.child_frame_id = child
        tx, ty, tz = (float(v) for v in t.translation)
        m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = tx, ty, tz
        q = m.transform.rotation
        q.x, q.y, q.z, q.w = (float(v) for v in t.rotation)
        out.append(m)
    return TFMessage(transforms=out)


def from_tf_message(msg) -> List[Tuple[str, str, Transform]]:
    """The ``(parent, child, Transform)`` items of a ``TFMessage`` (see
    :func:`skeleton_core.tf.transforms_from_msg`)."""
    return transforms_from_msg(msg)


def take_waiting(sub):
    """The messages waiting on the rclpy subscription ``sub``, taken now, oldest first (what its
    executor would deliver once woken)."""
    while True:
        with sub.handle:
            taken = sub.handle.take_message(sub.msg_type, sub.raw)
        if taken is None:
            return
        yield taken[0]


class StaticTfListener:
    """Subscribes ``node`` to ``/tf_static`` and fills ``buffer``. ``on_change()`` is called after
    a message changed the tree; a malformed message is logged once per sender frame and skipped.

    Look frames up with :meth:`lookup` / :meth:`missing`, not on the buffer alone: a miss first
    takes the messages waiting on the subscription. The executor delivers a message only when the
    middleware wakes it, and that wake-up can be lost: rmw_fastrtps counts the unread samples
    before it installs the executor's new-message callback, so a latched message that arrives in
    between (a subscription created in a lifecycle transition, matching a publisher that is
    already up) waits on the subscription unannounced. /tf_static sends nothing more, so the node
    would wait for its frames for ever ("known: none")."""

    def __init__(self, node, buffer: Optional[TfBuffer] = None,
                 on_change: Optional[Callable[[], None]] = None):
        from tf2_msgs.msg import TFMessage
        self.node = node
        self.buffer = buffer if buffer is not None else TfBuffer()
        self.on_change = on_change
        self.bad = 0
        self.received = 0   # messages applied (delivered or taken by poll)
        self._warned = set()
        self._said_taken = False
        self.sub = node.create_subscription(TFMessage, TF_STATIC_TOPIC, self._on_msg,
                                            STATIC_LISTENER_QOS)

    def _on_msg(self, msg) -> None:
        self.received += 1
        before = self.buffer.version
        for m in msg.transforms:
            try:
                self.buffer.update(from_tf_message(type(msg)(transforms=[m])))
            except ValueError as e:
                self.bad += 1
                if str(e) not in self._warned:
                    self._warned.add(str(e))
                    self.node.get_logger().warning(f'/tf_static: ignored a transform: {e}')
        if self.buffer.version != before and self.on_change is not None:
            self.on_change()

    def poll(self) -> int:
        """Apply the messages waiting on the subscription now (returns how many): for a node
        that waits for a frame inside one of its callbacks (its activation), where its executor
        cannot deliver them, and for a message whose wake-up the executor never got."""
        n = 0
        for msg in take_waiting(self.sub):
            n += 1
            self._on_msg(msg)
        return n

    def lookup(self, target: str, source: str) -> Transform:
        """``buffer.lookup(target, source)``; on a miss, again after :meth:`poll` (which calls
        ``on_change`` first when it took a message that changed the tree). Raises
        ``LookupError`` as the buffer does, with the publishers matched and messages received."""
        try:
            return self.buffer.lookup(target, source)
        except LookupError:
            taken = self.poll()
        try:
            out = self.buffer.lookup(target, source)
        except LookupError as e:   # what tells a publisher not (yet) met from a message lost
            raise LookupError(f'{e}; /tf_static: {self.sub.get_publisher_count()} publisher(s) '
                              f'matched, {self.received} message(s) received') from None
        if not taken:
            return out
        if not self._said_taken:   # (evidence of a lost wake-up, or of one still on its way)
            self._said_taken = True
            self.node.get_logger().info(f'/tf_static: {source} found in {taken} message(s) '
                                        'waiting on the subscription, not yet delivered')
        return out

    def missing(self, frames: Iterable[str], target: str) -> List[str]:
        """Of ``frames``, those TF cannot map into ``target`` yet (after :meth:`poll`)."""
        self.poll()
        return [f for f in frames if f and not self.buffer.can_transform(target, f)]

    def destroy(self) -> None:
        self.node.destroy_subscription(self.sub)


class StaticTfBroadcaster:
    """tf2's ``StaticTransformBroadcaster``: every transform sent so far, in one latched message."""

    def __init__(self, node):
        from tf2_msgs.msg import TFMessage
        self.node = node
        self.pub = node.create_publisher(TFMessage, TF_STATIC_TOPIC, STATIC_BROADCASTER_QOS)
        self._items = {}

    def send(self, items: Iterable[Tuple[str, str, Transform]]) -> None:
        for parent, child, t in items:
            self._items[child] = (parent, child, t)
        stamp = self.node.get_clock().now().to_msg()
        self.pub.publish(to_tf_message(self._items.values(), stamp))


__all__ = ['TF_STATIC_TOPIC', 'STATIC_BROADCASTER_QOS', 'STATIC_LISTENER_QOS', 'to_tf_message',
           'from_tf_message', 'StaticTfListener', 'StaticTfBroadcaster']
