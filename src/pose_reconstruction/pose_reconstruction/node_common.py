"""What the three reconstruction nodes share: SkeletonArray in -> per-user processing ->
SkeletonArray out, per-user state with a timeout, stamp checks, Health, diagnostics and
run-time-changeable, validated parameters.

A node subclass gives its parameter specs and ``make_processor(params) -> object`` with
``process(frame) -> frame`` and ``reset()``; one processor is kept per user id and rebuilt (state
dropped) when a parameter changes. A node with several outputs (``outputs``: the parameter names of
their topics, the first one primary) gets ``process(frame, wanted) -> tuple`` of one frame (or None)
per output instead: ``wanted[i]`` says whether output i has subscribers (the primary output always
counts as wanted), so work nobody consumes can be skipped.
"""
from __future__ import annotations

import threading
import time
from typing import Any, Callable, Dict, List, Optional, Sequence

from rclpy.node import Node
from rclpy.qos import QoSProfile

from skeleton_core.cdr import CdrError, frames_from_cdr, frames_to_cdr
from skeleton_core.conversions import SkeletonFormatError, frame_from_arrays
from skeleton_core.health import Health
from skeleton_core.params import ParamSpec, build, hidden, specs
from skeleton_core.rosnode import DiagnosticsPublisher, InputDrops, Parameters

from .correction import CorrectionConfig
from .reliability import ReliabilityConfig

# Reliability parameters (Shum et al. 2013 Sec. IV, declared on ReliabilityConfig), shared by every
# node that may estimate it
RELIABILITY_SPECS = specs(ReliabilityConfig)
RELIABILITY_NAMES = [s.name for s in RELIABILITY_SPECS]
DATABASE_SPEC = ParamSpec('database', '', "motion database file ('' = built-in / CMU default)")

# Learned sensor correction and user profile (pose_reconstruction.correction / .profile)
CORRECTION_SPECS = specs(CorrectionConfig)
CORRECTION_NAMES = [s.name for s in CORRECTION_SPECS]


def common_specs(input_topic: str, output_topic: str) -> List[ParamSpec]:
    return [
        ParamSpec('input_topic', input_topic, 'SkeletonArray input topic', read_only=True),
        ParamSpec('output_topic', output_topic, 'SkeletonArray output topic', read_only=True),
        # fixed: the queue depth and the bag-loop time jump are not what a lab tunes
        hidden(ParamSpec('qos_depth', 10, 'publisher/subscription queue depth', (1, 1000),
                         read_only=True)),
        ParamSpec('user_timeout_s', 2.0, "drop a user's state after this long unseen (s)",
                  (0.05, 3600.0)),
        hidden(ParamSpec('time_jump_reset_s', 1.0,
                         'a stamp this far back in time (s) restarts every user (bag loop); '
                         'smaller backward steps are dropped as out of order', (0.0, 3600.0))),
    ]


def check_reliability_params(values: Dict[str, Any]) -> Optional[str]:
    """The cross-parameter checks of ReliabilityConfig (an error text or None)."""
    try:
        build(ReliabilityConfig, values).validate()
    except ValueError as e:
        return str(e)
    return None


class SkeletonArrayNode(Node):
    """Base class (see module docstring)."""

    def __init__(self, name: str, specs: List[ParamSpec], outputs: Sequence[str] = ('output_topic',),
                 **kwargs):
        super().__init__(name, **kwargs)
        self._lock = threading.RLock()
        self.health = Health()
        self._drop = InputDrops(self.health, self.get_logger())
        self._users: Dict[int, Any] = {}
        self._last_seen: Dict[int, float] = {}
        self._last_stamp_ns: Optional[int] = None
        self.params = Parameters(self, specs, on_change=self._on_params)
        err = self.validate(dict(self.params.values))
        if err:
            raise ValueError(f'invalid parameter: {err}')
        self.setup()
        from skeleton_msgs.msg import SkeletonArray
        depth = self.params['qos_depth']
        self._multi = len(outputs) > 1
        self._pubs = [self.create_publisher(SkeletonArray, self.params[o], QoSProfile(depth=depth))
                      for o in outputs]
        # serialized in and out (skeleton_core.cdr): no rclpy message objects per joint
        self._sub = self.create_subscription(SkeletonArray, self.params['input_topic'],
                                             self._on_msg, QoSProfile(depth=depth), raw=True)
        self._timer = self.create_timer(0.5, self._purge)
        self.diagnostics = DiagnosticsPublisher(self, self.health, extra=self.diagnostics_extra)
        self.get_logger().info(f"{self.params['input_topic']} -> "
                               + ', '.join(p.topic_name for p in self._pubs))

    # -- hooks -----------------------------------------------------------------------------------
    def setup(self) -> None:
        """Called once after parameters are declared (load databases here)."""

    def validate(self, values: Dict[str, Any]) -> Optional[str]:
        """Cross-parameter checks; return an error text or None."""
        return None

    def make_processor(self, values: Dict[str, Any]):
        raise NotImplementedError

    def apply_params(self, values: Dict[str, Any], changed: Dict[str, Any]) -> Optional[str]:
        """React to a validated change (e.g. reload a database); return an error text or None."""
        return None

    def diagnostics_extra(self) -> Dict[str, Any]:
        with self._lock:
            return {'users': len(self._users),
                    'user_states': len(set(self._users) | set(self._last_seen))}

    # -- internals -------------------------------------------------------------------------------
    def _on_params(self, changed: Dict[str, Any]) -> Optional[str]:
        values = dict(self.params.values)
        values.update(changed)
        err = self.validate(values)
        if err:
            return err
        with self._lock:
            err = self.apply_params(values, changed)
            if err:
                return err
            try:
                self.make_processor(values)  # refuse values the library rejects
            except (ValueError, TypeError) as e:
                return str(e)
            self._users.clear()  # rebuilt with the new values on the next message
        return None

    def _purge(self) -> None:
        now = time.monotonic()
        timeout = self.params['user_timeout_s']
        with self._lock:
            for uid in [u for u, t in self._last_seen.items() if now - t > timeout]:
                self._users.pop(uid, None)
                self._last_seen.pop(uid, None)

    def _on_msg(self, data: bytes) -> None:
        t0 = time.monotonic()
        self.health.on_receive()
        errors: List[SkeletonFormatError] = []
        try:
            stamp, frame_id, frames = frames_from_cdr(data, errors)
        except CdrError as e:  # undecodable: a dropped message, not a crash
            self._drop('malformed message', str(e))
            return
        with self._lock:
            if stamp != 0 and self._last_stamp_ns is not None and stamp <= self._last_stamp_ns:
                back = (self._last_stamp_ns - stamp) * 1e-9
                if stamp == self._last_stamp_ns:
                    self._drop('duplicate stamp')
                    return
                if back <= self.params['time_jump_reset_s']:
                    self._drop('out-of-order stamp', f'{back * 1e3:.1f} ms back in time')
                    return
                self.get_logger().info(f'time jumped back {back:.2f} s: restarting every user')
                self._users.clear()
                self._last_seen.clear()
            if stamp != 0:
                self._last_stamp_ns = stamp
            for e in errors:
                self._drop(e.cause, e.detail)
            # the primary output always; the others only while someone subscribes
            wanted = (True,) + tuple(p.get_subscription_count() > 0 for p in self._pubs[1:])
            results: List[List] = [[] for _ in self._pubs]
            self._purge()
            for f in frames:
                proc = self._users.get(f.user_id)
                if proc is None:
                    proc = self._users[f.user_id] = self.make_processor(dict(self.params.values))
                self._last_seen[f.user_id] = time.monotonic()
                if f.stamp_ns == 0:
                    f.stamp_ns = stamp
                try:
                    outs = proc.process(f, wanted) if self._multi else (proc.process(f),)
                    # every result checked before any is kept; the checked arrays are what
                    # gets serialized (frames_to_cdr(validated=True) does not check again)
                    checked = [None if res is None else frame_from_arrays(
                        res.positions, res.tracking_state, res.reliability, res.orientations,
                        res.user_id, res.stamp_ns, res.frame_id) for res in outs]
                    for i, res in enumerate(checked):
                        if res is not None:
                            results[i].append(res)
                except SkeletonFormatError as e:
                    self._drop('bad result: ' + e.cause, e.detail)
                except (ValueError, FloatingPointError, ArithmeticError, IndexError) as e:
                    self._drop('processing error', f'{type(e).__name__}: {e}')
                    proc.reset()
        for pub, want, res in zip(self._pubs, wanted, results):
            if want:
                pub.publish(frames_to_cdr(res, stamp, frame_id, validated=True))
        self.health.on_publish(latency_s=time.monotonic() - t0)


class DatabaseNode(SkeletonArrayNode):
    """A :class:`SkeletonArrayNode` holding the motion database named by its ``database``
    parameter (``self.db``), reloaded when the parameter changes (a missing or corrupt file is a
    refused change). ``database_obj`` (tests) stands in for the default database."""

    def __init__(self, name: str, specs: List[ParamSpec], database_obj=None, **kwargs):
        self._database_obj = database_obj
        super().__init__(name, specs, **kwargs)

    def setup(self) -> None:
        self._load(self.params['database'])
        self.user_terms: Dict[str, Any] = {}
        if 'sensor_correction' in self.params.values:
            self.user_terms = load_user_terms(dict(self.params.values), self.get_logger())

    def _load(self, path: str) -> None:
        from .posture_space import as_database_arrays
        db = self._database_obj if (self._database_obj is not None and not path) else \
            load_database(path)
        self.db = as_database_arrays(db)
        self.get_logger().info(f'motion database: {self.db.size} postures')

    def apply_params(self, values: Dict[str, Any], changed: Dict[str, Any]) -> Optional[str]:
        if 'database' in changed:
            try:
                self._load(changed['database'])
            except (FileNotFoundError, ValueError, RuntimeError) as e:
                return str(e)
        if any(k in changed for k in CORRECTION_NAMES):
            try:
                self.user_terms = load_user_terms(values, self.get_logger())
            except (FileNotFoundError, ValueError, RuntimeError) as e:
                return str(e)
        return None


def load_user_terms(values: Dict[str, Any], logger=None) -> Dict[str, Any]:
    """The Reconstructor keywords of the correction / profile parameters: ``correction`` (None
    when off or refused: another or an undeclared tracker, logged in one line),
    ``correction_stage``, ``input_tracker``, ``profile``. A named file that is missing or
    malformed raises ValueError with one line."""
    from . import correction as C
    from . import profile as P
    info = logger.info if logger is not None else (lambda m: None)
    warn = logger.warning if logger is not None else (lambda m: None)
    name = values.get('sensor_correction', '')
    tracker = values.get('input_tracker', '')
    corr = None
    if name == 'auto':
        if tracker != C.UIPRMD_TRACKER:
            info(f'sensor correction off: the default correction is learned from '
                 f'{C.UIPRMD_TRACKER} skeletons and the input tracker is '
                 f'{tracker or "not declared"} (input_tracker)')
        else:
            try:
                corr = C.load_or_build_default(log=info)
            except (ValueError, OSError) as e:
                warn(f'sensor correction off: cannot build the default one ({e})')
            if corr is None:
                info('sensor correction off: no paired recordings under <shared>/kinect/ui-prmd '
                     f'and no {C.default_path()}')
    elif name:
        corr = C.load(name)  # CorrectionFileError (a ValueError): one line
    if corr is not None:
        try:
            C.check_tracker(corr, tracker)
            info(f'{C.describe_file(corr)}: applied at stage {values.get("correction_stage")}')
        except C.TrackerMismatch as e:
            warn(str(e))
            corr = None
    prof = None
    if values.get('user_profile'):
        prof = P.load_by_name(values['user_profile'], values.get('profiles_dir') or None)
        info(f'user profile {prof.name!r}: segment lengths from {prof.frames} frames')
    return {'correction': corr, 'correction_stage': values.get('correction_stage', 'input'),
            'input_tracker': tracker, 'profile': prof}


def load_database(path: str, loader: Optional[Callable[[], Any]] = None):
    """The motion database named by the ``database`` parameter ('' = built-in / CMU default).

    Raises FileNotFoundError / ValueError with one clear line (run_node prints it and exits 1).
    """
    if loader is not None:
        return loader()
    try:
        from skeleton_data import database as dbmod
    except ImportError as e:  # pragma: no cover - the library ships with the workspace
        raise RuntimeError(f'skeleton_data.database is not available: {e}') from e
    if not path:
        try:
            return dbmod.load_or_build_default()
        except (FileNotFoundError, ValueError, RuntimeError):
            raise
        except Exception as e:  # noqa: BLE001
            raise ValueError(f'cannot build the default motion database: {e}') from e
    from pathlib import Path
    p = Path(path).expanduser()
    if not p.is_file():
        raise FileNotFoundError(f'motion database {str(p)!r} does not exist')
    try:
        return dbmod.MotionDatabase.load(str(p))
    except (FileNotFoundError, ValueError, RuntimeError):
        raise
    except Exception as e:  # noqa: BLE001 - corrupt file: one clear line
        raise ValueError(f'motion database {str(p)!r} cannot be read: {type(e).__name__}: {e}') from e
