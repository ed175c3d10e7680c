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

from rclpy.qos import QoSProfile

from skeleton_core.cdr import CdrError, frames_from_cdr, frames_to_cdr
from skeleton_core.conversions import SkeletonFormatError, frame_from_arrays
from skeleton_core.params import ParamSpec, build, hidden, specs
from skeleton_core.rosnode import InputDrops, ManagedNode, Parameters

from .bone_lengths import lengths_text
from .correction import CorrectionConfig
from .reliability import ReliabilityConfig

# Reliability parameters (Shum et al. 2013 Sec. IV, declared on ReliabilityConfig), shared by every
# node that may estimate it
RELIABILITY_SPECS = specs(ReliabilityConfig)
RELIABILITY_NAMES = [s.name for s in RELIABILITY_SPECS]
DATABASE_SPEC = ParamSpec('database', '', "motion database file ('' = the default one that "
                          '`make build-db` writes: cache/motion_db.npz)')

# Learned sensor correction and user profile (pose_reconstruction.correction / .profile)
CORRECTION_SPECS = specs(CorrectionConfig)
CORRECTION_NAMES = [s.name for s in CORRECTION_SPECS]


OUTPUT_MATCH_WAIT_S = 3.0   # then the input is taken anyway (with a warning naming the outputs)


def tracker_qos():
    """Latched QoS of /kinect/tracker (skeleton_core.tracker): a late joiner still gets it."""
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
    return QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                      reliability=ReliabilityPolicy.RELIABLE)


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


class SkeletonArrayNode(ManagedNode):
    """Base class (see module docstring)."""

    def __init__(self, name: str, specs: List[ParamSpec], outputs: Sequence[str] = ('output_topic',),
                 **kwargs):
        super().__init__(name, **kwargs)
        self._lock = threading.RLock()
        self._drop = InputDrops(self.health, self.get_logger())
        self._users: Dict[int, Any] = {}
        self._last_seen: Dict[int, float] = {}
        self._last_stamp_ns: Optional[int] = None
        self._outputs = tuple(outputs)
        self._multi = len(outputs) > 1
        self._pubs: list = []
        self.params = Parameters(self, specs, validate=self._validate_change,
                                 apply=self._apply_change)
        err = self.validate(dict(self.params.values))
        if err:
            raise ValueError(f'invalid parameter: {err}')

    # -- lifecycle -------------------------------------------------------------------------------
    def configure(self) -> None:
        self.setup()
        from skeleton_msgs.msg import SkeletonArray
        depth = self.params['qos_depth']
        self._pubs = [self.publisher(SkeletonArray, self.params[o], QoSProfile(depth=depth))
                      for o in self._outputs]
        # the compiled kernels loaded now, not on the first frame: loading them from numba's
        # cache takes 0.5-0.7 s on a quiet 2-core machine, seconds under load, and a node that
        # stalls on its first frame loses the frames behind it (a depth-10 queue holds 1/3 s).
        # After the publishers: DDS matches them with their subscribers meanwhile
        warm_s = sum(warm() for warm in self.kernels())
        if warm_s > 0.5:
            self.get_logger().info(f'compiled kernels ready in {warm_s:.1f} s (cached from now on)')
        self.diagnostics(extra=self.diagnostics_extra)

    def activate(self) -> None:
        self.timer(0.5, self._purge)
        # the input is taken only once every output reaches the subscribers the graph already
        # knows (at most OUTPUT_MATCH_WAIT_S): a subscriber this node's publisher has not met yet
        # would miss the outputs of the first frames (a replay starts once the input has its
        # readers), e.g. a recorder started before this node
        self.when_ready(self._unmatched_outputs, self._subscribe_input, OUTPUT_MATCH_WAIT_S,
                        'not every subscriber reached; taking the input anyway')

    def _unmatched_outputs(self) -> List[str]:
        return [p.topic_name for p in self._pubs
                if p.get_subscription_count() < self.count_subscribers(p.topic_name)]

    def _subscribe_input(self) -> None:
        from rclpy.qos_overriding_options import QoSOverridingOptions
        from skeleton_msgs.msg import SkeletonArray
        # serialized in and out (skeleton_core.cdr): no rclpy message objects per joint. The
        # queue's depth may be overridden the ROS way (qos_overrides.<topic>.subscription.depth):
        # the launch files queue a replayed recording (kinect_bringup.graph.replay_overrides)
        self.subscription(SkeletonArray, self.params['input_topic'], self._on_msg,
                          QoSProfile(depth=self.params['qos_depth']), raw=True, watch=True,
                          qos_overriding_options=QoSOverridingOptions.with_default_policies())
        self.get_logger().info(f"{self.params['input_topic']} -> "
                               + ', '.join(p.topic_name for p in self._pubs))

    def deactivate(self) -> None:
        with self._lock:   # a restart begins with every user anew
            self._users.clear()
            self._last_seen.clear()
            self._last_stamp_ns = None

    def cleanup(self) -> None:
        self._pubs = []
        self.teardown()

    # -- hooks -----------------------------------------------------------------------------------
    def setup(self) -> None:
        """Called on configure (load the files named by the parameters here)."""

    def teardown(self) -> None:
        """Called on cleanup: release what :meth:`setup` loaded."""

    def kernels(self) -> List[Callable[[], float]]:
        """The ``warm_up`` functions of the compiled kernels this node's processing calls
        (run on configure; each returns the seconds it took)."""
        return []

    def validate(self, values: Dict[str, Any]) -> Optional[str]:
        """Cross-parameter checks; return an error text or None."""
        return None

    def make_processor(self, values: Dict[str, Any]):
        raise NotImplementedError

    def check_change(self, values: Dict[str, Any], changed: Dict[str, Any]) -> Optional[str]:
        """Validate a change before it is accepted (no side effects); an error text or None."""
        return None

    def apply_params(self, values: Dict[str, Any], changed: Dict[str, Any]) -> None:
        """Make an accepted change take effect (e.g. reload a database)."""

    def diagnostics_extra(self) -> Dict[str, Any]:
        with self._lock:
            return {'users': len(self._users),
                    'user_states': len(set(self._users) | set(self._last_seen))}

    # -- internals -------------------------------------------------------------------------------
    def _validate_change(self, values: Dict[str, Any], changed: Dict[str, Any]) -> Optional[str]:
        err = self.validate(values) or self.check_change(values, changed)
        if err:
            return err
        if self.lifecycle_state != 'unconfigured':
            try:
                self.make_processor(values)  # refuse values the library rejects
            except (ValueError, TypeError) as e:
                return str(e)
        return None

    def _apply_change(self, changed: Dict[str, Any]) -> None:
        if self.lifecycle_state == 'unconfigured':
            return   # configure reads the values
        with self._lock:
            self.apply_params(dict(self.params.values), changed)
            self._users.clear()  # rebuilt with the new values on the next message

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
        # a subscriber that appeared since activation is reached before this frame's output
        self.reach_subscribers(self._pubs)
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
            procs = []
            for f in frames:
                proc = self._users.get(f.user_id)
                if proc is None:
                    proc = self._users[f.user_id] = self.make_processor(dict(self.params.values))
                self._last_seen[f.user_id] = time.monotonic()
                if f.stamp_ns == 0:
                    f.stamp_ns = stamp
                procs.append(proc)
            # a processor that handles a message's users together (the reconstruction: their
            # optimizer runs batched) gets them at once: per user a tuple or its exception
            batch = getattr(type(procs[0]), 'process_batch', None) if (
                self._multi and len(procs) > 1
                and all(type(p) is type(procs[0]) for p in procs)) else None
            batched = batch(procs, frames, wanted) if batch is not None else None
            for k, (f, proc) in enumerate(zip(frames, procs)):
                try:
                    if batched is not None:
                        outs = batched[k]
                        if isinstance(outs, Exception):
                            raise outs
                    else:
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
    parameter (``self.db``), loaded on configure and reloaded when the parameter changes (a
    missing file is a refused change; a corrupt one is logged, the old database kept).
    ``database_obj`` (tests) stands in for the default database."""

    def __init__(self, name: str, specs: List[ParamSpec], database_obj=None, **kwargs):
        self._database_obj = database_obj
        self.db = None
        self.user_terms: Dict[str, Any] = {}
        super().__init__(name, specs, **kwargs)

    def diagnostics_extra(self) -> Dict[str, Any]:
        """Adds each user's bone lengths (methods B and C: the constant lengths every output
        posture has, ``user_<id>_bone_lengths_m``; 'estimating' until frozen) and how often they
        were estimated again for another person under the same id."""
        extra = super().diagnostics_extra()
        with self._lock:
            users = list(self._users.items())
        for uid, proc in users:
            if not getattr(proc, 'rigid_output', False):
                continue   # method A, the blend output, the reliability alone
            extra[f'user_{uid}_bone_lengths_m'] = lengths_text(proc.bone_lengths)
            extra[f'user_{uid}_bone_length_restarts'] = int(proc.bone_length_restarts)
        return extra

    def setup(self) -> None:
        self._load(self.params['database'])
        self.stream_tracker = ''
        if 'sensor_correction' in self.params.values:
            self.user_terms = load_user_terms(dict(self.params.values), self.get_logger())
            # the tracker the stream declares (skeleton_core.tracker): latched, read once
            from std_msgs.msg import String
            from skeleton_core import tracker as T
            # (from configure on: the correction follows it before the input starts; released
            # on cleanup)
            sub = self.create_subscription(String, T.TOPIC, self._on_tracker, tracker_qos())
            self._configured.append(('subscription', sub))

    def _on_tracker(self, msg) -> None:
        """The stream's tracker: used when input_tracker is not set (an explicit one wins)."""
        name = msg.data.strip()
        if name == self.stream_tracker:
            return
        self.get_logger().info(f'the input stream declares skeleton tracker {name!r} '
                               f'(/kinect/tracker)')
        with self._lock:
            self.stream_tracker = name
            if self.params['input_tracker']:
                return
            try:
                self.user_terms = load_user_terms(
                    {**self.params.values, 'stream_tracker': name}, self.get_logger())
            except (FileNotFoundError, ValueError, RuntimeError) as e:
                self.get_logger().error(f'sensor correction off: {e}')
                self.user_terms = {**self.user_terms, 'correction': None}
            self._users.clear()   # rebuilt with the correction on the next message

    def teardown(self) -> None:
        self.db = None
        self.user_terms = {}

    def _load(self, path: str) -> None:
        from .posture_space import as_database_arrays
        db = self._database_obj if (self._database_obj is not None and not path) else \
            load_database(path)
        self.db = as_database_arrays(db)
        self.get_logger().info(f'motion database: {self.db.size} postures')

    def check_change(self, values: Dict[str, Any], changed: Dict[str, Any]) -> Optional[str]:
        if 'database' in changed and not (self._database_obj is not None
                                          and not changed['database']):
            p = database_path(changed['database'])
            if not p.is_file():
                return missing_database(p)
        if any(k in changed for k in CORRECTION_NAMES):
            return check_user_files(values)
        return None

    def apply_params(self, values: Dict[str, Any], changed: Dict[str, Any]) -> None:
        try:
            if 'database' in changed:
                self._load(changed['database'])
            if any(k in changed for k in CORRECTION_NAMES):
                self.user_terms = load_user_terms({**values, 'stream_tracker': self.stream_tracker},
                                                  self.get_logger())
        except (FileNotFoundError, ValueError, RuntimeError, OSError) as e:
            self.get_logger().error(f'{e} (the previous one stays in use)')


BUILD_DB = 'make build-db'
BUILD_CORRECTION = 'make build-correction'


def database_path(path: str):
    """The file the ``database`` parameter names: '' = the default that ``make build-db``
    writes (:func:`skeleton_data.database.default_path`)."""
    from pathlib import Path

    from skeleton_data.database import default_path
    return Path(path).expanduser() if path else default_path()


def missing_database(p) -> str:
    return (f'motion database {str(p)!r} does not exist: build it with `{BUILD_DB}` '
            f'(or name another file: database:=FILE)')


def check_user_files(values: Dict[str, Any]) -> Optional[str]:
    """The correction / profile files the parameters name exist (no file is read)."""
    from . import correction as C
    from . import profile as P
    name = values.get('sensor_correction', '')
    tracker = values.get('input_tracker', '')
    if name == 'auto' and tracker == C.UIPRMD_TRACKER and not C.default_path().is_file():
        return missing_correction(C.default_path())
    if name and name != 'auto':
        from pathlib import Path
        if not Path(name).expanduser().is_file():
            return f'sensor correction {name!r} does not exist'
    if values.get('user_profile'):
        try:
            path = P.profile_path(values['user_profile'], values.get('profiles_dir') or None)
        except ValueError as e:
            return str(e)
        if not path.is_file():
            return (f'user profile {str(path)!r} does not exist: build it with '
                    f'`ros2 run pose_reconstruction build_profile --name {values["user_profile"]}`')
    return None


def missing_correction(p) -> str:
    return (f'sensor correction {str(p)!r} does not exist: build it with '
            f'`{BUILD_CORRECTION}` (or sensor_correction:=\'\' for none)')


def load_user_terms(values: Dict[str, Any], logger=None) -> Dict[str, Any]:
    """The Reconstructor keywords of the correction / profile parameters: ``correction`` (None
    when off or refused: another or an undeclared tracker, logged in one line; the tracker is
    ``input_tracker``, else ``stream_tracker``: the one the stream declares on /kinect/tracker),
    ``correction_stage``, ``input_tracker``, ``profile``, ``length_noise`` (the sensor's segment
    length noise, shared by the node's users: :class:`.bone_lengths.SensorLengthNoise`). Files are loaded by path, never
    built: a named file (or the default correction that applies to the input) that is missing
    or malformed raises FileNotFoundError / ValueError with one line naming the command that
    builds it."""
    from . import correction as C
    from . import profile as P
    info = logger.info if logger is not None else (lambda m: None)
    warn = logger.warning if logger is not None else (lambda m: None)
    tracker = values.get('input_tracker', '') or values.get('stream_tracker', '')
    corr = C.select(values.get('sensor_correction', ''), tracker, log=info, warn=warn)
    if corr is not None:
        info(f'{C.describe_file(corr)}: applied at stage {values.get("correction_stage")}')
    prof = None
    if values.get('user_profile'):
        prof = P.load_by_name(values['user_profile'], values.get('profiles_dir') or None)
        info(f'user profile {prof.name!r}: segment lengths from {prof.frames} frames')
    from .bone_lengths import SensorLengthNoise
    return {'correction': corr, 'correction_stage': values.get('correction_stage', 'input'),
            'input_tracker': tracker, 'profile': prof, 'length_noise': SensorLengthNoise()}


def load_database(path: str, loader: Optional[Callable[[], Any]] = None):
    """The motion database named by the ``database`` parameter ('' = the default file that
    ``make build-db`` writes). Loaded, never built: a missing or unreadable file raises
    FileNotFoundError / ValueError with one line naming the command that builds it."""
    if loader is not None:
        return loader()
    from skeleton_data import database as dbmod
    p = database_path(path)
    if not p.is_file():
        raise FileNotFoundError(missing_database(p))
    try:
        return dbmod.MotionDatabase.load(str(p))
    except Exception as e:  # noqa: BLE001 - corrupt file: one clear line
        raise ValueError(f'motion database {str(p)!r} cannot be read ({type(e).__name__}: {e}): '
                         f'rebuild it with `{BUILD_DB}`') from e
