"""Azure Kinect / Orbbec Femto Body Tracking (K4ABT, 32 joints) onto the 20-joint model (no
rclpy): the markers of the Azure Kinect ROS driver, live or from a bag, and the JSON of the SDK's
``offline_processor`` sample.

What the Azure Kinect ROS driver publishes (read in microsoft/Azure_Kinect_ROS_Driver, ROS 2
branches, ``src/k4a_ros_device.cpp``: ``K4AROSDevice::getBodyMarker`` and
``bodyPublisherThread``): on ``body_tracking_data`` one ``visualization_msgs/MarkerArray`` per
body-tracking frame holding every body of that capture, 32 markers each (none when nobody is
seen); every marker a ``SPHERE`` with ``ns`` empty, ``action`` ADD, ``id = body_id * 100 +
joint`` (joint in K4ABT order, :data:`JOINTS`), ``header.frame_id = tf_prefix +
'depth_camera_link'``, ``header.stamp`` the capture's device time made real time, ``lifetime``
0.25 s (for RViz: a body that is gone is simply absent from the next message), the position in
metres (the SDK's millimetres / 1000) and the joint's orientation. No confidence: the SDK's
``confidence_level`` is not in the message.

Axes: ``depth_camera_link`` is the depth camera's optical frame (x right, y down, z forward), and
the depth camera looks 6 degrees down from the housing (the driver's
``k4a_calibration_transform_data.cpp``: ``camera_base -> depth_camera_link`` is the optical
rotation times a -6 degree tilt about the camera's x axis). The skeletons here are in the sensor
frame of the product (``kinect_link``, REP-103: x forward, y left, z up), taken as the housing
(the driver's ``camera_base``): :func:`camera_to_sensor` is that rotation, so a camera standing
level on its base gives a level floor, and the housing's own pitch and height are the
``sensor_pose`` (or ``extrinsics``) of the product, on TF as ``world -> kinect_link``.

The map onto the model (``config/joint_maps/k4abt.yaml``, :func:`load_map`): each model joint is
an anchor K4ABT joint refined by others (clavicles and neck for the shoulder centre, hand tip and
thumb for the hand, ears, nose and eyes for the head), the refinement used only when every joint
it names is there and at least as confident as the anchor.

Tracking states: the markers carry none, so every joint that is there is TRACKED and the
reliability (Shum 2013 Eq. 1-8) rests on its behaviour and kinematic terms (R_t = 1 changes
nothing in the minimum of Eq. 8); a joint that is not there is NOT_TRACKED. Where the input has
the SDK's confidence levels (the JSON of a tool that writes them): HIGH and MEDIUM -> TRACKED, LOW
(occluded, predicted by the SDK) -> INFERRED, NONE (out of range) -> NOT_TRACKED.
"""
from __future__ import annotations

import collections
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, Iterator, List, Optional, Sequence, Tuple

import numpy as np

from skeleton_core.conversions import SkeletonFrame
from skeleton_core.marker_cdr import (ADD, SPHERE, Marker, MarkerArrayDecoder, MarkerCdrError)
from skeleton_core.model import (INFERRED, JOINT_NAMES, NOT_TRACKED, NUM_JOINTS,
                                 PARENTS, TRACKED)

JOINTS: Tuple[str, ...] = (
    'PELVIS', 'SPINE_NAVEL', 'SPINE_CHEST', 'NECK', 'CLAVICLE_LEFT', 'SHOULDER_LEFT', 'ELBOW_LEFT',
    'WRIST_LEFT', 'HAND_LEFT', 'HANDTIP_LEFT', 'THUMB_LEFT', 'CLAVICLE_RIGHT', 'SHOULDER_RIGHT',
    'ELBOW_RIGHT', 'WRIST_RIGHT', 'HAND_RIGHT', 'HANDTIP_RIGHT', 'THUMB_RIGHT', 'HIP_LEFT',
    'KNEE_LEFT', 'ANKLE_LEFT', 'FOOT_LEFT', 'HIP_RIGHT', 'KNEE_RIGHT', 'ANKLE_RIGHT', 'FOOT_RIGHT',
    'HEAD', 'NOSE', 'EYE_LEFT', 'EAR_LEFT', 'EYE_RIGHT', 'EAR_RIGHT')
NUM_K4ABT = len(JOINTS)   # K4ABT_JOINT_COUNT
K4ABT_INDEX = {n: i for i, n in enumerate(JOINTS)}
# k4abt_joint_confidence_level_t
CONF_NONE, CONF_LOW, CONF_MEDIUM, CONF_HIGH = 0, 1, 2, 3
STATE_OF_CONFIDENCE = np.array([NOT_TRACKED, INFERRED, TRACKED, TRACKED], np.uint8)
TRACKER = 'azure_kinect_bt'
TOPIC_SUFFIX = 'body_tracking_data'
MARKER_ARRAY = 'visualization_msgs/msg/MarkerArray'
DEPTH_FRAME_SUFFIX = 'depth_camera_link'
DEPTH_TILT_DEG = 6.0      # the depth camera looks this far down from the housing
ID_STRIDE = 100           # marker id = body_id * 100 + joint
MAX_RANGE_M = 20.0        # a joint farther than this from the camera is malformed


class K4abtError(ValueError):
    """A map or JSON file that cannot be used (one line naming the file)."""


# ------------------------------------------------------------------------------------------
# The map
# ------------------------------------------------------------------------------------------
@dataclass
class K4abtMap:
    """Per model joint: the anchor K4ABT joint, and the refinement (K4ABT joints, weights)."""

    anchor: np.ndarray                                   # (20,) int
    refine: List[Optional[Tuple[np.ndarray, np.ndarray]]] = field(default_factory=list)
    name: str = 'k4abt'


def maps_dir() -> Path:
    from .joint_map import maps_dir as d
    return d()


def parse_map(data, path: str = '<map>') -> K4abtMap:
    def bad(why):
        return K4abtError(f'{path}: {why}')
    if not isinstance(data, dict) or data.get('format') != 'k4abt':
        raise bad("not a K4ABT joint map (needs 'format: k4abt')")
    joints = data.get('joints')
    if not isinstance(joints, dict):
        raise bad("needs 'joints:' (model joint -> K4ABT joint or {joint: weight})")
    unknown = sorted(set(joints) - set(JOINT_NAMES))
    if unknown:
        raise bad(f'joints: unknown model joint {unknown[0]!r}')
    missing = [n for n in JOINT_NAMES if n not in joints]
    if missing:
        raise bad(f'joints: model joint {missing[0]} has no K4ABT joint')
    anchor = np.zeros(NUM_JOINTS, int)
    refine: List[Optional[Tuple[np.ndarray, np.ndarray]]] = []
    for j, name in enumerate(JOINT_NAMES):
        v = joints[name]
        items = [(v, 1.0)] if isinstance(v, str) else list(v.items()) if isinstance(v, dict) else None
        if not items:
            raise bad(f'joints: {name}: a K4ABT joint name or {{joint: weight}}')
        for src, w in items:
            if src not in K4ABT_INDEX:
                raise bad(f'joints: {name}: unknown K4ABT joint {src!r}')
            if not isinstance(w, (int, float)) or not 0 < w <= 1:
                raise bad(f'joints: {name}: weight of {src} must be in (0, 1]')
        total = sum(w for _, w in items)
        if abs(total - 1.0) > 1e-6:
            raise bad(f'joints: {name}: weights sum to {total:g}, not 1')
        anchor[j] = K4ABT_INDEX[items[0][0]]
        refine.append(None if len(items) == 1 else (
            np.array([K4ABT_INDEX[s] for s, _ in items]), np.array([w for _, w in items], float)))
    return K4abtMap(anchor=anchor, refine=refine, name=str(data.get('name', 'k4abt')))


def load_map(path=None) -> K4abtMap:
    """The K4ABT joint map (default: the shipped ``config/joint_maps/k4abt.yaml``)."""
    import yaml
    path = Path(path) if path else maps_dir() / 'k4abt.yaml'
    try:
        data = yaml.safe_load(path.read_text(encoding='utf-8'))
    except (OSError, UnicodeDecodeError) as e:
        raise K4abtError(f'{path}: cannot read ({getattr(e, "strerror", None) or e})') from None
    except yaml.YAMLError as e:
        raise K4abtError(f'{path}: not YAML ({str(e).splitlines()[0]})') from None
    return parse_map(data, str(path))


# ------------------------------------------------------------------------------------------
# Axes and one body
# ------------------------------------------------------------------------------------------
def camera_to_sensor(tilt_deg: float = DEPTH_TILT_DEG) -> np.ndarray:
    """3x3 rotation: depth camera optical axes (x right, y down, z forward) -> the housing's
    REP-103 axes (x forward, y left, z up), the depth camera looking ``tilt_deg`` down."""
    optical = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    t = math.radians(tilt_deg)
    pitch = np.array([[math.cos(t), 0.0, math.sin(t)], [0.0, 1.0, 0.0],
                      [-math.sin(t), 0.0, math.cos(t)]])   # about y (left): + = nose down
    return pitch @ optical


def body_frame(positions: np.ndarray, present: np.ndarray, jmap: K4abtMap,
               confidence: Optional[np.ndarray] = None, user_id: int = 0, stamp_ns: int = 0,
               frame_id: str = '') -> Optional[SkeletonFrame]:
    """One body's 32 K4ABT joints (``positions`` (32, 3) already in the sensor frame, ``present``
    (32,) bool, ``confidence`` (32,) SDK levels or None) as a model skeleton; None when no anchor
    joint is there."""
    conf = (np.full(NUM_K4ABT, CONF_MEDIUM, int) if confidence is None
            else np.clip(np.asarray(confidence, int), CONF_NONE, CONF_HIGH))
    conf = np.where(present, conf, CONF_NONE)
    ok = conf > CONF_NONE
    if not ok[jmap.anchor].any():
        return None
    p = np.zeros((NUM_JOINTS, 3))
    state = STATE_OF_CONFIDENCE[conf[jmap.anchor]]
    have = ok[jmap.anchor]
    for j in range(NUM_JOINTS):
        a = jmap.anchor[j]
        if not have[j]:
            continue
        r = jmap.refine[j]
        if r is not None and np.all(conf[r[0]] >= conf[a]):
            p[j] = r[1] @ positions[r[0]]
        else:
            p[j] = positions[a]
    if not have.all():
        # a joint that is not there: at its parent (else at the body's centre), NOT_TRACKED --
        # the reliability is 0 there and the reconstruction fills it
        centre = p[have].mean(axis=0)
        for j in range(NUM_JOINTS):
            if not have[j]:
                par = PARENTS[j]
                p[j] = p[par] if par >= 0 else centre   # parents come first
    # orientations: not published (unknown), as the NiTE source: the SDK's joint orientations
    # follow its own bone axes, and the reconstruction works from positions
    return SkeletonFrame(positions=p, tracking_state=state.astype(np.uint8), orientations=None,
                         user_id=int(user_id), stamp_ns=int(stamp_ns), frame_id=frame_id)


# ------------------------------------------------------------------------------------------
# Markers -> captures -> skeletons
# ------------------------------------------------------------------------------------------
@dataclass
class Capture:
    """All bodies of one body-tracking frame: body id -> ((32, 3) positions, (32,) present)."""

    stamp_ns: int
    bodies: Dict[int, Tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    last_ns: int = 0          # receive time of its last marker

    def complete(self) -> bool:
        return all(pr.all() for _, pr in self.bodies.values())


class MarkerStream:
    """The Azure Kinect ROS driver's ``body_tracking_data`` stream -> skeleton frames.

    :meth:`feed` takes one message's CDR bytes and its receive time and returns the captures it
    completes, as ``(stamp_ns, [SkeletonFrame, ...])`` in time order. A capture is complete when
    a later capture's markers arrive, or (``live``) at once when every body in it has its 32
    joints (the driver's messages), or when :meth:`flush` finds nothing came for it for
    ``hold_ns``. So a bag (``live=False``) takes a capture split over messages in any way; live,
    the bodies of one capture must come in one message (as the driver sends them), its joints
    may be split. A message without markers (nobody seen) is an empty capture at its receive
    time less the stream's largest recent latency (none before a body showed the latency).
    Markers of a capture already given out are dropped (``late_markers``).

    Malformed input never raises: a message that is not a MarkerArray (``malformed_messages``),
    a marker that is not a body joint (``malformed_markers``: not a SPHERE, an id whose joint is
    past 31, a position not finite or beyond 20 m) are counted and reported once each through
    ``warn``; DELETE / DELETEALL markers are ignored."""

    def __init__(self, frame_id: str = 'kinect_link', jmap: Optional[K4abtMap] = None,
                 tilt_deg: float = DEPTH_TILT_DEG, warn: Optional[Callable[[str], None]] = None,
                 layout: Optional[str] = None, live: bool = True):
        self.frame_id = frame_id
        self.live = live
        self.jmap = jmap or load_map()
        self.rotation = camera_to_sensor(tilt_deg)
        self._warn = warn or (lambda text: None)
        self._warned: set = set()
        self.decode = MarkerArrayDecoder(layout)
        self._pending: Dict[int, Capture] = {}
        self._last_out: Optional[int] = None
        self._latency_ns = 0
        self._latencies: collections.deque = collections.deque(maxlen=30)
        self.counts = {'messages': 0, 'captures': 0, 'empty_captures': 0, 'bodies': 0,
                       'malformed_messages': 0, 'malformed_markers': 0, 'late_markers': 0,
                       'missing_joints': 0}
        self.frames_seen: set = set()

    def _warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            self._warn(text)

    def feed(self, data: bytes, recv_ns: int) -> List[Tuple[int, List[SkeletonFrame]]]:
        self.counts['messages'] += 1
        try:
            markers = self.decode(data)
        except MarkerCdrError as e:
            self.counts['malformed_messages'] += 1
            self._warn_once('message', f'body_tracking_data: malformed message dropped ({e}); '
                            f'further ones are only counted')
            return []
        return self.add(markers, recv_ns)

    def add(self, markers: Sequence[Marker], recv_ns: int) -> List[Tuple[int, List[SkeletonFrame]]]:
        out = []
        touched = set()
        for m in markers:
            if m.action != ADD:
                continue
            joint, body = m.id % ID_STRIDE, m.id // ID_STRIDE
            pos = np.array(m.position, float)
            if (m.type != SPHERE or m.id < 0 or joint >= NUM_K4ABT
                    or not np.all(np.isfinite(pos)) or float(np.abs(pos).max()) > MAX_RANGE_M):
                self.counts['malformed_markers'] += 1
                self._warn_once('marker', f'body_tracking_data: a marker that is not a body '
                                f'joint dropped (type {m.type}, id {m.id}, position {m.position}); '
                                f'further ones are only counted')
                continue
            if m.frame_id not in self.frames_seen:
                self.frames_seen.add(m.frame_id)
                if not m.frame_id.endswith(DEPTH_FRAME_SUFFIX):
                    self._warn_once('frame', f'body_tracking_data: markers in frame '
                                    f'{m.frame_id!r}, not the driver\'s *{DEPTH_FRAME_SUFFIX}: '
                                    f'taken as the depth camera\'s optical axes')
            if self._last_out is not None and m.stamp_ns <= self._last_out:
                self.counts['late_markers'] += 1
                self._warn_once('late', 'body_tracking_data: markers of a capture already '
                                'published arrived late and were dropped; further ones are only '
                                'counted')
                continue
            cap = self._pending.get(m.stamp_ns)
            if cap is None:
                cap = self._pending[m.stamp_ns] = Capture(m.stamp_ns)
            b = cap.bodies.get(body)
            if b is None:
                b = cap.bodies[body] = (np.zeros((NUM_K4ABT, 3)), np.zeros(NUM_K4ABT, bool))
            b[0][joint] = pos
            b[1][joint] = True
            cap.last_ns = recv_ns
            touched.add(m.stamp_ns)
        if touched:
            newest = max(touched)
            self._latency_ns = max(0, recv_ns - newest)
            self._latencies.append(self._latency_ns)
            # every capture older than the newest one touched is done; a complete one too
            for stamp in sorted(self._pending):
                if stamp < newest or (self.live and self._pending[stamp].complete()):
                    out.append(self._emit(stamp))
        elif not markers:
            # nobody seen: what was pending is done, then an empty capture. The message has no
            # stamp: its capture time is the receive time less the largest recent latency (so a
            # later capture's own stamp still comes after it), and none is made before a body
            # has shown the latency
            out.extend(self.flush())
            stamp = recv_ns - max(self._latencies, default=0)
            if self._latencies and (self._last_out is None or stamp > self._last_out):
                self._last_out = stamp
                self.counts['empty_captures'] += 1
                out.append((stamp, []))
        return [o for o in out if o is not None]

    def flush(self, now_ns: Optional[int] = None, hold_ns: int = 0):
        """Captures nothing came for since ``hold_ns`` before ``now_ns`` (None: all of them)."""
        return [self._emit(s) for s in sorted(self._pending)
                if now_ns is None or now_ns - self._pending[s].last_ns >= hold_ns]

    def _emit(self, stamp: int) -> Tuple[int, List[SkeletonFrame]]:
        cap = self._pending.pop(stamp)
        self._last_out = stamp if self._last_out is None else max(self._last_out, stamp)
        frames = []
        for body, (pos, present) in sorted(cap.bodies.items()):
            self.counts['missing_joints'] += int(NUM_K4ABT - present.sum())
            f = body_frame(pos @ self.rotation.T, present, self.jmap, user_id=body,
                           stamp_ns=stamp, frame_id=self.frame_id)
            if f is not None:
                frames.append(f)
        self.counts['captures'] += 1
        self.counts['bodies'] += len(frames)
        return stamp, frames


def is_body_tracking_topic(topic: str, msgtype: str) -> bool:
    """A topic of the Azure Kinect ROS driver's body markers (any namespace)."""
    return msgtype == MARKER_ARRAY and topic.rstrip('/').endswith(TOPIC_SUFFIX)


def body_tracking_topics(topics: Dict[str, Tuple[str, int]]) -> List[str]:
    """The body-marker topics of a bag's ``{topic: (type, count)}``, sorted."""
    return sorted(t for t, (ty, n) in topics.items() if is_body_tracking_topic(t, ty) and n)


def bag_captures(messages, frame_id: str = 'kinect_link', warn=None, stream=None):
    """``(log_ns, stamp_ns, frames)`` for every capture of a bag's body-marker messages
    (``(data, log_ns)`` pairs, in log order); ``stream``: a :class:`MarkerStream` to use."""
    s = stream or MarkerStream(frame_id, warn=warn, live=False)
    for data, log_ns in messages:
        for stamp, frames in s.feed(data, log_ns):
            yield log_ns, stamp, frames
    for stamp, frames in s.flush():
        yield stamp + s._latency_ns, stamp, frames


def k4abt_from_model(positions: np.ndarray, jmap: Optional[K4abtMap] = None) -> np.ndarray:
    """32 K4ABT joints (sensor frame) whose mapping gives the 20 model ``positions`` back: the
    joints the map does not anchor placed where the SDK puts them (clavicles between the neck and
    the shoulders, hand tip and thumb past the hand, ears beside and face joints in front of the
    head), the anchors then solved so that each refined joint lands on its model position. For
    simulated drivers and tests."""
    from skeleton_core.model import (HAND_LEFT, HAND_RIGHT, HEAD, SHOULDER_CENTER, SHOULDER_LEFT,
                                     SHOULDER_RIGHT, SPINE, WRIST_LEFT, WRIST_RIGHT)
    jmap = jmap or load_map()
    p = np.asarray(positions, float)
    k = np.zeros((NUM_K4ABT, 3))
    k[jmap.anchor] = p
    left = p[SHOULDER_LEFT] - p[SHOULDER_RIGHT]
    left /= max(np.linalg.norm(left), 1e-9)
    up = p[HEAD] - p[SHOULDER_CENTER]
    up /= max(np.linalg.norm(up), 1e-9)
    fwd = np.cross(left, up)
    fwd /= max(np.linalg.norm(fwd), 1e-9)
    K = K4ABT_INDEX
    k[K['SPINE_CHEST']] = 0.5 * (p[SPINE] + p[SHOULDER_CENTER])
    k[K['CLAVICLE_LEFT']] = p[SHOULDER_CENTER] + 0.35 * (p[SHOULDER_LEFT] - p[SHOULDER_CENTER])
    k[K['CLAVICLE_RIGHT']] = p[SHOULDER_CENTER] + 0.35 * (p[SHOULDER_RIGHT] - p[SHOULDER_CENTER])
    for side, hand, wrist in (('LEFT', HAND_LEFT, WRIST_LEFT), ('RIGHT', HAND_RIGHT, WRIST_RIGHT)):
        d = p[hand] - p[wrist]
        d /= max(np.linalg.norm(d), 1e-9)
        k[K[f'HANDTIP_{side}']] = p[hand] + 0.07 * d
        k[K[f'THUMB_{side}']] = p[hand] + 0.03 * d + 0.03 * fwd
    k[K['EAR_LEFT']] = p[HEAD] + 0.075 * left
    k[K['EAR_RIGHT']] = p[HEAD] - 0.075 * left
    k[K['NOSE']] = p[HEAD] + 0.10 * fwd - 0.02 * up
    k[K['EYE_LEFT']] = p[HEAD] + 0.08 * fwd + 0.03 * left + 0.02 * up
    k[K['EYE_RIGHT']] = p[HEAD] + 0.08 * fwd - 0.03 * left + 0.02 * up
    for j in range(NUM_JOINTS):
        r = jmap.refine[j]
        if r is not None:   # anchor = (model - sum of the others' shares) / its own weight
            idx, w = r
            k[idx[0]] = (p[j] - w[1:] @ k[idx[1:]]) / w[0]
    return k


# ------------------------------------------------------------------------------------------
# The SDK's offline_processor JSON
# ------------------------------------------------------------------------------------------
_CONF_KEYS = ('confidence_levels', 'joint_confidence', 'confidence_level')


def read_offline_json(path, frame_id: str = 'kinect_link', jmap: Optional[K4abtMap] = None,
                      tilt_deg: float = DEPTH_TILT_DEG
                      ) -> Iterator[Tuple[int, List[SkeletonFrame]]]:
    """``(stamp_ns, frames)`` per frame of the Azure Kinect Body Tracking SDK's
    ``offline_processor`` JSON (``frames[]``: ``timestamp_usec``, ``bodies[]``: ``body_id``,
    ``joint_positions`` (32 x [x, y, z] mm, depth camera axes), ``joint_orientations``; a per-joint
    confidence list under ``confidence_levels`` / ``joint_confidence`` when the tool wrote one).
    Raises :class:`K4abtError` (one line) for a file that is not that JSON; a body that is
    malformed is skipped (counted in ``read_offline_json.skipped``)."""
    path = Path(path)
    try:
        with open(path, encoding='utf-8') as f:
            data = json.load(f)
    except (OSError, UnicodeDecodeError) as e:
        raise K4abtError(f'{path}: cannot read ({getattr(e, "strerror", None) or e})') from None
    except json.JSONDecodeError as e:
        raise K4abtError(f'{path}: not JSON ({e})') from None
    frames = data.get('frames') if isinstance(data, dict) else None
    if not isinstance(frames, list):
        raise K4abtError(f"{path}: not the Body Tracking SDK's offline_processor JSON (no "
                         f"'frames' list)")
    names = data.get('joint_names')
    if isinstance(names, list) and len(names) not in (0, NUM_K4ABT):
        raise K4abtError(f'{path}: joint_names lists {len(names)} joints, K4ABT has {NUM_K4ABT}')
    jmap = jmap or load_map()
    rot = camera_to_sensor(tilt_deg)
    skipped = 0
    last = None
    for i, fr in enumerate(frames):
        if not isinstance(fr, dict) or not isinstance(fr.get('timestamp_usec'), (int, float)):
            skipped += 1
            continue
        stamp = int(round(fr['timestamp_usec'] * 1000))
        if last is not None and stamp <= last:
            skipped += 1
            continue
        last = stamp
        out = []
        for b in fr.get('bodies') or []:
            try:
                pos = np.asarray(b['joint_positions'], float).reshape(NUM_K4ABT, 3) / 1000.0
                conf = None
                for k in _CONF_KEYS:
                    if isinstance(b.get(k), list) and len(b[k]) == NUM_K4ABT:
                        conf = np.asarray([c[0] if isinstance(c, list) else c for c in b[k]], int)
                        break
                uid = int(b.get('body_id', 0))
            except (KeyError, TypeError, ValueError):
                skipped += 1
                continue
            present = np.all(np.isfinite(pos), axis=1) & (np.abs(pos).max(axis=1) < MAX_RANGE_M)
            pos = np.where(present[:, None], pos, 0.0)
            f = body_frame(pos @ rot.T, present, jmap, confidence=conf, user_id=uid,
                           stamp_ns=stamp, frame_id=frame_id)
            if f is not None:
                out.append(f)
        yield stamp, out
    read_offline_json.skipped = skipped


read_offline_json.skipped = 0


def import_offline_json(src, out, frame_id: str = 'kinect_link') -> Dict:
    """Write the SDK JSON ``src`` as a bag ``out`` (``/kinect/skeletons`` and the tracker on
    ``/kinect/tracker``) that replays and processes like any recording."""
    from skeleton_core.bagio import BagWriter
    from skeleton_core.cdr import frames_to_cdr
    from skeleton_core.tracker import write_to_bag
    n = users = 0
    ids: set = set()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + '.part')
    try:
        with BagWriter(str(tmp)) as w:
            for stamp, frames in read_offline_json(src, frame_id):
                if n == 0:
                    write_to_bag(w, TRACKER, stamp)
                w.write_raw('/kinect/skeletons', frames_to_cdr(frames, stamp, frame_id), stamp)
                n += 1
                users += len(frames)
                ids.update(f.user_id for f in frames)
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            tmp.unlink()
    return {'frames': n, 'user_frames': users, 'users': sorted(ids),
            'skipped': read_offline_json.skipped, 'out': str(out)}


def main(argv=None) -> int:
    """``import_azure_json SRC.json --out BAG.mcap``."""
    import argparse
    import sys
    p = argparse.ArgumentParser(prog='import_azure_json', description=(
        "Import the Azure Kinect Body Tracking SDK's offline_processor JSON as a bag "
        '(/kinect/skeletons, tracker azure_kinect_bt) for replay and process_bag.'))
    p.add_argument('src', help='the JSON file written by offline_processor')
    p.add_argument('--out', default=None, help='output bag (default: SRC with .mcap)')
    p.add_argument('--frame-id', default='kinect_link')
    a = p.parse_args(argv)
    out = Path(a.out) if a.out else Path(a.src).with_suffix('.mcap')
    try:
        s = import_offline_json(a.src, out, a.frame_id)
    except (K4abtError, OSError) as e:
        print(f'import_azure_json: error: {e}', file=sys.stderr)
        return 1
    if not s['frames']:
        print(f'import_azure_json: error: {a.src} holds no frames', file=sys.stderr)
        return 1
    print(f"import_azure_json: {s['frames']} frames, {len(s['users'])} bodies "
          f"({s['skipped']} malformed skipped) -> {out}")
    return 0


__all__ = ['JOINTS', 'NUM_K4ABT', 'TRACKER', 'K4abtMap', 'K4abtError', 'MarkerStream', 'Capture',
           'load_map', 'parse_map', 'camera_to_sensor', 'body_frame', 'read_offline_json',
           'import_offline_json', 'is_body_tracking_topic', 'body_tracking_topics',
           'bag_captures', 'k4abt_from_model']
