"""Small rclpy adapters shared by every node: validated parameters with descriptors, diagnostics,
and a ``main()`` runner with a clean Ctrl-C shutdown.

This is the only module of ``skeleton_core`` that imports rclpy; library modules never import it.
"""
from __future__ import annotations

import signal
import sys
import time
from typing import Any, Callable, Dict, Iterable, Optional, Sequence

import rclpy
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter

from .cdr import CdrError, frames_from_cdr
from .health import Health
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
    """Declares the public :class:`ParamSpec` s on a node, validates every set (out-of-range sets
    are refused with a reason) and keeps the current values in ``values``; ``on_change(changed_dict)``
    runs after a successful set so the node can push new values into its library objects. A spec
    with ``public=False`` (set by a preset only, ``skeleton_core.params``) is not declared: its
    default stays in ``values``. A parameter file or ``-p`` naming a parameter the node does not
    declare is refused with one line (rclpy would silently ignore it)."""

    def __init__(self, node: Node, specs: Iterable[ParamSpec],
                 on_change: Optional[Callable[[Dict[str, Any]], Optional[str]]] = None):
        self._node = node
        every = list(specs)
        self.specs = {s.name: s for s in every if s.public}
        self.values: Dict[str, Any] = {s.name: s.default for s in every if not s.public}
        self._on_change = on_change
        check_overrides(node, self.specs, {s.name for s in every if not s.public})
        for s in self.specs.values():
            p = node.declare_parameter(s.name, s.default, descriptor(s))
            value = p.value
            if isinstance(s.default, float) and isinstance(value, int):
                value = float(value)
            err = s.check(value)
            if err is not None:
                raise ValueError(f'invalid parameter: {err}')
            self.values[s.name] = value
        node.add_on_set_parameters_callback(self._on_set)

    def __getitem__(self, name: str) -> Any:
        return self.values[name]

    def _on_set(self, params: Sequence[Parameter]) -> SetParametersResult:
        changed = {}
        for p in params:
            spec = self.specs.get(p.name)
            if spec is None:
                continue
            value = p.value
            if isinstance(spec.default, float) and isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            err = spec.check(value)
            if err is None and spec.read_only:
                err = f'{p.name} is read-only'
            if err is not None:
                self._node.get_logger().warning(f'refused parameter change: {err}')
                return SetParametersResult(successful=False, reason=err)
            changed[p.name] = value
        if changed and self._on_change is not None:
            err = self._on_change(changed)
            if err:
                self._node.get_logger().warning(f'refused parameter change: {err}')
                return SetParametersResult(successful=False, reason=err)
        self.values.update(changed)
        if changed:
            self._node.get_logger().info(
                'parameters set: ' + ', '.join(f'{k}={v!r}' for k, v in changed.items()))
        return SetParametersResult(successful=True)


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
                 extra: Optional[Callable[[], Dict[str, Any]]] = None):
        from diagnostic_msgs.msg import DiagnosticArray  # noqa: F401 (fail early if missing)
        self._node = node
        self._health = health
        self._extra = extra
        self._pub = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._timer = node.create_timer(period_s, self._publish)

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
        if snap.get('received', 0) > 0 and snap.get('rate_hz', 0.0) == 0.0:
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


def run_node(node_factory: Callable[..., Node], args=None, executor=None) -> int:
    """Standard ``main()``: init, build the node (a start-up error is one clear line and exit 1),
    spin until Ctrl-C / SIGTERM, shut down cleanly."""
    from rclpy.executors import ExternalShutdownException
    rclpy.init(args=args)
    node = None
    try:
        node = node_factory()
    except KeyboardInterrupt:  # Ctrl-C while still starting up
        rclpy.try_shutdown()
        return 0
    except (ValueError, FileNotFoundError, RuntimeError, OSError, ParameterException) as e:
        print(f'[ERROR] {e}', file=sys.stderr)
        if rclpy.ok():
            rclpy.try_shutdown()
        return 1
    try:
        if executor is None:
            rclpy.spin(node)
        else:
            executor.add_node(node)
            executor.spin()
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
