"""Live source: OpenNI2 device + NiTE2 user tracker (no rclpy).

Libraries
---------
* OpenNI2 through the PyPI bindings ``openni`` (``from openni import openni2, nite2``) and the
  OpenNI2 runtime (Debian/Ubuntu: ``apt-get install libopenni2-0``; its ``libOpenNI2.so.0`` is found
  in the system library directories, or in ``openni2_path``).
* NiTE2 (proprietary, never bundled): the directory of its redistributable (``libNiTE2.so``,
  ``NiTE.ini`` and the ``NiTE2/`` data folder), given as ``nite2_path``.

Device: ``device_uri`` ``''`` = the first device found; an OpenNI2 URI; or a path to an ``.oni``
recording (played by OpenNI2's file driver).

Mapping NiTE -> Kinect skeleton (``skeleton_core.model.NITE_TO_KINECT``)
-------------------------------------------------------------------------
* Axes: NiTE gives millimetres in the camera frame (x right, y up, z forward away from the lens);
  we publish metres in REP-103 (x forward, y left, z up): ``(x, y, z) = (z, -x, y) / 1000``.
* Tracking state from NiTE's joint position confidence ``c``: ``c >= tracked_confidence`` (0.5)
  -> TRACKED, ``c > inferred_confidence`` (0.0) -> INFERRED, else NOT_TRACKED. (NiTE reports
  0, 0.5 or 1 in practice.)
* Joints NiTE does not have are filled with plausible positions so arrays stay valid:
  HipCenter = midpoint of the hips, INFERRED when both hips are at least INFERRED, else
  NOT_TRACKED; HandLeft/Right = the wrist extended along the forearm by the standard body's
  wrist-to-hand offset, NOT_TRACKED; FootLeft/Right = the ankle plus the standard body's
  ankle-to-foot offset turned into the body frame (forward from the hips, up along the trunk),
  NOT_TRACKED. Orientations are not published (identity = unknown); reliability is NaN.
* Only users whose skeleton NiTE reports as TRACKED are published, at most ``max_users`` (6);
  user_id is NiTE's user id.

Errors (one line each, :class:`SourceError`): bindings or OpenNI2 library missing, no device (or
URI / recording that cannot be opened), NiTE2 not found at the configured path. A device that
stops delivering frames mid-run is reported, closed and reopened every ``retry_s`` seconds while
the node keeps running.
"""
from __future__ import annotations

import collections
import os
import sys
import sysconfig
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, List, Optional

import numpy as np

from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import (ANKLE_LEFT, ANKLE_RIGHT, ELBOW_LEFT, ELBOW_RIGHT, FOOT_LEFT,
                                 FOOT_RIGHT, HAND_LEFT, HAND_RIGHT, HIP_CENTER, HIP_LEFT, HIP_RIGHT,
                                 INFERRED, NITE_TO_KINECT, NOT_TRACKED, NUM_JOINTS,
                                 SHOULDER_CENTER, TRACKED, WRIST_LEFT, WRIST_RIGHT, standard_body)
from skeleton_core.params import param

from .base import Source, SourceError, SourceOutput

MAX_USERS = 6
APT_HINT = 'install it: sudo apt-get install libopenni2-0'


@dataclass
class LiveConfig:
    """Parameters of :class:`LiveSource`."""

    device_uri: str = param('', "OpenNI2 device URI ('' = first device) or an .oni recording path")
    nite2_path: str = param('', 'NiTE2 Redist directory (holding libNiTE2.so)')
    openni2_path: str = param('', "directory of libOpenNI2.so ('' = system libraries)")
    max_users: int = param(MAX_USERS, 'most users published per frame', range=(1, MAX_USERS),
                           public=False)   # NiTE's own limit; labs do not lower it
    tracked_confidence: float = param(0.5, 'NiTE joint confidence >= this -> TRACKED',
                                      range=(0.0, 1.0), public=False)
    inferred_confidence: float = param(0.0, 'NiTE joint confidence > this -> INFERRED (else '
                                       'NOT_TRACKED)', range=(0.0, 1.0), public=False)
    smoothing: float = param(0.0, 'NiTE skeleton smoothing factor (0 = off)', range=(0.0, 0.99),
                             public=False)
    retry_s: float = param(0.0, 'when > 0, keep retrying a missing device every retry_s seconds '
                           'instead of exiting (a device lost mid-run is always retried)',
                           range=(0.0, 60.0))


# --------------------------------------------------------------------------------------------
# Pure conversion (unit-tested without any device)
# --------------------------------------------------------------------------------------------
def camera_mm_to_rep103(points_mm) -> np.ndarray:
    """NiTE camera millimetres (x right, y up, z forward) -> REP-103 metres (x fwd, y left, z up)."""
    p = np.asarray(points_mm, dtype=float)
    return np.stack([p[..., 2], -p[..., 0], p[..., 1]], axis=-1) / 1000.0


def confidence_to_state(conf, tracked: float = LiveConfig.tracked_confidence,
                        inferred: float = LiveConfig.inferred_confidence) -> np.ndarray:
    c = np.asarray(conf, dtype=float)
    out = np.full(c.shape, NOT_TRACKED, np.uint8)
    out[c > inferred] = INFERRED
    out[c >= tracked] = TRACKED
    return out


def _unit(v: np.ndarray) -> Optional[np.ndarray]:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-6 else None


def nite_to_frame(points_mm, confidences, user_id: int, stamp_ns: int, frame_id: str,
                  tracked: float = LiveConfig.tracked_confidence,
                  inferred: float = LiveConfig.inferred_confidence) -> SkeletonFrame:
    """15 NiTE joints (nite::JointType order, camera mm) -> a 20-joint :class:`SkeletonFrame`."""
    nite = camera_mm_to_rep103(points_mm)
    if nite.shape != (len(NITE_TO_KINECT), 3):
        raise ValueError(f'expected {len(NITE_TO_KINECT)} NiTE joints, got {nite.shape}')
    pos = np.zeros((NUM_JOINTS, 3))
    state = np.full(NUM_JOINTS, NOT_TRACKED, np.uint8)
    idx = list(NITE_TO_KINECT)
    pos[idx] = nite
    state[idx] = confidence_to_state(confidences, tracked, inferred)
    # HipCenter: between the hips
    pos[HIP_CENTER] = 0.5 * (pos[HIP_LEFT] + pos[HIP_RIGHT])
    if state[HIP_LEFT] >= INFERRED and state[HIP_RIGHT] >= INFERRED:
        state[HIP_CENTER] = INFERRED
    rest = standard_body().rest_offsets
    # Hands: wrist + hand offset along the forearm
    for hand, wrist, elbow in ((HAND_LEFT, WRIST_LEFT, ELBOW_LEFT),
                               (HAND_RIGHT, WRIST_RIGHT, ELBOW_RIGHT)):
        d = _unit(pos[wrist] - pos[elbow])
        pos[hand] = pos[wrist] + (0.0 if d is None else np.linalg.norm(rest[hand]) * d)
    # Feet: ankle + the rest-pose ankle->foot offset in the body frame (forward, left, up)
    up = _unit(pos[SHOULDER_CENTER] - pos[HIP_CENTER])
    left = pos[HIP_LEFT] - pos[HIP_RIGHT]
    body = None
    if up is not None:
        left = _unit(left - np.dot(left, up) * up)
        if left is not None:
            body = np.column_stack([np.cross(left, up), left, up])
    for foot, ankle in ((FOOT_LEFT, ANKLE_LEFT), (FOOT_RIGHT, ANKLE_RIGHT)):
        pos[foot] = pos[ankle] + (0.0 if body is None else body @ rest[foot])
    return SkeletonFrame(positions=pos, tracking_state=state, user_id=int(user_id),
                         stamp_ns=int(stamp_ns), frame_id=frame_id)


# --------------------------------------------------------------------------------------------
# Library loading
# --------------------------------------------------------------------------------------------
def _lib_dirs(openni2_path: str) -> List[str]:
    if openni2_path:
        return [openni2_path]
    dirs = [os.environ.get('OPENNI2_REDIST64', ''), os.environ.get('OPENNI2_REDIST', '')]
    multiarch = sysconfig.get_config_var('MULTIARCH') or 'x86_64-linux-gnu'
    dirs += [f'/usr/lib/{multiarch}', f'/lib/{multiarch}', '/usr/lib', '/usr/local/lib', '/lib',
             '/lib64']
    return [d for d in dirs if d]


def find_openni2_library(openni2_path: str = '') -> Optional[str]:
    """Full path of libOpenNI2.so(.0) in ``openni2_path`` or the system library directories."""
    for d in _lib_dirs(openni2_path):
        for name in ('libOpenNI2.so', 'libOpenNI2.so.0'):
            f = os.path.join(d, name)
            if os.path.isfile(f):
                return f
    return None


def load_openni2(openni2_path: str = ''):
    """Import the bindings and initialize OpenNI2; returns the ``openni2`` module."""
    try:
        from openni import _openni2, openni2
    except ImportError:
        raise SourceError('OpenNI2 Python bindings not installed (pip install openni==2.3.0)'
                          ) from None
    if openni2.is_initialized():
        return openni2
    lib = find_openni2_library(openni2_path)
    if lib is None:
        where = f' in {openni2_path}' if openni2_path else ''
        raise SourceError(f'OpenNI2 library not found{where} ({APT_HINT})')
    try:
        if not openni2.loaded_dll_directory:
            # the bindings look for an unversioned libOpenNI2.so; Debian ships libOpenNI2.so.0
            _openni2.load_dll(lib)
            openni2.loaded_dll_directory = os.path.dirname(lib)
        openni2.initialize()
    except Exception as e:  # noqa: BLE001 - library-level failure: one line
        raise SourceError(f'OpenNI2 library {lib} failed to initialize: {_one_line(e)}') from None
    return openni2


def _one_line(e: BaseException) -> str:
    args = getattr(e, 'args', ())
    parts = [a.decode(errors='replace') if isinstance(a, bytes) else str(a) for a in args if a]
    text = ' '.join(parts) or type(e).__name__
    return ' '.join(text.split())


def open_device(openni2, device_uri: str):
    if device_uri.lower().endswith('.oni'):
        p = Path(device_uri).expanduser()
        if not p.is_file() or not os.access(p, os.R_OK):
            raise SourceError(f'cannot read OpenNI recording {p}: no such file or not readable')
        try:
            return openni2.Device.open_file(str(p).encode())
        except Exception as e:  # noqa: BLE001
            raise SourceError(f'cannot open OpenNI recording {p}: {_one_line(e)}') from None
    try:
        if device_uri:
            return openni2.Device(device_uri.encode())
        return openni2.Device.open_any()
    except Exception as e:  # noqa: BLE001
        try:
            found = [u.uri.decode(errors='replace') for u in openni2.Device.enumerate_uris()]
        except Exception:  # noqa: BLE001
            found = []
        what = f'at URI {device_uri!r}' if device_uri else 'connected'
        listing = f'; devices present: {", ".join(found)}' if found else ''
        raise SourceError(f'no device: no OpenNI2 depth sensor {what} (is it plugged in and '
                          f'powered? Kinect v1 needs the libfreenect OpenNI2 driver){listing} '
                          f'[{_one_line(e)}]', retryable=True) from None


def load_nite2(nite2_path: str):
    if not nite2_path:
        raise SourceError('NiTE2 not found: set nite2_path to the NiTE2 Redist directory '
                          '(the one holding libNiTE2.so)')
    p = Path(nite2_path).expanduser()
    lib = p / 'libNiTE2.so'
    if not lib.is_file():
        raise SourceError(f'NiTE2 not found at {p} (no libNiTE2.so there; nite2_path must be '
                          f'the NiTE2 Redist directory)')
    from openni import nite2
    if nite2.is_initialized():
        return nite2
    try:
        nite2.initialize(str(p))
    except Exception as e:  # noqa: BLE001
        raise SourceError(f'NiTE2 at {p} failed to initialize: {_one_line(e)}') from None
    return nite2


# --------------------------------------------------------------------------------------------
# The source
# --------------------------------------------------------------------------------------------
class LiveSource(Source):
    name = 'live'
    tracker = 'nite2'
    config_class = LiveConfig

    def __init__(self, config: Optional[LiveConfig] = None, frame_id: str = 'kinect_link',
                 clock_ns: Callable[[], int] = time.time_ns,
                 log: Optional[Callable[[str], None]] = None, **params):
        cfg = replace(config or LiveConfig(), **params)
        self.config = cfg
        self.device_uri = cfg.device_uri
        self.nite2_path = cfg.nite2_path
        self.openni2_path = cfg.openni2_path
        self.frame_id = frame_id
        self.max_users = int(cfg.max_users)
        self.tracked_confidence = float(cfg.tracked_confidence)
        self.inferred_confidence = float(cfg.inferred_confidence)
        self.retry_s = float(cfg.retry_s)
        self.smoothing = float(cfg.smoothing)
        self.clock_ns = clock_ns
        self.log = log or (lambda m: print(f'[WARN] {m}', file=sys.stderr))
        self._queue: collections.deque = collections.deque(maxlen=10)
        self._device = None
        self._tracker = None
        self._thread: Optional[threading.Thread] = None
        self._stop = threading.Event()
        self.connected = False
        self.reconnects = 0
        self.frames_read = 0
        self.last_frame_ns = 0

    @classmethod
    def from_config(cls, config, frame_id, log=None, clock_ns=None) -> 'LiveSource':
        kw = {} if clock_ns is None else {'clock_ns': clock_ns}
        return cls(config=config, frame_id=frame_id, log=log, **kw)

    # -- connection -----------------------------------------------------------------------
    def connect(self) -> None:
        """Load the libraries, open the device and start the user tracker (or raise)."""
        openni2 = load_openni2(self.openni2_path)
        device = open_device(openni2, self.device_uri)
        try:
            nite2 = load_nite2(self.nite2_path)
            cwd = os.getcwd()
            try:
                os.chdir(os.path.expanduser(self.nite2_path))  # NiTE reads NiTE.ini / NiTE2/ here
                tracker = nite2.UserTracker(device)
            finally:
                os.chdir(cwd)
            if self.smoothing > 0:
                tracker.skeleton_smoothing_factor = self.smoothing
        except SourceError:
            device.close()
            raise
        except Exception as e:  # noqa: BLE001
            device.close()
            raise SourceError(f'NiTE2 user tracker could not start on the device: '
                              f'{_one_line(e)}') from None
        self._device, self._tracker = device, tracker
        self.connected = True

    def disconnect(self) -> None:
        self.connected = False
        for h in (self._tracker, self._device):
            try:
                if h is not None:
                    h.close()
            except Exception:  # noqa: BLE001
                pass
        self._tracker = self._device = None

    def open(self) -> None:
        """Connect (errors propagate; ``retryable`` ones the node may retry), then read frames in
        a background thread."""
        self.connect()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name='nite2-reader', daemon=True)
        self._thread.start()

    # -- reading --------------------------------------------------------------------------
    def read_once(self) -> List[SkeletonFrame]:
        frame = self._tracker.read_frame()
        stamp = self.clock_ns()
        from openni import nite2
        out = []
        for user in frame.users:
            if user.is_new():
                self._tracker.start_skeleton_tracking(user.id)
            if int(user.skeleton.state) != int(nite2.SkeletonState.NITE_SKELETON_TRACKED):
                continue
            joints = user.skeleton.joints
            pts = [(joints[k].position.x, joints[k].position.y, joints[k].position.z)
                   for k in range(len(NITE_TO_KINECT))]
            conf = [joints[k].positionConfidence for k in range(len(NITE_TO_KINECT))]
            out.append(nite_to_frame(pts, conf, int(user.id), stamp, self.frame_id,
                                     self.tracked_confidence, self.inferred_confidence))
            if len(out) >= self.max_users:
                break
        frame.close()
        self.frames_read += 1
        self.last_frame_ns = stamp
        self._queue.append(SourceOutput(stamp_ns=stamp, frames=out, frame_id=self.frame_id))
        return out

    def _run(self) -> None:
        retry = self.retry_s if self.retry_s > 0 else 1.0
        while not self._stop.is_set():
            if not self.connected:
                try:
                    self.connect()
                    self.reconnects += 1
                    self.log('device reconnected')
                except SourceError as e:
                    self.log(f'{e} - retrying in {retry:g} s')
                    self._stop.wait(retry)
                continue
            try:
                self.read_once()
            except Exception as e:  # noqa: BLE001 - device gone: keep running, reconnect
                self.log(f'device disconnected or stopped sending frames ({_one_line(e)}); '
                         f'reconnecting every {retry:g} s')
                self.disconnect()
                self._stop.wait(retry)

    def poll(self, now_ns: int) -> List[SourceOutput]:
        out = []
        while self._queue:
            out.append(self._queue.popleft())
        return out

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self.disconnect()

    def status(self) -> dict:
        return {'connected': self.connected, 'frames_read': self.frames_read,
                'reconnects': self.reconnects, 'device_uri': self.device_uri or '(any)'}
