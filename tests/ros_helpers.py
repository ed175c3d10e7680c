"""Helpers for tests that talk to running nodes over real DDS."""
from __future__ import annotations

import importlib
import threading
import time
import traceback
from typing import Dict, Iterable, List, Optional

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy


def wait_until(cond, timeout: float, step: float = 0.02) -> bool:
    """Poll ``cond()`` until it is true or ``timeout`` s passed; its last value."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(step)
    return bool(cond())


def call_until_answered(client, request, timeout: float, every: float = 2.0):
    """The response to a request that is harmless to repeat (a query, setting a value), sent
    again every ``every`` s until answered: the first reply of a fresh client can be lost while
    DDS is still matching the reply path (rmw: "failed to send response (timeout)")."""
    from skeleton_core.lifecycle_client import call_once
    deadline = time.monotonic() + timeout
    if not client.wait_for_service(timeout_sec=timeout):
        raise TimeoutError(f'service {client.srv_name} not available')
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError(f'service {client.srv_name} did not answer')
        reply = call_once(client, request, min(every, left))
        if reply is not None:
            return reply


def msg_class(msgtype: str):
    pkg, _, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{pkg}.msg'), name)


class Spinner:
    """Spins ``nodes`` on one executor thread until :meth:`stop`, which lets the callback in
    flight finish before shutting the executor down: rclpy's ``Executor.shutdown`` does not
    wait for running callbacks (its wait is skipped), so shutting down a spinning
    MultiThreadedExecutor destroys its guard condition under them ("exception never retrieved:
    cannot use Destroyable" at exit)."""

    def __init__(self, context, *nodes):
        self.context = context
        self.executor = SingleThreadedExecutor(context=context)
        for n in nodes:
            self.executor.add_node(n)
        self._running = True
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self):
        while self._running and self.context.ok():
            self.executor.spin_once(timeout_sec=0.05)

    def stop(self):
        self._running = False
        self._thread.join(timeout=5)
        self.executor.shutdown()


class Probe:
    """A node in its own context and spin thread that records arrival times (and the last few
    messages) on a set of topics, and can query/set parameters of other nodes."""

    def __init__(self, topics: Dict[str, str], name: str = 'test_probe', keep: int = 50,
                 domain_id: Optional[int] = None):
        self.context = rclpy.Context()
        # domain_id: listen on another DDS domain than this process's ROS_DOMAIN_ID (a graph
        # started with its own domain cannot be confused with another graph still running)
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = Node(name, context=self.context)
        self.times: Dict[str, List[float]] = {t: [] for t in topics}
        self.messages: Dict[str, List] = {t: [] for t in topics}
        self._keep = keep
        self._lock = threading.Lock()
        self.errors: List[str] = []   # exceptions raised while spinning (printed as they happen)
        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        self._types = {t: msg_class(ty) for t, ty in topics.items()}
        for topic, cls in self._types.items():
            # raw: count arrivals without deserializing (a MarkerArray costs ms in Python);
            # messages are deserialized only when a test asks for them
            self.node.create_subscription(cls, topic, lambda m, t=topic: self._cb(t, m), qos,
                                          raw=True)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._running = True
        self._thread.start()

    def _spin(self):
        while self._running and self.context.ok():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except Exception as e:  # noqa: BLE001
                if not (self._running and self.context.ok()):
                    break   # shut down under us
                # anything else (an exception in a callback): reported and spun on; a probe
                # whose thread ended here would go deaf and fail every later test of its
                # module with "no output", hiding the one error that mattered
                self.errors.append(f'{type(e).__name__}: {e}')
                traceback.print_exc()

    def _cb(self, topic, msg):
        with self._lock:
            self.times[topic].append(time.monotonic())
            self.messages[topic].append(msg)
            if len(self.messages[topic]) > self._keep:
                self.messages[topic].pop(0)

    def reset(self):
        with self._lock:
            for t in self.times:
                self.times[t].clear()
                self.messages[t].clear()

    def wait_for(self, topics: Iterable[str], count: int = 1, timeout: float = 30.0) -> bool:
        deadline = time.monotonic() + timeout
        topics = list(topics)
        while time.monotonic() < deadline:
            with self._lock:
                if all(len(self.times[t]) >= count for t in topics):
                    return True
            time.sleep(0.05)
        return False

    def rate(self, topic: str, window: float) -> float:
        """Messages per second over the last ``window`` seconds."""
        now = time.monotonic()
        with self._lock:
            n = sum(1 for t in self.times[topic] if t > now - window)
        return n / window

    def counts(self) -> Dict[str, int]:
        with self._lock:
            return {t: len(v) for t, v in self.times.items()}

    def messages_of(self, topic: str) -> List:
        """Every kept message of ``topic``, oldest first, deserialized from one snapshot taken
        under the lock (the spin thread keeps appending, and drops the oldest beyond ``keep``:
        indices taken before reading would shift under a reader on a loaded machine)."""
        from rclpy.serialization import deserialize_message
        with self._lock:
            raw = list(self.messages[topic])
        return [deserialize_message(d, self._types[topic]) for d in raw]

    def last(self, topic: str):
        from rclpy.serialization import deserialize_message
        with self._lock:
            data = self.messages[topic][-1] if self.messages[topic] else None
        return None if data is None else deserialize_message(data, self._types[topic])

    # ---- parameters of other nodes --------------------------------------------------------
    def _call(self, srv_type, name: str, request, timeout: float = 10.0):
        client = self.node.create_client(srv_type, name)
        try:
            return call_until_answered(client, request, timeout)
        finally:
            self.node.destroy_client(client)

    def get_parameters(self, node: str, names: Optional[List[str]] = None) -> Dict:
        from rcl_interfaces.srv import GetParameters, ListParameters
        from rclpy.parameter import parameter_value_to_python
        if names is None:
            res = self._call(ListParameters, f'{node}/list_parameters', ListParameters.Request())
            names = [n for n in res.result.names if n != 'use_sim_time'
                     and not n.startswith('qos_overrides')]
        res = self._call(GetParameters, f'{node}/get_parameters', GetParameters.Request(names=names))
        return {n: parameter_value_to_python(v) for n, v in zip(names, res.values)}

    def set_parameter(self, node: str, name: str, value):
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter
        req = SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()])
        return self._call(SetParameters, f'{node}/set_parameters', req).results[0]

    def close(self):
        self._running = False
        self._thread.join(timeout=2)
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
