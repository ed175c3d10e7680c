"""A simulated Azure Kinect ROS driver for the tests: bodies entering and leaving in front of the
camera, their 32 K4ABT joints with tracker noise, as the driver's ``body_tracking_data``
MarkerArrays (``K4AROSDevice::getBodyMarker``: SPHERE, ns '', id = body * 100 + joint, frame
``<tf_prefix>depth_camera_link``, depth camera optical axes, metres, lifetime 0.25 s, one message
per capture holding every body; an empty message when nobody is seen)."""
from __future__ import annotations

from typing import Dict, List, Tuple

import numpy as np

from skeleton_data import k4abt as K4
from skeleton_eval.clips import toy_clip

FPS = 30.0
FRAMES = 150
NOISE_M = 0.012          # K4ABT joint noise (1 sigma, per axis)
# body id -> (first frame, last frame, place in the sensor frame (x ahead, y left))
BODIES = {1: (5, 149, (2.6, 0.3)), 2: (30, 99, (3.3, -0.7)), 3: (110, 149, (3.0, -0.5))}
MISSING = (50, 2, 'HAND_LEFT')   # frame, body, joint left out of the message
SENSOR_HEIGHT = 0.8


def truth(seconds: float = FRAMES / FPS) -> Dict[int, np.ndarray]:
    """Model skeletons (frames, 20, 3) of each body in the sensor frame (REP-103), facing it."""
    clip = toy_clip(seconds=seconds + 1.0)
    out = {}
    for body, (a, b, (x, y)) in BODIES.items():
        p = clip.positions[(np.arange(FRAMES) + 7 * body) % len(clip.positions)]
        p = p * np.array([-1.0, -1.0, 1.0]) + np.array([x, y, -SENSOR_HEIGHT])   # yaw 180 deg
        out[body] = p
    return out


def captures(seed: int = 3) -> List[List[Tuple[int, np.ndarray, np.ndarray]]]:
    """Per frame: [(body id, (32, 3) positions in depth camera axes, (32,) present), ...]."""
    rng = np.random.default_rng(seed)
    cam = K4.camera_to_sensor()
    jmap = K4.load_map()
    t = truth()
    out = []
    for i in range(FRAMES):
        bodies = []
        for body, (a, b, _) in BODIES.items():
            if a <= i <= b:
                k = K4.k4abt_from_model(t[body][i], jmap) + rng.normal(0, NOISE_M, (K4.NUM_K4ABT, 3))
                present = np.ones(K4.NUM_K4ABT, bool)
                if (i, body) == MISSING[:2]:
                    present[K4.K4ABT_INDEX[MISSING[2]]] = False
                bodies.append((body, k @ cam, present))   # sensor -> depth camera axes
        out.append(bodies)
    return out


def expected_user_frames() -> Dict[int, int]:
    return {body: b - a + 1 for body, (a, b, _) in BODIES.items()}


def marker_array(bodies, stamp_ns: int, frame_id: str = 'depth_camera_link'):
    """The driver's MarkerArray of one capture (rclpy message)."""
    from visualization_msgs.msg import Marker, MarkerArray
    arr = MarkerArray()
    for body, pos, present in bodies:
        for j in range(K4.NUM_K4ABT):
            if not present[j]:
                continue
            m = Marker()
            m.header.frame_id = frame_id
            m.header.stamp.sec, m.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
            m.lifetime.nanosec = 250_000_000
            m.id = body * 100 + j
            m.type = Marker.SPHERE
            m.color.a, m.color.r = 1.0, 0.5
            m.scale.x = m.scale.y = m.scale.z = 0.05
            m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in pos[j])
            m.pose.orientation.w = 1.0
            arr.markers.append(m)
    return arr


def write_bag(path, t0_ns: int = 1_700_000_000_000_000_000, latency_ns: int = 45_000_000,
              split=(60, 70), extra_topics: bool = True) -> Dict:
    """A bag as ``ros2 bag record /body_tracking_data /imu`` writes it from the driver; capture
    ``split[0]`` comes as two messages (one body each), capture ``split[1]`` with its joints over
    two messages. Returns {frame: stamp_ns}."""
    from skeleton_core.bagio import BagWriter
    MA = 'visualization_msgs/msg/MarkerArray'
    stamps = {}
    with BagWriter(str(path)) as bag:
        for i, bodies in enumerate(captures()):
            stamp = t0_ns + int(round(i * 1e9 / FPS))
            stamps[i] = stamp
            log = stamp + latency_ns
            if i == split[0] and len(bodies) > 1:
                bag.write('/body_tracking_data', marker_array(bodies[:1], stamp), log, MA)
                bag.write('/body_tracking_data', marker_array(bodies[1:], stamp), log + 1000, MA)
            elif i == split[1]:
                arr = marker_array(bodies, stamp)
                half = len(arr.markers) // 2
                first = type(arr)(markers=arr.markers[:half])
                bag.write('/body_tracking_data', first, log, MA)
                bag.write('/body_tracking_data', type(arr)(markers=arr.markers[half:]),
                          log + 1000, MA)
            else:
                bag.write('/body_tracking_data', marker_array(bodies, stamp), log, MA)
            if extra_topics and i % 10 == 0:   # whatever else the user recorded
                from sensor_msgs.msg import Imu
                imu = Imu()
                imu.header.frame_id = 'imu_link'
                imu.linear_acceleration.z = 9.81
                bag.write('/imu', imu, log + 2000, 'sensor_msgs/msg/Imu')
    return stamps


def users_of(path, topic) -> Dict[int, Dict[int, np.ndarray]]:
    """{user: {stamp: positions}} of a SkeletonArray topic of a bag that may still be written."""
    from skeleton_core.bagio import read_messages
    from skeleton_core.cdr import frames_from_cdr
    out: Dict[int, Dict[int, np.ndarray]] = {}
    try:
        for m in read_messages(path, topics=[topic], decode=False, warn=lambda s: None):
            for f in frames_from_cdr(m.data)[2]:
                out.setdefault(f.user_id, {})[f.stamp_ns] = f.positions
    except Exception:  # noqa: BLE001 - missing, or its header not on disk yet
        return {}
    return out


def user_frames(users) -> Dict[int, int]:
    return {u: len(v) for u, v in users.items()}
