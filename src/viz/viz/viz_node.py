"""``viz`` node: skeleton topics -> ``visualization_msgs/MarkerArray`` for RViz.

Subscribes (names are read-only parameters ``*_topic``; a layer's topic only while it is shown):
  /kinect/skeletons              raw Kinect skeletons         -> layer ``raw``
  /kinect/skeletons_reliability  with per-joint reliability   -> layer ``reliability`` (red squares)
  /posture/reconstructed         reconstructed postures       -> layer ``reconstructed``
  /posture/completed             completion-only postures     -> layer ``completed`` (off by default)
  /character/skeletons           simulated character          -> layer ``character`` (capsules)
  /physics/objects               environment objects (MarkerArray) -> ``environment/<ns>``
Publishes ``/viz/markers`` (MarkerArray) at most ``max_rate_hz``, only when something changed, and
``/diagnostics``. The geometry is in :mod:`viz.markers`; this node adapts messages and parameters.
"""
from __future__ import annotations

import time
from typing import Any, Dict, Optional

from rclpy.exceptions import InvalidParameterValueException
from rclpy.qos import qos_profile_sensor_data
from visualization_msgs.msg import Marker, MarkerArray

from skeleton_core.cdr import CdrError, frames_from_cdr
from skeleton_core.conversions import ns_to_stamp
from skeleton_core.params import ParamSpec, build, hidden, specs
from skeleton_core.rosnode import ManagedNode, Parameters, run_node

from . import markers as mk

_TYPES = {mk.SPHERE: Marker.SPHERE, mk.CYLINDER: Marker.CYLINDER, mk.CUBE: Marker.CUBE,
          mk.SPHERE_LIST: Marker.SPHERE_LIST, mk.LINE_LIST: Marker.LINE_LIST}


def _topic_ok(v):
    return None if v else 'topic name must not be empty'


PARAMS = [
    ParamSpec('raw_topic', '/kinect/skeletons', 'raw skeletons (SkeletonArray)', read_only=True,
              validator=_topic_ok),
    ParamSpec('reliability_topic', '/kinect/skeletons_reliability',
              'skeletons with reliability filled in (SkeletonArray)', read_only=True,
              validator=_topic_ok),
    ParamSpec('reconstructed_topic', '/posture/reconstructed', 'reconstructed postures',
              read_only=True, validator=_topic_ok),
    ParamSpec('completed_topic', '/posture/completed', 'completion-only postures', read_only=True,
              validator=_topic_ok),
    ParamSpec('character_topic', '/character/skeletons', 'simulated character skeletons',
              read_only=True, validator=_topic_ok),
    ParamSpec('objects_topic', '/physics/objects',
              'environment objects (visualization_msgs/MarkerArray), forwarded', read_only=True,
              validator=_topic_ok),
    ParamSpec('markers_topic', '/viz/markers', 'output MarkerArray topic', read_only=True,
              validator=_topic_ok),
    ParamSpec('show_raw', True, 'draw the raw Kinect skeleton'),
    ParamSpec('show_reliability', True, 'draw red squares sized by 1 - reliability'),
    ParamSpec('show_reconstructed', True, 'draw the reconstructed skeleton'),
    ParamSpec('show_completed', False, 'draw the completion-only skeleton'),
    ParamSpec('show_character', True, 'draw the simulated character capsules'),
    ParamSpec('show_objects', True, 'forward environment objects'),
    ParamSpec('max_rate_hz', 30.0, 'maximum MarkerArray publish rate', range=(0.5, 120.0)),
    ParamSpec('stale_timeout_s', 1.0, 'a layer not updated for this long is deleted (s)',
              range=(0.05, 60.0)),
    # fixed values (hidden: not what a lab changes), read where the node reads its parameters
    hidden(ParamSpec('marker_lifetime_s', 0.5, 'marker lifetime in RViz (0 = forever)',
                     range=(0.0, 60.0))),
    hidden(ParamSpec('default_frame_id', 'kinect_link', 'frame used when a message has none',
                     validator=lambda v: None if v else 'default_frame_id must not be empty')),
] + specs(mk.Style)   # the style's parameters, declared on viz.markers.Style


_LAYER_TOPIC = {'raw': 'raw_topic', 'reliability': 'reliability_topic',
                'reconstructed': 'reconstructed_topic', 'completed': 'completed_topic',
                'character': 'character_topic'}


def style_from_params(v: Dict[str, Any]) -> mk.Style:
    return build(mk.Style, v)


class MarkerCache:
    """Turns :class:`viz.markers.MarkerSpec` s into Marker messages, reusing the message objects
    of every (ns, id) across publishes: constructing rclpy messages costs ~15x more than setting
    their fields (a 2-user scene with every layer has ~170 markers at up to 30 Hz)."""

    def __init__(self):
        self._markers: Dict[tuple, Marker] = {}
        self._points: Dict[tuple, list] = {}
        self._colors: Dict[tuple, list] = {}

    def __len__(self) -> int:
        return len(self._markers)

    def to_msg(self, spec: mk.MarkerSpec, lifetime_s: float) -> Marker:
        key = (spec.ns, spec.id)
        if spec.action == mk.DELETE:
            self._markers.pop(key, None)
            self._points.pop(key, None)
            self._colors.pop(key, None)
            m = Marker(ns=spec.ns, id=int(spec.id), action=Marker.DELETE)
            m.header.frame_id = spec.frame_id
            ns_to_stamp(spec.stamp_ns, m.header.stamp)
            return m
        m = self._markers.get(key)
        if m is None:
            m = self._markers[key] = Marker(ns=spec.ns, id=int(spec.id), action=Marker.ADD)
        m.header.frame_id = spec.frame_id
        ns_to_stamp(spec.stamp_ns, m.header.stamp)
        m.type = _TYPES[spec.type]
        p = m.pose.position
        p.x, p.y, p.z = (float(v) for v in spec.position)
        o = m.pose.orientation
        o.x, o.y, o.z, o.w = (float(v) for v in spec.orientation)
        m.scale.x, m.scale.y, m.scale.z = (float(v) for v in spec.scale)
        m.color.r, m.color.g, m.color.b, m.color.a = (float(v) for v in spec.color)
        secs = int(lifetime_s)
        m.lifetime.sec, m.lifetime.nanosec = secs, int(round((lifetime_s - secs) * 1e9))
        if spec.points is not None:
            from geometry_msgs.msg import Point
            from std_msgs.msg import ColorRGBA
            pts = self._points.setdefault(key, [])
            n = len(spec.points)
            while len(pts) < n:
                pts.append(Point())
            for q, (a, b, c) in zip(pts, spec.points.tolist()):
                q.x, q.y, q.z = a, b, c
            m.points = pts[:n]
            if spec.colors is not None and len(spec.colors) == n:
                cols = self._colors.setdefault(key, [])
                while len(cols) < n:
                    cols.append(ColorRGBA())
                for q, (r, g, b, a) in zip(cols, spec.colors.tolist()):
                    q.r, q.g, q.b, q.a = r, g, b, a
                m.colors = cols[:n]
            else:
                m.colors = []
        return m


def spec_to_msg(spec: mk.MarkerSpec, lifetime_s: float) -> Marker:
    """One spec -> a new Marker message."""
    return MarkerCache().to_msg(spec, lifetime_s)


class VizNode(ManagedNode):
    """Thin adapter: SkeletonArray topics -> :class:`viz.markers.SceneState` -> MarkerArray.
    Configure builds the scene and the publisher; activate subscribes to the shown layers."""

    def __init__(self, **kwargs):
        super().__init__('viz', **kwargs)
        self.scene = None
        self._layer_subs: Dict[str, Any] = {}
        self._timer = None
        try:
            self.params = Parameters(self, PARAMS, validate=self._validate_change,
                                     apply=self._apply_change)
        except InvalidParameterValueException as e:  # out of a descriptor range at start-up
            raise ValueError(f'viz: {e}') from None
        self.scene = None
        self._layer_subs: Dict[str, Any] = {}
        self._timer = None

    def configure(self) -> None:
        v = self.params.values
        self.scene = mk.SceneState(style_from_params(v), stale_timeout_s=v['stale_timeout_s'],
                                   default_frame_id=v['default_frame_id'])
        self._apply_enabled(v)
        self._dirty = False
        self._cache = MarkerCache()
        self._objects: Optional[list] = None
        self._objects_at = 0.0
        self._objects_shown: Dict[tuple, str] = {}
        self._objects_new = False
        self._pub = self.publisher(MarkerArray, v['markers_topic'], 10)
        self.diagnostics(extra=lambda: {'namespaces': len(self.scene.shown_namespaces()),
                                        'markers_cached': len(self._cache)})

    def activate(self) -> None:
        v = self.params.values
        self._sync_subscriptions(v)
        self.subscription(MarkerArray, v['objects_topic'], self._on_objects, 10)
        self._timer = self.create_timer(1.0 / v['max_rate_hz'], self._tick)
        self.get_logger().info(f"publishing markers on {self._pub.topic_name} at <= "
                               f"{v['max_rate_hz']:g} Hz")

    def deactivate(self) -> None:
        for sub in self._layer_subs.values():
            self.destroy_subscription(sub)
        self._layer_subs = {}
        if self._timer is not None:
            self._timer.cancel()
            self.destroy_timer(self._timer)
            self._timer = None

    def cleanup(self) -> None:
        self.scene = None

    # ---------------------------------------------------------------- parameters
    def _apply_enabled(self, v: Dict[str, Any]) -> None:
        for layer in mk.LAYERS:
            self.scene.enabled[layer] = bool(v[f'show_{layer}'])

    def _sync_subscriptions(self, v: Dict[str, Any]) -> None:
        """Subscribe to a layer's topic only while the layer is shown: a hidden layer costs
        nothing, here or upstream (the reconstruction node skips outputs nobody subscribes to)."""
        from skeleton_msgs.msg import SkeletonArray
        for layer, key in _LAYER_TOPIC.items():
            sub = self._layer_subs.get(layer)
            if v[f'show_{layer}'] and sub is None:
                self._layer_subs[layer] = self.create_subscription(
                    SkeletonArray, v[key],   # serialized (skeleton_core.cdr)
                    lambda data, layer=layer: self._on_skeletons(layer, data),
                    qos_profile_sensor_data, raw=True)
            elif not v[f'show_{layer}'] and sub is not None:
                self.destroy_subscription(sub)
                del self._layer_subs[layer]

    def _validate_change(self, v: Dict[str, Any], changed: Dict[str, Any]) -> Optional[str]:
        try:
            style_from_params(v)
        except (TypeError, ValueError) as e:
            return str(e)
        return None

    def _apply_change(self, changed: Dict[str, Any]) -> None:
        if self.scene is None:
            return   # configure reads the values
        v = self.params.values
        self.scene.style = style_from_params(v)
        self.scene.invalidate()
        self.scene.stale_timeout_s = v['stale_timeout_s']
        self.scene.default_frame_id = v['default_frame_id']
        self._apply_enabled(v)
        if self.lifecycle_state == 'active':
            self._sync_subscriptions(v)
            if 'max_rate_hz' in changed:
                self._timer.cancel()
                self.destroy_timer(self._timer)
                self._timer = self.create_timer(1.0 / v['max_rate_hz'], self._tick)
        self._dirty = True

    # ---------------------------------------------------------------- inputs
    def _on_skeletons(self, layer: str, data: bytes) -> None:
        self.health.on_receive()
        errors = []
        try:
            frames = frames_from_cdr(data, errors)[2]
        except CdrError as e:
            if self.health.on_drop('malformed message'):
                self.get_logger().warning(f'{layer}: dropped a malformed message ({e}); '
                                          'further drops of this cause are only counted')
            return
        for e in errors:
            if self.health.on_drop(e.cause):
                self.get_logger().warning(f'{layer}: dropped a skeleton ({e}); '
                                          'further drops of this cause are only counted')
        self.scene.update(layer, frames, time.monotonic())
        self._dirty = True

    def _on_objects(self, msg: MarkerArray) -> None:
        """Keep the ADD markers of the newest environment array, renamed ``environment/<ns>``
        (DELETE / DELETEALL entries are dropped: this node deletes what it forwarded itself)."""
        self.health.on_receive()
        v = self.params.values
        lt = v['marker_lifetime_s']
        kept = []
        for m in msg.markers:
            if m.action != Marker.ADD:
                continue
            m.ns = f'environment/{m.ns}' if m.ns else 'environment'
            if not m.header.frame_id:
                m.header.frame_id = v['default_frame_id']
            if m.lifetime.sec == 0 and m.lifetime.nanosec == 0:
                m.lifetime.sec, m.lifetime.nanosec = int(lt), int(round((lt - int(lt)) * 1e9))
            kept.append(m)
        self._objects = kept
        self._objects_at = time.monotonic()
        self._objects_new = True

    def _object_markers(self, now: float):
        """The newest environment markers once, plus DELETEs for forwarded objects that are gone,
        hidden or stale."""
        v = self.params.values
        fresh = self._objects is not None and now - self._objects_at <= v['stale_timeout_s']
        out = []
        if v['show_objects'] and fresh:
            if not self._objects_new:
                return out
            self._objects_new = False
            shown = {(m.ns, m.id): m.header.frame_id for m in self._objects}
            out = list(self._objects)
            for (ns, i), frame in self._objects_shown.items():
                if (ns, i) not in shown:
                    out.append(self._delete(ns, i, frame))
            self._objects_shown = shown
        elif self._objects_shown:
            out = [self._delete(ns, i, frame) for (ns, i), frame in self._objects_shown.items()]
            self._objects_shown = {}
            self._objects_new = True  # forward again when shown again
        return out

    @staticmethod
    def _delete(ns: str, i: int, frame: str) -> Marker:
        m = Marker(action=Marker.DELETE, ns=ns, id=i)
        m.header.frame_id = frame
        return m

    # ---------------------------------------------------------------- output
    def _tick(self) -> None:
        now = time.monotonic()
        objects = self._object_markers(now)
        # without new input, rebuild only when a shown layer went stale (its markers are deleted)
        if not self._dirty and not objects and not self.scene.has_stale(now):
            return
        t0 = time.perf_counter()
        specs = self.scene.build(now)
        self._dirty = False
        if not specs and not objects:
            return
        lifetime = self.params.values['marker_lifetime_s']
        out = MarkerArray()
        out.markers = [self._cache.to_msg(s, lifetime) for s in specs] + objects
        self._pub.publish(out)
        self.health.on_publish(latency_s=time.perf_counter() - t0)


def main(args=None):
    return run_node(VizNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
