"""``visualization_msgs/msg/MarkerArray`` CDR bytes -> the fields a body tracker's markers carry
(no rclpy): the bytes of a bag, or of a subscription taken with ``raw=True``.

Only what a skeleton needs is kept per marker: header stamp and frame, ``ns``, ``id``, ``type``,
``action``, the pose (position, orientation x y z w) and the lifetime; the rest is skipped.

Two layouts of ``visualization_msgs/Marker`` are in use: the one of ROS 2 Iron and later (Jazzy,
Kilted: ``texture_resource``, ``texture``, ``uv_coordinates`` and ``mesh_file`` added) and the one
of Humble and earlier (without them) -- a bag recorded on a Humble PC holds the latter. A decoder
finds which one a stream uses from its first non-empty message (the layout that parses the whole
message to its end) and keeps it. Errors: :class:`MarkerCdrError` (one line), never another
exception on malformed bytes.
"""
from __future__ import annotations

import struct
from typing import List, NamedTuple, Optional, Tuple

SPHERE = 2
ADD, DELETE, DELETEALL = 0, 2, 3
LAYOUTS = ('iron', 'humble')
_MAX_COUNT = 1 << 20   # a sequence longer than this is a parse error, not an allocation


class MarkerCdrError(ValueError):
    """Bytes that are not a MarkerArray of the expected layout."""


class Marker(NamedTuple):
    stamp_ns: int
    frame_id: str
    ns: str
    id: int
    type: int
    action: int
    position: Tuple[float, float, float]
    orientation: Tuple[float, float, float, float]   # x, y, z, w
    lifetime_ns: int


_I32 = struct.Struct('<i')
_U32 = struct.Struct('<I')
_STAMP = struct.Struct('<iI')
_IDS = struct.Struct('<iii')
_POSE = struct.Struct('<7d')


class _Reader:
    __slots__ = ('b', 'o', 'n')

    def __init__(self, data: bytes):
        self.b = data
        self.o = 4            # after the encapsulation header; alignment counts from here
        self.n = len(data)

    def align(self, k: int) -> None:
        r = (self.o - 4) % k
        if r:
            self.o += k - r

    def need(self, k: int) -> None:
        if self.o + k > self.n:
            raise MarkerCdrError(f'MarkerArray: message ends at byte {self.n}, needs {self.o + k}')

    def u32(self) -> int:
        self.align(4)
        self.need(4)
        v = _U32.unpack_from(self.b, self.o)[0]
        self.o += 4
        return v

    def count(self) -> int:
        v = self.u32()
        if v > _MAX_COUNT:
            raise MarkerCdrError(f'MarkerArray: sequence of {v} elements')
        return v

    def string(self) -> str:
        k = self.count()
        self.need(k)
        s = self.b[self.o:self.o + k]
        self.o += k
        if k == 0 or s[-1] != 0:
            raise MarkerCdrError('MarkerArray: string without its terminating NUL')
        return s[:-1].decode('utf-8', 'replace')

    def skip(self, size: int, align: int, n: int = 1) -> None:
        if n:
            self.align(align)
            self.need(size * n)
            self.o += size * n

    def header(self) -> Tuple[int, str]:
        self.align(4)
        self.need(8)
        sec, nsec = _STAMP.unpack_from(self.b, self.o)
        self.o += 8
        return sec * 1_000_000_000 + nsec, self.string()


def _marker(r: _Reader, layout: str) -> Marker:
    stamp, frame = r.header()
    ns = r.string()
    r.align(4)
    r.need(12)
    mid, mtype, action = _IDS.unpack_from(r.b, r.o)
    r.o += 12
    r.align(8)
    r.need(56)
    px, py, pz, qx, qy, qz, qw = _POSE.unpack_from(r.b, r.o)
    r.o += 56
    r.skip(8, 8, 3)          # scale
    r.skip(4, 4, 4)          # color
    r.align(4)
    r.need(8)
    lsec, lnsec = _STAMP.unpack_from(r.b, r.o)
    r.o += 8
    r.skip(1, 1)             # frame_locked
    r.skip(24, 8, r.count())     # points
    r.skip(16, 4, r.count())     # colors
    if layout == 'iron':
        r.string()                   # texture_resource
        r.header()                   # texture (sensor_msgs/CompressedImage)
        r.string()
        r.skip(1, 1, r.count())
        r.skip(8, 4, r.count())      # uv_coordinates
    r.string()                       # text
    r.string()                       # mesh_resource
    if layout == 'iron':
        r.string()                   # mesh_file
        r.skip(1, 1, r.count())
    r.skip(1, 1)                     # mesh_use_embedded_materials
    return Marker(stamp, frame, ns, mid, mtype, action, (px, py, pz), (qx, qy, qz, qw),
                  lsec * 1_000_000_000 + lnsec)


def decode_markers(data: bytes, layout: str) -> List[Marker]:
    """The markers of one MarkerArray in ``layout`` (:data:`LAYOUTS`)."""
    data = bytes(data)
    if len(data) < 8:
        raise MarkerCdrError('MarkerArray: short message')
    if data[1] != 1:
        raise MarkerCdrError('MarkerArray: not little-endian CDR')
    r = _Reader(data)
    out = [_marker(r, layout) for _ in range(r.count())]
    if r.n - r.o > 3:   # at most the final alignment padding may follow
        raise MarkerCdrError(f'MarkerArray: {r.n - r.o} bytes after the last marker')
    return out


class MarkerArrayDecoder:
    """Decodes one stream's MarkerArray messages, finding its layout on the first marker."""

    def __init__(self, layout: Optional[str] = None):
        self.layout = layout

    def __call__(self, data: bytes) -> List[Marker]:
        if self.layout is not None:
            return decode_markers(data, self.layout)
        err = None
        for layout in LAYOUTS:
            try:
                out = decode_markers(data, layout)
            except MarkerCdrError as e:
                err = err or e
                continue
            if out:
                self.layout = layout
            return out
        raise err


def installed_layout() -> Optional[str]:
    """The layout of the installed ``visualization_msgs`` (None when it is not importable)."""
    try:
        from visualization_msgs.msg import Marker as M
    except ImportError:
        return None
    return 'iron' if 'texture_resource' in M.get_fields_and_field_types() else 'humble'


__all__ = ['Marker', 'MarkerArrayDecoder', 'MarkerCdrError', 'decode_markers', 'installed_layout',
           'LAYOUTS', 'SPHERE', 'ADD', 'DELETE', 'DELETEALL']
