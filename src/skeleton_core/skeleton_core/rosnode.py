"""Small rclpy adapters shared by every node: validated parameters with descriptors, diagnostics,
and a ``main()`` runner with a clean Ctrl-C shutdown.

This is the only module of ``skeleton_core`` that imports rclpy; library modules never import it.
"""
from __future__ import annotations

import os
import signal
import sys
import threading
import time
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence

import rclpy
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.exceptions import ParameterException
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions

from .cdr import CdrError, frames_from_cdr
from .health import Health
from .input_watch import SILENT, InputWatch
from .memory import open_files, rss_mb
from .params import ParamSpec  # noqa: F401 (declared in params, re-exported for the nodes)


def descriptor(spec: ParamSpec) -> ParameterDescriptor:
    """The ROS descriptor of a :class:`~skeleton_core.params.ParamSpec`."""
    d = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    if spec.choices is not None:
        d.additional_constraints = f'one of {list(spec.choices)}'
    if spec.range is not None and not isinstance(spec.default, bool):
        lo, hi = spec.range
        if isinstance(spec.default, float):
            d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi))]
        elif isinstance(spec.default, int):
            d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
    return d


class Parameters:
    """Declares the public :class:`ParamSpec` s on a node and keeps the current values in
    ``values``. A spec with ``public=False`` (set by a preset only, ``skeleton_core.params``) is
    not declared: its default stays in ``values``. A parameter file or ``-p`` naming a parameter
    the node does not declare is refused with one line (rclpy would silently ignore it).

    Two callbacks, as rclpy separates them: the on-set callback only *validates* (each value
    against its spec, then ``validate(values_after, changed)`` for cross-parameter checks: an
    error text refuses the whole set, nothing else happens); the post-set callback *applies*
    (``values`` updated, then ``apply(changed)`` pushes the new values into the library objects,
    reloads a file...). ``apply`` cannot refuse any more: what may fail is checked in
    ``validate``, what still fails (a file corrupt beyond what a check sees) is logged there."""

    def __init__(self, node: Node, specs: Iterable[ParamSpec],
                 validate: Optional[Callable[[Dict[str, Any], Dict[str, Any]], Optional[str]]] = None,
                 apply: Optional[Callable[[Dict[str, Any]], None]] = None):
        self._node = node
        every = list(specs)
        self.specs = {s.name: s for s in every if s.public}
        self.values: Dict[str, Any] = {s.name: s.default for s in every if not s.public}
        self._validate = validate
        self._apply = apply
        try:
            check_overrides(node, self.specs, {s.name for s in every if not s.public})
            for s in self.specs.values():
                p = node.declare_parameter(s.name, s.default, descriptor(s))
                value = self._typed(s, p.value)
                err = s.check(value)
                if err is not None:
                    raise ValueError(f'invalid parameter: {err}')
                self.values[s.name] = value
        except Exception:
            # the constructor fails: nobody will ever hold this node to destroy it, and an
            # undestroyed node stays on the graph (its services still discoverable, answering
            # nothing) for as long as the process lives
            node.destroy_node()
            raise
        node.add_on_set_parameters_callback(self._on_set)
        node.add_post_set_parameters_callback(self._post_set)

    def __getitem__(self, name: str) -> Any:
        return self.values[name]

    @staticmethod
    def _typed(spec: ParamSpec, value: Any) -> Any:
        if isinstance(spec.default, float) and isinstance(value, int) and not isinstance(value, bool):
            return float(value)
        return value

    def _changed(self, params: Sequence[Parameter]) -> Dict[str, Any]:
        return {p.name: self._typed(self.specs[p.name], p.value)
                for p in params if p.name in self.specs}

    def _on_set(self, params: Sequence[Parameter]) -> SetParametersResult:
        """Validation only: no state of the node changes here."""
        changed = self._changed(params)
        for name, value in changed.items():
            spec = self.specs[name]
            err = spec.check(value)
            if err is None and spec.read_only:
                err = f'{name} is read-only'
            if err is not None:
                self._node.get_logger().warning(f'refused parameter change: {err}')
                return SetParametersResult(successful=False, reason=err)
        if changed and self._validate is not None:
            err = self._validate({**self.values, **changed}, changed)
            if err:
                self._node.get_logger().warning(f'refused parameter change: {err}')
                return SetParametersResult(successful=False, reason=err)
        return SetParametersResult(successful=True)

    def _post_set(self, params: Sequence[Parameter]) -> None:
        """The accepted values take effect."""
        changed = self._changed(params)
        if not changed:
            return
        self.values.update(changed)
        self._node.get_logger().info(
            'parameters set: ' + ', '.join(f'{k}={v!r}' for k, v in changed.items()))
        if self._apply is not None:
            self._apply(changed)


# parameters rclpy itself reads from the overrides (declared by Node, or QoS overrides)
_RCLPY_PARAMS = ('use_sim_time', 'start_type_description_service')


def check_overrides(node: Node, declared: Iterable[str], fixed: Iterable[str] = ()) -> None:
    """Raise ValueError (one line) when the node's parameter overrides (its YAML files, ``-p``,
    launch ``parameters=``) name a parameter outside ``declared``: a misspelt or removed name
    would otherwise be ignored without a word. ``fixed``: names the node keeps as fixed values
    (set by a preset in the evaluation, not on a node), said so in the message."""
    overrides = getattr(node, '_parameter_overrides', None) or {}
    known = set(declared) | set(_RCLPY_PARAMS) | set(getattr(node, '_parameters', {}))
    unknown = sorted(n for n in overrides
                     if n not in known and not n.startswith('qos_overrides.'))
    if not unknown:
        return
    fixed = set(fixed)
    preset = [n for n in unknown if n in fixed]
    what = (f'{unknown[0]!r} is not a parameter of node {node.get_name()!r}'
            + (' (a fixed value of the library, set only by a preset file in config/presets)'
               if preset and preset[0] == unknown[0] else ' (removed or misspelt)'))
    more = f'; also {", ".join(unknown[1:])}' if len(unknown) > 1 else ''
    raise ValueError(f'{what}{more}: see docs/parameters.md')


class InputDrops:
    """What a node does with input it cannot use: counts the drop per cause in its :class:`Health`
    (reported on /diagnostics) and logs the first drop of each cause, with the detail, once.
    ``drops(cause, detail)`` drops one input; :meth:`decode` reads a SkeletonArray message."""

    def __init__(self, health: Health, logger):
        self.health = health
        self.logger = logger

    def __call__(self, cause: str, detail: str = '') -> None:
        if self.health.on_drop(cause):
            self.logger.warning(f'dropping input ({cause}){": " + detail if detail else ""}'
                                ' (logged once per cause)')

    def decode(self, data: bytes) -> Optional[tuple]:
        """``(stamp_ns, frame_id, frames)`` of a serialized SkeletonArray, the malformed skeletons
        in it dropped by their cause; None (dropped as 'malformed message') when it cannot be
        decoded at all."""
        errors: list = []
        try:
            decoded = frames_from_cdr(data, errors)
        except CdrError as e:  # undecodable: a dropped message, not a crash
            self('malformed message', str(e))
            return None
        for e in errors:
            self(getattr(e, 'cause', 'malformed'), str(e))
        return decoded


class DiagnosticsPublisher:
    """Publishes a node's :class:`Health` on ``/diagnostics`` (diagnostic_msgs/DiagnosticArray),
    with the process's resident memory (``rss_mb``) and open files (``open_files``) so that a lab
    sees growth before it hurts; a node's ``extra`` adds ``user_states`` (the users it holds state
    for: a count that grows while nobody is in view is per-user state never let go)."""

    def __init__(self, node: Node, health: Health, period_s: float = 1.0,
                 extra: Optional[Callable[[], Dict[str, Any]]] = None,
                 state: Optional[Callable[[], str]] = None):
        from diagnostic_msgs.msg import DiagnosticArray  # noqa: F401 (fail early if missing)
        self._node = node
        self._health = health
        self._extra = extra
        self._state = state
        # a plain publisher, also on a lifecycle node: an inactive node still reports its state
        self._pub = Node.create_publisher(node, DiagnosticArray, '/diagnostics', 10)
        self._timer = node.create_timer(period_s, self._publish)

    def destroy(self) -> None:
        self._timer.cancel()
        self._node.destroy_timer(self._timer)
        self._node.destroy_publisher(self._pub)

    def _publish(self) -> None:
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
        snap = self._health.snapshot()
        snap['rss_mb'] = rss_mb()
        snap['open_files'] = open_files()
        if self._extra is not None:
            snap.update(self._extra())
        st = DiagnosticStatus()
        st.name = f'{self._node.get_fully_qualified_name()}'
        st.hardware_id = 'kinect_posture'
        dropped = snap.get('dropped_total', 0)
        state = self._state() if self._state is not None else 'active'
        silent = [k[len('silent_input['):-1] for k in snap if k.startswith('silent_input[')]
        if state != 'active':
            snap['state'] = state
            st.level, st.message = DiagnosticStatus.OK, state
        elif silent:   # (skeleton_core.input_watch; docs/recovery.md)
            st.level = DiagnosticStatus.WARN
            st.message = f'input {", ".join(silent)}: publisher matched, nothing received'
        elif snap.get('received', 0) > 0 and snap.get('rate_hz', 0.0) == 0.0:
            st.level, st.message = DiagnosticStatus.WARN, 'no output for > 2 s'
        elif dropped:
            st.level, st.message = DiagnosticStatus.OK, f'running, {dropped} inputs dropped'
        else:
            st.level, st.message = DiagnosticStatus.OK, 'running'
        st.values = [KeyValue(key=str(k), value=(f'{v:.3f}' if isinstance(v, float) else str(v)))
                     for k, v in snap.items()]
        msg = DiagnosticArray()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.status = [st]
        self._pub.publish(msg)


def fill_marker(m, position, quat, scale, rgba, text: str = '') -> None:
    """Pose (xyz, quaternion xyzw), scale, colour (rgba) and text of a visualization_msgs Marker."""
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(x) for x in position)
    (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
     m.pose.orientation.w) = (float(x) for x in quat)
    m.scale.x, m.scale.y, m.scale.z = (float(x) for x in scale)
    m.color.r, m.color.g, m.color.b, m.color.a = (float(x) for x in rgba)
    m.text = text


def ignore_further_interrupts() -> None:
    """Call when shutdown has begun: a second SIGINT must not interrupt the cleanup with a
    KeyboardInterrupt traceback. It comes routinely: Ctrl-C in a terminal reaches ``ros2 launch``
    and its nodes (one process group), and launch then forwards its own SIGINT to each node."""
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: signals are not ours to handle
        pass


# spin_until_shutdown: the longest a process goes on after its context was shut down
SPIN_SLICE_S = 0.25
# ManagedNode.reach_subscribers: how long a publish waits, once per change of the graph's count,
# for a subscriber the graph knows and the publisher has not reached yet
REACH_WAIT_S = 0.5
# ManagedNode.subscription(watch=True): how often the watched inputs are looked at (s)
WATCH_PERIOD_S = 1.0


def spin_until_shutdown(executor, context=None, stop=None) -> None:
    """Spin ``executor`` until ``context`` (default: the global one) is shut down, in slices of
    ``SPIN_SLICE_S``. ``executor.spin()`` waits in rcl_wait without a timeout for the guard
    condition rclpy's signal handler triggers, and with the pip wheels (Jazzy 7.1.6, Kilted)
    that wake-up is lost in about 1 of 10 SIGTERMs: the context is shut down, the process waits
    forever (a plain ``rclpy.spin`` node: 4 hangs in 40 SIGTERMs 1.5-3.5 s after start; this loop
    0 in 40). A lost wake-up now costs at most one slice. ``stop`` (a threading.Event): also
    ends when it is set (run_node's signal handler)."""
    ctx = context if context is not None else rclpy.get_default_context()
    while ctx.ok() and not (stop is not None and stop.is_set()):
        executor.spin_once(timeout_sec=SPIN_SLICE_S)


# The executor of a node's own process (run_node): KINECT_EXECUTOR=auto (default: rclpy's events
# executor where it exists, Jazzy and newer; else the single-threaded one), events or single.
# The single-threaded executor rebuilds its wait set -- every subscription, timer and the
# lifecycle node's five services -- in Python on every wake-up; the events executor waits in C++
# and runs only what is ready.
EXECUTOR_ENV = 'KINECT_EXECUTOR'
EXECUTOR_KINDS = ('auto', 'events', 'single')


def node_executor(kind: Optional[str] = None):
    """The executor that spins one node process (``kind``: default ``$KINECT_EXECUTOR`` or
    ``auto``)."""
    kind = (kind or os.environ.get(EXECUTOR_ENV) or 'auto').strip().lower()
    if kind not in EXECUTOR_KINDS:
        raise ValueError(f'{EXECUTOR_ENV}={kind!r} is not one of {list(EXECUTOR_KINDS)}')
    if kind in ('auto', 'events'):
        from skeleton_core.compat import events_executor
        try:
            return events_executor()
        except RuntimeError:
            if kind == 'events':
                raise
    from rclpy.executors import SingleThreadedExecutor
    return SingleThreadedExecutor()


# What a configure step reports as one line (a missing or corrupt file, a value the library
# refuses, a device that does not open): never a traceback
CONFIGURE_ERRORS = (ValueError, FileNotFoundError, RuntimeError, OSError, ParameterException)
MANAGED_FLAG = '--managed'


class ManagedNode(LifecycleNode):
    """A lifecycle node (``rclpy.lifecycle``, as ros2/demos lifecycle_py) with the project's
    division of work:

    * the constructor declares the parameters, nothing else: it reads, writes and opens nothing;
    * :meth:`configure` loads the node's files by path (its parameters), builds its library
      objects and creates its publishers (:meth:`publisher`: lifecycle publishers, silent unless
      active) and its diagnostics (a plain publisher: reported in every state). A failure is
      raised as one of :data:`CONFIGURE_ERRORS` with one line that names what to do (the
      command that builds a missing file); ``on_configure`` logs that line, releases what was
      made and returns FAILURE: the node stays unconfigured, ready to be configured again after
      a corrected parameter;
    * :meth:`activate` starts the input and the timers (:meth:`subscription`, :meth:`timer`:
      destroyed again on deactivate);
    * :meth:`deactivate` / :meth:`cleanup` stop / release (cleanup and shutdown release
      everything configure made).
    """

    def __init__(self, name: str, **kwargs):
        # (first: a constructor that fails later is still destroyed cleanly, e.g. by the
        # context's shutdown)
        self.lifecycle_state = 'unconfigured'
        self.configure_error: Optional[str] = None   # the last failed configure's line
        self._configured: list = []   # (kind, entity) made by configure, released on cleanup
        self._active: list = []       # made by activate, released on deactivate
        super().__init__(name, **kwargs)
        self.health = Health()
        # reach_subscribers: per topic, the graph's subscriber count it last gave up waiting at
        self._reach_gave_up: Dict[str, int] = {}
        # subscription(watch=True): (subscription, InputWatch) while active, and their timer
        self._watched: list = []
        self._watch_timer = None

    # -- hooks -----------------------------------------------------------------------------------
    def configure(self) -> None:
        """Load files, build the library objects, create publishers (raise one line on error)."""

    def activate(self) -> None:
        """Create subscriptions and timers (:meth:`subscription`, :meth:`timer`)."""

    def deactivate(self) -> None:
        """Stop what activate started beyond its subscriptions and timers (released here)."""

    def cleanup(self) -> None:
        """Release what configure loaded beyond its publishers (released here)."""

    # -- entities tied to a state ------------------------------------------------------------
    def publisher(self, msg_type, topic: str, qos):
        """A lifecycle publisher (publishes only while active), destroyed on cleanup."""
        pub = self.create_lifecycle_publisher(msg_type, topic, qos)
        self._configured.append(('lifecycle_publisher', pub))
        if self.lifecycle_state == 'active':   # made while active (a device opened late)
            pub.on_activate(None)
        return pub

    def diagnostics(self, extra: Optional[Callable[[], Dict[str, Any]]] = None):
        """Health on /diagnostics in every state from configure to cleanup."""
        d = DiagnosticsPublisher(self, self.health, extra=extra,
                                 state=lambda: self.lifecycle_state)
        self._configured.append(('diagnostics', d))
        return d

    def subscription(self, msg_type, topic: str, callback, *args, watch: bool = False, **kwargs):
        """A subscription, destroyed on deactivate. ``watch``: a STREAM input (never a latched
        one, silent by design) whose messages are counted (one integer increment each) and
        looked at every :data:`WATCH_PERIOD_S` while active: matched with a publisher for
        ``input_watch.SILENT_AFTER_S`` with nothing received is one warning and a WARN on
        /diagnostics (a restarted node that DDS does not deliver to, docs/recovery.md), the
        first message after it one info line."""
        w = InputWatch(topic) if watch else None
        if w is not None:
            def counted(msg, _w=w, _callback=callback):
                _w.count += 1
                return _callback(msg)
        sub = self.create_subscription(msg_type, topic, counted if w is not None else callback,
                                       *args, **kwargs)
        self._active.append(('subscription', sub))
        if w is not None:
            w.topic = sub.topic_name
            self._watched.append((sub, w))
            self._active.append(('input_watch', w))
            if self._watch_timer is None:
                self._watch_timer = self.create_timer(WATCH_PERIOD_S, self._check_inputs)
        return sub

    def _check_inputs(self) -> None:
        now = time.monotonic()
        for sub, w in list(self._watched):
            try:
                publishers = sub.get_publisher_count()
            except Exception:   # (destroyed meanwhile: released with its watch)
                continue
            event = w.check(now, publishers)
            if event is None:
                continue
            if event == SILENT:
                self.get_logger().warning(w.message(event, now))
                self.health.set_silent(w.topic, w.status())
            else:   # a message came, or the publishers went (a new match: a new episode)
                self.get_logger().info(w.message(event, now))
                self.health.set_silent(w.topic, None)

    def timer(self, period_s: float, callback):
        t = self.create_timer(period_s, callback)
        self._active.append(('timer', t))
        return t

    def reach_subscribers(self, publishers: Sequence) -> None:
        """Before a publish: wait (at most :data:`REACH_WAIT_S`) until each publisher has
        reached every subscriber the graph knows on its topic. A subscriber that appeared after
        this node activated (a recorder started later) is known to the graph, and sees this
        publisher, before this publisher has matched it: the discovery is two-sided, and a
        message published in between is lost to it (under load, the first frame's output of a
        replay). Waited once per change of the graph's count: a subscriber that never matches
        (incompatible QoS) costs one wait, not one per message. A few us per publisher when
        nothing is missing."""
        gave_up = self._reach_gave_up
        deadline = None
        for p in publishers:
            topic = p.topic_name
            known = self.count_subscribers(topic)
            if p.get_subscription_count() >= known or gave_up.get(topic) == known:
                continue
            if deadline is None:
                deadline = time.monotonic() + REACH_WAIT_S
            while p.get_subscription_count() < known and time.monotonic() < deadline:
                time.sleep(0.002)
                known = self.count_subscribers(topic)   # (one that left ends the wait)
            if p.get_subscription_count() < known:
                gave_up[topic] = known
                self.get_logger().warning(
                    f'{topic}: {known - p.get_subscription_count()} subscriber(s) the graph '
                    f'knows not reached after {REACH_WAIT_S:g} s (incompatible QoS?)')

    def when_ready(self, missing: Callable[[], List[str]], then: Callable[[], None],
                   timeout_s: float, what: str) -> None:
        """Call ``then`` once ``missing()`` (the names still waited for) is empty, at most
        ``timeout_s``: then a warning names what is still missing (``<names>: <what> after N
        s``) and ``then`` runs anyway. Called from :meth:`activate`, it waits inside the
        transition (polled every 10 ms; DDS discovery and matching go on in the middleware's
        own threads), so the node reports active only once ``then`` ran: a manager that
        activates the source last (the launch files) starts it when this node takes its input.
        At once when nothing is missing now; not at all when the context shuts down meanwhile."""
        since = time.monotonic()
        left = missing()
        while left:
            waited = time.monotonic() - since
            if not self.context.ok():
                return
            if waited >= timeout_s:
                self.get_logger().warning(f'{", ".join(left)}: {what} after {waited:.0f} s')
                break
            time.sleep(0.01)
            left = missing()
        then()

    def service(self, *args, **kwargs):
        srv = self.create_service(*args, **kwargs)
        self._active.append(('service', srv))
        return srv

    def _release(self, entities: list) -> None:
        while entities:
            kind, e = entities.pop()
            if kind == 'timer':
                e.cancel()
                self.destroy_timer(e)
            elif kind == 'subscription':
                self.destroy_subscription(e)
            elif kind == 'service':
                self.destroy_service(e)
            elif kind == 'lifecycle_publisher':
                self.destroy_lifecycle_publisher(e)
            elif kind == 'diagnostics':
                e.destroy()
            elif kind == 'input_watch':
                self._watched = [(s, w) for s, w in self._watched if w is not e]
                self.health.set_silent(e.topic, None)
                if not self._watched and self._watch_timer is not None:
                    self._watch_timer.cancel()
                    self.destroy_timer(self._watch_timer)
                    self._watch_timer = None

    # -- transitions ---------------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.configure_error = None
        try:
            self.configure()
        except CONFIGURE_ERRORS as e:
            self.configure_error = str(e)
            if self.context.ok():   # (else: stopped while starting, nothing to report)
                self.get_logger().error(str(e))
            self._release_configured()
            return TransitionCallbackReturn.FAILURE
        self.lifecycle_state = 'inactive'
        return super().on_configure(state)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self.activate()
        except CONFIGURE_ERRORS as e:
            self.configure_error = str(e)
            if self.context.ok():
                self.get_logger().error(str(e))
            self._release(self._active)
            return TransitionCallbackReturn.FAILURE
        ret = super().on_activate(state)   # enables the lifecycle publishers
        self.lifecycle_state = 'active'
        return ret

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release_configured()
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release_all()
        self.lifecycle_state = 'finalized'
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release_all()
        return TransitionCallbackReturn.SUCCESS   # back to unconfigured

    def _stop(self) -> None:
        if self.lifecycle_state == 'active':
            self._release(self._active)
            self.deactivate()
            for kind, e in self._configured:
                if kind == 'lifecycle_publisher':
                    e.on_deactivate(None)
            self.lifecycle_state = 'inactive'

    def _release_configured(self) -> None:
        self._release(self._configured)
        if self.lifecycle_state != 'finalized':
            self.cleanup()
            self.lifecycle_state = 'unconfigured'

    def _release_all(self) -> None:
        self._stop()
        self._release(self._active)
        self._release_configured()

    def destroy_node(self):
        if self.lifecycle_state != 'finalized':
            self._release_all()
            self.lifecycle_state = 'finalized'
        return super().destroy_node()


class TransitionFailed(RuntimeError):
    """A configure / activate that failed: the node has logged its one line already."""


def bring_up(*nodes: 'ManagedNode'):
    """Configure, then activate ``nodes`` in this process (the one-process pipeline, tools,
    tests); a failure raises :class:`TransitionFailed` with the node's one line (logged by the
    node already). Returns the node (one) or the nodes."""
    ok = TransitionCallbackReturn.SUCCESS
    for step in ('trigger_configure', 'trigger_activate'):
        for node in nodes:
            if getattr(node, step)() != ok:
                raise TransitionFailed(node.configure_error
                                       or f'{node.get_name()}: {step[8:]} failed')
    return nodes[0] if len(nodes) == 1 else nodes


def node_help(node_factory: Callable[..., Node], prog: str) -> str:
    """``--help`` of a node executable: what it is (its module's first paragraph), how to set its
    parameters, and each parameter with its default when the module lists them (``PARAMS`` or
    ``node_params()``, as ``make params`` reads them)."""
    mod = sys.modules.get(getattr(node_factory, '__module__', ''), None)
    doc = ' '.join(((mod.__doc__ if mod else None) or node_factory.__doc__ or '').strip()
                   .split('\n\n')[0].split())
    lines = [f'usage: {prog} [--ros-args -p NAME:=VALUE ... --params-file FILE -r FROM:=TO]', '']
    if doc:
        lines += [doc, '']
    fn = getattr(mod, 'node_params', None)
    specs = fn() if callable(fn) else getattr(mod, 'PARAMS', None)
    specs = [s for s in specs or () if getattr(s, 'public', True)]
    if specs:
        lines.append('parameters (default; docs/parameters.md has ranges and details):')
        lines += [f'  {s.name} ({s.default!r}): {s.description}' for s in specs]
    return '\n'.join(lines)


def run_node(node_factory: Callable[..., Node], args=None, executor=None) -> int:
    """Standard ``main()``: init, build the node (a parameter error is one clear line and exit 1),
    configure and activate it (a failed configure: the node's one line, exit 1) unless started
    with ``--managed`` (then a lifecycle manager drives it: the launch file's LifecycleNode or
    ``ros2 lifecycle set``), spin until Ctrl-C / SIGTERM, shut down cleanly. ``-h`` / ``--help``
    before any ``--ros-args`` prints :func:`node_help` and exits 0 without starting ROS."""
    from rclpy.executors import ExternalShutdownException
    from rclpy.utilities import remove_ros_args
    argv = list(args if args is not None else sys.argv)
    if any(a in ('-h', '--help') for a in remove_ros_args(args=argv)[1:]):
        print(node_help(node_factory, prog=argv[0].rsplit('/', 1)[-1] if argv else 'node'))
        return 0
    managed = MANAGED_FLAG in remove_ros_args(argv)
    spinning = []
    stop = threading.Event()

    def _on_signal(signum, frame):
        # Starting up: Ctrl-C / SIGTERM stops the start (KeyboardInterrupt, handled below).
        # Spinning: the spin loop ends after the callback in progress (at most SPIN_SLICE_S),
        # and only then are the node and the context shut down. (rclpy's own handler shut the
        # context down from under the executor: the events executor then still ran callbacks
        # whose publish raised "publisher's context is invalid", logged as a FATAL and a trace.)
        if not spinning:
            raise KeyboardInterrupt
        stop.set()

    try:
        signal.signal(signal.SIGINT, _on_signal)
        signal.signal(signal.SIGTERM, _on_signal)
        handlers = SignalHandlerOptions.NO
    except ValueError:  # not the main thread (a test calling run_node): signals are not ours
        handlers = SignalHandlerOptions.ALL
    rclpy.init(args=args, signal_handler_options=handlers)
    node = None
    try:
        if executor is None:
            executor = node_executor()   # (a wrong KINECT_EXECUTOR: its one line, exit 1)
        node = node_factory()
        if isinstance(node, ManagedNode):
            if managed:
                node.get_logger().info(f'unconfigured: waiting for the lifecycle transitions '
                                       f'(ros2 lifecycle set {node.get_fully_qualified_name()} '
                                       'configure, then activate)')
            else:
                bring_up(node)
    except KeyboardInterrupt:  # Ctrl-C while still starting up
        if node is not None:
            ignore_further_interrupts()
            node.destroy_node()
        rclpy.try_shutdown()
        return 0
    except (ValueError, FileNotFoundError, RuntimeError, OSError, ParameterException) as e:
        stopped = not rclpy.ok()   # Ctrl-C / SIGTERM while starting up: a clean stop
        if not isinstance(e, TransitionFailed) and not stopped:
            print(f'[ERROR] {e}', file=sys.stderr)   # (a failed transition has logged its line)
        if node is not None:
            ignore_further_interrupts()
            node.destroy_node()
        rclpy.try_shutdown()
        return 0 if stopped else 1
    spinning.append(True)
    try:
        executor.add_node(node)
        spin_until_shutdown(executor, stop=stop)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:
        # Ctrl-C / SIGINT shuts the context down under the executor: when that happens while it
        # is taking a message, rclpy raises RuntimeError ("Unable to convert call argument '0'")
        # from take_message instead of ExternalShutdownException. A clean stop, not a crash.
        # rclpy's signal handler shuts the context down from its own thread: give it a moment
        deadline = time.monotonic() + 1.0
        while rclpy.ok() and time.monotonic() < deadline:
            time.sleep(0.01)
        if rclpy.ok():
            raise
    finally:
        ignore_further_interrupts()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
