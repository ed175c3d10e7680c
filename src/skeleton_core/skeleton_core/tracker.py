"""Which skeleton tracker a stream comes from, carried with the data (no rclpy).

A learned sensor correction (``pose_reconstruction.correction``) is specific to the skeleton
tracker it was learned from, so every stream the product writes or reads declares its tracker:

* **On the graph**: the driver publishes the tracker's name once on :data:`TOPIC`
  (``/kinect/tracker``, ``std_msgs/msg/String``) with a *transient local* (latched) QoS of depth
  1, so a node that starts later still receives it: ``nite2`` for the live OpenNI2/NiTE2 source,
  ``sensor_model`` for the synthetic one, and for a replay whatever the bag declares. The
  reconstruction reads it and picks the correction learned for that tracker; an explicit
  ``input_tracker`` parameter overrides it.
* **In a bag**: the same topic, one message (the recorder records it like any topic; imported
  recordings write it at their first frame; ``ros2 bag play`` and Foxglove show it). A bag without
  it declares no tracker (recordings from before this existed).

Why a topic and not MCAP metadata or a message field: the topic reaches a node on another
machine (``driver.launch.py`` on the sensor's PC) exactly like the skeletons, needs no change to
``SkeletonArray``, survives a cut recording (it is an ordinary message, written first), and the
same reader serves bags and live graphs.
"""
from __future__ import annotations

from typing import Optional

# skeleton trackers a stream or a correction can come from
TRACKERS = ('kinect_v2_sdk', 'kinect_v1_sdk', 'nite2', 'sensor_model', 'azure_kinect_bt')
TOPIC = '/kinect/tracker'
MSGTYPE = 'std_msgs/msg/String'
DESCRIPTIONS = {
    'kinect_v2_sdk': 'Microsoft Kinect v2 SDK body tracking (e.g. UI-PRMD)',
    'kinect_v1_sdk': 'Microsoft Kinect v1 SDK skeletal tracking',
    'nite2': 'OpenNI2 + NiTE2 user tracker (the live driver)',
    'sensor_model': "the synthetic source's sensor model",
    'azure_kinect_bt': 'Azure Kinect / Orbbec Femto body tracking (K4ABT)',
}


class TrackerError(ValueError):
    """An unknown tracker name (one line naming the known ones)."""


def check(name: str) -> str:
    """``name`` if it is a known tracker (or ''), else :class:`TrackerError`."""
    name = (name or '').strip()
    if name and name not in TRACKERS:
        raise TrackerError(f'unknown skeleton tracker {name!r}; known: {", ".join(TRACKERS)}')
    return name


def resolve(declared: str, streamed: str) -> str:
    """The tracker a reconstruction uses: the explicitly declared one (parameter, option) when
    set, else the one the stream carries ('' = unknown)."""
    return check(declared) or check(streamed)


def string_cdr(text: str) -> bytes:
    """CDR bytes of a ``std_msgs/msg/String`` (little endian), without rclpy."""
    import struct
    b = text.encode('utf-8') + b'\0'
    return b'\x00\x01\x00\x00' + struct.pack('<I', len(b)) + b


def parse_string_cdr(data: bytes) -> str:
    import struct
    data = bytes(data)
    if len(data) < 8:
        raise ValueError('std_msgs/String: short message')
    endian = '<' if data[1] == 1 else '>'
    n = struct.unpack(endian + 'I', data[4:8])[0]
    return data[8:8 + max(n - 1, 0)].decode('utf-8', 'replace')


def write_to_bag(writer, tracker: str, stamp_ns: int) -> None:
    """Declare ``tracker`` in a bag being written (:class:`skeleton_core.bagio.BagWriter`)."""
    writer.write_raw(TOPIC, string_cdr(check(tracker)), int(stamp_ns), MSGTYPE)


def from_bag(path, warn=None) -> str:
    """The tracker a bag declares ('' = none: no :data:`TOPIC` message). An unknown name is
    returned as read (the caller refuses it with :func:`check`)."""
    from .bagio import bag_topics, read_messages
    topics = bag_topics(path, warn=warn)
    if TOPIC not in topics or not topics[TOPIC][1]:
        return ''
    name: Optional[str] = None
    for m in read_messages(path, topics=[TOPIC], decode=False, warn=warn):
        try:
            name = parse_string_cdr(m.data).strip()
        except ValueError:
            continue
        break
    return name or ''


__all__ = ['TRACKERS', 'TOPIC', 'MSGTYPE', 'TrackerError', 'check', 'resolve', 'from_bag',
           'write_to_bag', 'string_cdr', 'parse_string_cdr']
