"""A REP-155 consumer written against the REP alone: plain rclpy, its own TF buffer from /tf and
/tf_static messages, /humans/bodies/tracked, each body's URDF and joint states, and forward
kinematics of the URDF (a generic URDF reader). Used by the hri node's tests."""
from __future__ import annotations

import struct
import threading
import time
from typing import Dict, List, Optional, Tuple

import numpy as np
import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from ros_helpers import Spinner
from skeleton_core.kinematic_tree import forward_kinematics_urdf
from skeleton_core.tf import Transform

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
STATIC = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.TRANSIENT_LOCAL)


_U32, _STAMP, _SEVEN = struct.Struct('<I'), struct.Struct('<iI'), struct.Struct('<7d')


def decode_tf(data: bytes):
    """(stamp ns, parent, child, (x, y, z), (qx, qy, qz, qw)) of every transform of a serialized
    ``tf2_msgs/TFMessage`` (XCDR1 little endian, what rclpy publishes)."""
    if data[1] != 1:
        raise ValueError('big-endian CDR')
    buf = memoryview(data)[4:]
    pos = 0

    def string(pos):
        pos += (-pos) % 4
        n = _U32.unpack_from(buf, pos)[0]
        return bytes(buf[pos + 4:pos + 3 + n]).decode(), pos + 4 + n
    (count,) = _U32.unpack_from(buf, 0)
    pos = 4
    out = []
    for _ in range(count):
        pos += (-pos) % 4
        sec, nsec = _STAMP.unpack_from(buf, pos)
        parent, pos = string(pos + 8)
        child, pos = string(pos)
        pos += (-pos) % 8
        v = _SEVEN.unpack_from(buf, pos)
        pos += 56
        out.append((sec * 10**9 + nsec, parent, child, v[:3], v[3:]))
    return out


class TfHistory:
    """tf2's buffer in small: every transform by (child, stamp ns), static ones for any time;
    :meth:`lookup` chains them up to the common ancestor at one stamp."""

    def __init__(self):
        self.dynamic: Dict[str, Dict[int, tuple]] = {}   # child -> stamp -> (parent, t, q)
        self.static: Dict[str, tuple] = {}
        self.arrival: Dict[str, float] = {}

    def add(self, data: bytes, static: bool) -> None:
        """A serialized TFMessage (decoded here: rclpy's deserializer takes ~7 ms for the 180
        transforms of two bodies, more than a loaded machine leaves this process at 60 Hz)."""
        now = time.monotonic()
        for stamp, parent, child, t, q in decode_tf(data):   # (a Transform is made on lookup)
            item = (parent, t, q)
            if static:
                self.static[child] = item
            else:
                d = self.dynamic.setdefault(child, {})
                d[stamp] = item
                if len(d) > 600:
                    for k in sorted(d)[:-300]:
                        del d[k]
                self.arrival[child] = now

    def _parent(self, frame: str, stamp: int):
        item = self.static.get(frame) or self.dynamic.get(frame, {}).get(stamp)
        return None if item is None else (item[0], Transform(item[1], item[2]))

    def _to_top(self, frame: str, stamp: int) -> List[Tuple[str, Transform]]:
        chain, t, f = [(frame, Transform())], Transform(), frame
        while True:
            step = self._parent(f, stamp)
            if step is None:
                return chain
            f, t = step[0], step[1] * t
            chain.append((f, t))

    def lookup(self, target: str, source: str, stamp: int) -> Optional[Transform]:
        """``p_target = T p_source`` at ``stamp`` (None: not connected at that stamp)."""
        up_s = self._to_top(source, stamp)
        up_t = dict(self._to_top(target, stamp))
        for f, t_s in up_s:
            if f in up_t:
                return up_t[f].inverse() * t_s
        return None


class Consumer:
    """Subscribes to REP-155's topics (and any extra ``{topic: type}``) in its own context."""

    def __init__(self, extra: Optional[Dict[str, type]] = None, name: str = 'rep155_consumer',
                 domain_id: Optional[int] = None):
        from hri_msgs.msg import IdsList
        from tf2_msgs.msg import TFMessage
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node(name, context=self.context)
        self.lock = threading.Lock()
        self.tf = TfHistory()
        self.tracked: List[Tuple[float, List[str]]] = []
        self.urdf: Dict[str, str] = {}
        self.joint_states: Dict[str, Dict[int, Dict[str, float]]] = {}
        self.extra: Dict[str, List] = {t: [] for t in (extra or {})}
        self._subs = {}
        n = self.node
        n.create_subscription(TFMessage, '/tf', lambda m: self._tf(m, False),
                              QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE),
                              raw=True)
        n.create_subscription(TFMessage, '/tf_static', lambda m: self._tf(m, True), STATIC,
                              raw=True)
        n.create_subscription(IdsList, '/humans/bodies/tracked', self._on_tracked, 10)
        for topic, cls in (extra or {}).items():
            n.create_subscription(cls, topic, lambda m, t=topic: self._on_extra(t, m),
                                  LATCHED if topic.endswith('description') else 300)
        self._spinner = Spinner(self.context, n)

    def _tf(self, msg, static):
        with self.lock:
            self.tf.add(msg, static)

    def _on_extra(self, topic, msg):
        with self.lock:
            self.extra[topic].append(msg)
            del self.extra[topic][:-400]

    def _on_tracked(self, msg):
        from sensor_msgs.msg import JointState
        from std_msgs.msg import String
        with self.lock:
            self.tracked.append((time.monotonic(), list(msg.ids)))
        for bid in msg.ids:   # REP-155: per body, its URDF (latched) and joint states
            if bid not in self._subs:
                self._subs[bid] = (
                    self.node.create_subscription(
                        String, f'/humans/bodies/{bid}/urdf',
                        lambda m, b=bid: self._on_urdf(b, m), LATCHED),
                    self.node.create_subscription(
                        JointState, f'/humans/bodies/{bid}/joint_states',
                        lambda m, b=bid: self._on_js(b, m), 300))

    def _on_urdf(self, bid, msg):
        with self.lock:
            self.urdf[bid] = msg.data

    def _on_js(self, bid, msg):
        # as robot_state_publisher does: joint states apply to the URDF received before them
        stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
        with self.lock:
            d = self.joint_states.setdefault(bid, {})
            d[stamp] = (dict(zip(msg.name, msg.position)), self.urdf.get(bid))
            for k in sorted(d)[:-300]:
                del d[k]

    def last_tracked(self) -> List[str]:
        with self.lock:
            return list(self.tracked[-1][1]) if self.tracked else []

    def body_positions(self, bid: str, frames: List[str], stamp: int, fixed: str):
        """(joint frame positions in ``fixed`` by FK of the body's URDF and joint states at
        ``stamp``, the same by TF lookups); None where something is missing."""
        with self.lock:
            js, urdf = self.joint_states.get(bid, {}).get(stamp, (None, None))
            root = self.tf.lookup(fixed, f'body_{bid}', stamp)
            by_tf = [self.tf.lookup(fixed, f, stamp) for f in frames]
        if urdf is None or js is None or root is None:
            return None, None
        poses = forward_kinematics_urdf(urdf, js)
        fk = np.array([root.apply(poses[f][1]) for f in frames])
        tf = None if any(t is None for t in by_tf) else np.array([t.translation for t in by_tf])
        return fk, tf

    def close(self):
        self._spinner.stop()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)
