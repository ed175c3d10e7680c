"""A small C3D reader (the marker trajectories of a mocap system): POINT data only, no rclpy, no
third-party package (none is in the environment).

Supported: Intel (PC) byte order (processor type 84, what Vicon Nexus, Qualisys and Motive
write on PCs), floating-point or scaled-integer POINT data, the parameters ``POINT:LABELS``
(+ ``LABELS2``...), ``POINT:USED``, ``POINT:SCALE``, ``POINT:RATE``, ``POINT:DATA_START``,
``ANALOG:USED`` / ``ANALOG:RATE`` (to skip the analog samples between frames). A sample whose
residual is negative (the system's "invalid") is NaN. DEC and MIPS files are refused with one
line (convert them to PC byte order in the mocap software).

The format (C3D.org, "The C3D File Format User Guide", Motion Lab Systems 2008): 512-byte blocks;
block 1 is the header; the parameter section starts at the block named by the header's first
byte; each frame holds, per point, X Y Z and a residual word, then the analog samples.
"""
from __future__ import annotations

import struct
from pathlib import Path
from typing import Dict, List, Tuple

import numpy as np


class C3DError(ValueError):
    """A C3D file that cannot be read (one line naming the file)."""


def _params(buf: bytes, path) -> Dict[str, Dict[str, Tuple[int, tuple, bytes]]]:
    """{GROUP: {PARAM: (type, dims, raw data)}} of the parameter section ``buf``."""
    if len(buf) < 4:
        raise C3DError(f'{path}: truncated parameter section')
    if buf[3] != 84:
        kind = {85: 'DEC', 86: 'MIPS'}.get(buf[3], f'processor type {buf[3]}')
        raise C3DError(f'{path}: {kind} byte order is not supported (write the file for PC / '
                       'Intel)')
    groups: Dict[int, str] = {}
    pending: List[Tuple[int, str, tuple]] = []
    pos = 4
    while pos + 2 <= len(buf):
        nlen = struct.unpack('<b', buf[pos:pos + 1])[0]
        gid = struct.unpack('<b', buf[pos + 1:pos + 2])[0]
        if nlen == 0:
            break
        nlen = abs(nlen)
        name = buf[pos + 2:pos + 2 + nlen].decode('ascii', 'replace').upper()
        p = pos + 2 + nlen
        nxt = struct.unpack('<h', buf[p:p + 2])[0]
        body = p + 2
        if gid < 0:
            groups[-gid] = name
        else:
            typ = struct.unpack('<b', buf[body:body + 1])[0]
            nd = buf[body + 1]
            dims = tuple(buf[body + 2:body + 2 + nd])
            size = abs(typ) * int(np.prod(dims)) if nd else abs(typ)
            start = body + 2 + nd
            pending.append((gid, name, (typ, dims, buf[start:start + size])))
        if nxt == 0:
            break
        pos = p + nxt
    out: Dict[str, Dict[str, Tuple[int, tuple, bytes]]] = {}
    for gid, name, val in pending:
        out.setdefault(groups.get(gid, str(gid)), {})[name] = val
    return out


def _num(val, fmt):
    typ, dims, raw = val
    n = len(raw) // struct.calcsize(fmt)
    vals = struct.unpack('<' + fmt * n, raw[:n * struct.calcsize(fmt)])
    return vals


def _scalar(p, group, name, default=None):
    v = p.get(group, {}).get(name)
    if v is None:
        return default
    typ = v[0]
    vals = _num(v, {1: 'B', 2: 'h', 4: 'f'}[abs(typ)]) if typ != -1 else None
    return vals[0] if vals else default


def _labels(p, path) -> List[str]:
    out = []
    for key in ['LABELS'] + [f'LABELS{k}' for k in range(2, 10)]:
        v = p.get('POINT', {}).get(key)
        if v is None:
            break
        typ, dims, raw = v
        if typ != -1 or len(dims) != 2:
            raise C3DError(f'{path}: POINT:{key} is not a character array')
        w = dims[0]
        out += [raw[i * w:(i + 1) * w].decode('ascii', 'replace').strip()
                for i in range(dims[1])]
    return out


def read_c3d(path) -> Tuple[List[str], np.ndarray, float]:
    """(labels, points (F, P, 3) in the file's units, frame rate): NaN where invalid."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise C3DError(f'{path}: cannot read ({e.strerror or e})') from None
    if len(data) < 512 or data[1] != 0x50:
        raise C3DError(f'{path}: not a C3D file (no 0x50 key in the header)')
    pblock = data[0]
    p = _params(data[(pblock - 1) * 512:], path)
    n_pts = int(_scalar(p, 'POINT', 'USED', struct.unpack('<H', data[2:4])[0]))
    scale = float(_scalar(p, 'POINT', 'SCALE', struct.unpack('<f', data[12:16])[0]))
    rate = float(_scalar(p, 'POINT', 'RATE', struct.unpack('<f', data[20:24])[0]))
    start = int(_scalar(p, 'POINT', 'DATA_START', struct.unpack('<H', data[16:18])[0]))
    first, last = struct.unpack('<HH', data[6:10])
    n_frames = int(_scalar(p, 'POINT', 'FRAMES', last - first + 1))
    n_frames = n_frames if n_frames > 0 else n_frames + 65536
    analog_used = int(_scalar(p, 'ANALOG', 'USED', 0) or 0)
    analog_rate = float(_scalar(p, 'ANALOG', 'RATE', rate) or rate)
    per_frame = int(round(analog_rate / rate)) if rate > 0 and analog_used else 0
    labels = _labels(p, path)[:n_pts]
    labels += [f'point{k}' for k in range(len(labels), n_pts)]
    is_float = scale < 0
    word = 4 if is_float else 2
    stride = (4 * n_pts + analog_used * per_frame) * word
    body = data[(start - 1) * 512:]
    n_frames = min(n_frames, len(body) // stride) if stride else 0
    if n_frames < 1 or rate <= 0:
        raise C3DError(f'{path}: no point frames')
    raw = np.frombuffer(body[:n_frames * stride], dtype='<f4' if is_float else '<i2')
    raw = raw.reshape(n_frames, -1)[:, :4 * n_pts].reshape(n_frames, n_pts, 4).astype(float)
    xyz = raw[..., :3] * (1.0 if is_float else abs(scale))
    xyz[raw[..., 3] < 0] = np.nan
    return labels, xyz, rate


def read_c3d_markers(path, jm) -> Tuple[np.ndarray, float]:
    """(N, 39, 3) Plug-in-Gait markers of a C3D file in REP-103 metres through a ``markers``
    joint map (its ``columns`` name the file's labels to use, ``markers`` renames them), and the
    frame rate. A missing label is a :class:`C3DError` naming it."""
    from . import vicon
    labels, xyz, rate = read_c3d(path)
    index = {lab.split(':')[-1]: k for k, lab in enumerate(labels)}   # 'Subject:LASI' -> LASI
    lookup = {jm.markers.get(c, c): c for c in jm.columns}
    missing = [lookup[m] for m in vicon.MARKERS if lookup.get(m) not in index]
    if missing:
        raise C3DError(f'{path}: no marker {", ".join(missing[:5])}'
                       + (' ...' if len(missing) > 5 else '') + f' (labels: '
                       f'{", ".join(labels[:8])}{" ..." if len(labels) > 8 else ""})')
    m = xyz[:, [index[lookup[name]] for name in vicon.MARKERS]]
    return (m * jm.scale) @ jm.rotation.T, rate


def write_c3d(path, labels: List[str], points: np.ndarray, rate: float) -> Path:
    """A minimal float C3D (Intel) of (F, P, 3) points; NaN = invalid (tests, conversions)."""
    path = Path(path)
    f, n, _ = points.shape

    def param(gid, name, typ, dims, raw):
        nm = name.encode()
        body = struct.pack('<bB', typ, len(dims)) + bytes(dims) + raw + b'\0'
        return struct.pack('<bb', len(nm), gid) + nm + struct.pack('<h', 2 + len(body)) + body

    def group(gid, name):
        nm = name.encode()
        return struct.pack('<bb', len(nm), -gid) + nm + struct.pack('<h', 3) + b'\0'

    w = max(len(s) for s in labels) if labels else 1
    lab = b''.join(s.encode().ljust(w) for s in labels)
    ps = (group(1, 'POINT') + param(1, 'USED', 2, (), struct.pack('<h', n))
          + param(1, 'SCALE', 4, (), struct.pack('<f', -1.0))
          + param(1, 'RATE', 4, (), struct.pack('<f', rate))
          + param(1, 'DATA_START', 2, (), struct.pack('<h', 0))
          + param(1, 'FRAMES', 2, (), struct.pack('<h', f))
          + param(1, 'LABELS', -1, (w, n), lab))
    nblocks = (4 + len(ps) + 2 + 511) // 512
    start = 2 + nblocks
    ps = ps.replace(param(1, 'DATA_START', 2, (), struct.pack('<h', 0)),
                    param(1, 'DATA_START', 2, (), struct.pack('<h', start)))
    psec = (bytes([1, 80, nblocks, 84]) + ps + b'\0\0').ljust(nblocks * 512, b'\0')
    header = bytearray(512)
    header[0], header[1] = 2, 0x50
    struct.pack_into('<HHHHHf', header, 2, n, 0, 1, f, 0, -1.0)
    struct.pack_into('<H', header, 16, start)
    struct.pack_into('<Hf', header, 18, 0, rate)
    d = np.zeros((f, n, 4), '<f4')
    d[..., :3] = np.nan_to_num(points)
    d[..., 3] = np.where(np.isfinite(points).all(-1), 0.0, -1.0)
    path.write_bytes(bytes(header) + psec + d.tobytes())
    return path


__all__ = ['read_c3d', 'read_c3d_markers', 'write_c3d', 'C3DError']
