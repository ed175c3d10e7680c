"""Record and read ROS 2 bags (MCAP) without rclpy.

The files are plain MCAP with the ``ros2`` profile: one ``ros2msg`` schema per message type (the
complete message definition: the type's ``.msg`` text followed by every dependency, each preceded
by a line of 80 ``=`` and ``MSG: pkg/msg/Type``, as rosbag2 writes them) and ``cdr``-encoded
messages. That is what ``rosbag2_storage_mcap`` reads, so the files open in ``ros2 bag play``,
``ros2 bag info`` and Foxglove.

API::

    with BagWriter('out/run.mcap') as bag:
        bag.write('/kinect/skeletons', msg, stamp_ns)              # rclpy message or look-alike
        bag.write('/diagnostics', msg, stamp_ns, 'diagnostic_msgs/msg/DiagnosticArray')
        bag.write_raw('/kinect/skeletons', cdr_bytes, stamp_ns)    # already-serialized CDR

    for m in read_messages('out/run.mcap', topics=['/kinect/skeletons']):
        m.topic, m.stamp_ns, m.msgtype, m.msg.skeletons[0].user_id, m.data

    bag_topics('out/run.mcap')  # {'/kinect/skeletons': ('skeleton_msgs/msg/SkeletonArray', 300)}

``stamp_ns`` is the bag's receive (log) time; ``ros2 bag play`` replays on it. Message definitions
are read from the installed ``share/<pkg>/msg/*.msg`` (ament index / ``AMENT_PREFIX_PATH``), with
``src/skeleton_msgs/msg`` of this workspace as a fallback. An rclpy message is serialized by rclpy
(the bytes a publisher sends); any other object with the message's fields as attributes (e.g. a
decoded message) is encoded from its attributes with the schema, giving the same bytes except for
alignment padding, which the Python encoder zeroes and Fast CDR leaves uninitialized. Either way
rclpy deserializes them to an equal message. For recording, subscribing with ``raw=True`` and
calling :meth:`BagWriter.write_raw` avoids serialization altogether.

Nothing lost (docs/recovery.md): the writer puts what it has on the file at least every
``flush_period_s``; an unfinished or cut file (a writer killed, a recording still being written)
is read up to its last complete message with one warning line, and :func:`recover` rewrites it
into a complete, indexed bag (``ros2 run kinect_bringup recover_bag``). Files that cannot be read
at all raise :class:`BagError` naming the file.
"""
from __future__ import annotations

import math
import os
import re
import struct
import sys
import threading
import time
from pathlib import Path
from typing import Any, Dict, Iterable, Iterator, List, NamedTuple, Optional, Tuple
from io import BytesIO

DEFAULT_MSGTYPE = 'skeleton_msgs/msg/SkeletonArray'
_SEPARATOR = '=' * 80
_PRIMITIVES = {
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string', 'wstring',
}


class BagError(RuntimeError):
    """A bag that cannot be written or read (the message names the file)."""


class BagMessage(NamedTuple):
    topic: str
    stamp_ns: int      # log (receive) time in the bag
    msgtype: str       # 'pkg/msg/Type'
    msg: Any           # decoded message: attribute access like a ROS message
    data: bytes        # raw CDR bytes as stored


# --------------------------------------------------------------------------------------------
# Message definitions
# --------------------------------------------------------------------------------------------
def _normalize_type(name: str) -> str:
    """'pkg/Type' or 'pkg/msg/Type' -> 'pkg/msg/Type'."""
    parts = name.strip().split('/')
    if len(parts) == 2:
        return f'{parts[0]}/msg/{parts[1]}'
    if len(parts) == 3:
        return name.strip()
    raise BagError(f'invalid message type name {name!r} (expected pkg/msg/Type)')


def _share_dirs(package: str) -> List[Path]:
    out: List[Path] = []
    try:
        from ament_index_python.packages import get_package_share_directory
        out.append(Path(get_package_share_directory(package)))
    except Exception:
        pass
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            out.append(Path(prefix) / 'share' / package)
    # this workspace's sources (skeleton_msgs before it is built / installed)
    out.append(Path(__file__).resolve().parents[3] / 'src' / package)
    return out


_MSG_TEXT_CACHE: Dict[str, str] = {}


def message_text(msgtype: str) -> str:
    """The ``.msg`` text of one type (without dependencies)."""
    msgtype = _normalize_type(msgtype)
    if msgtype in _MSG_TEXT_CACHE:
        return _MSG_TEXT_CACHE[msgtype]
    pkg, sub, name = msgtype.split('/')
    for d in _share_dirs(pkg):
        f = d / sub / f'{name}.msg'
        if f.is_file():
            text = f.read_text()
            _MSG_TEXT_CACHE[msgtype] = text
            return text
    raise BagError(f'no message definition for {msgtype} (looked for {sub}/{name}.msg in the '
                   f'share directories of {pkg}; is the workspace sourced?)')


def _field_types(text: str, package: str) -> List[str]:
    """Complex field types referenced by a ``.msg`` text, as 'pkg/msg/Type'."""
    out: List[str] = []
    for line in text.splitlines():
        line = line.split('#', 1)[0].strip()
        if not line:
            continue
        tokens = line.split()
        if len(tokens) < 2:
            continue
        if '=' in tokens[1] or (len(tokens) > 2 and tokens[2].startswith('=')):
            continue  # constant
        base = re.sub(r'\[.*\]$', '', tokens[0])
        base = re.sub(r'<=\d+$', '', base)
        if base in _PRIMITIVES:
            continue
        if base == 'Header':
            dep = 'std_msgs/msg/Header'
        elif '/' in base:
            dep = _normalize_type(base)
        else:
            dep = f'{package}/msg/{base}'
        if dep not in out:
            out.append(dep)
    return out


_FULL_DEF_CACHE: Dict[str, str] = {}


def message_definition(msgtype: str) -> str:
    """The complete ``ros2msg`` definition of a type (rosbag2 / MCAP ``ros2msg`` encoding)."""
    msgtype = _normalize_type(msgtype)
    if msgtype in _FULL_DEF_CACHE:
        return _FULL_DEF_CACHE[msgtype]
    main = message_text(msgtype)
    order: List[str] = []
    todo = _field_types(main, msgtype.split('/')[0])
    while todo:
        dep = todo.pop(0)
        if dep in order or dep == msgtype:
            continue
        order.append(dep)
        todo.extend(_field_types(message_text(dep), dep.split('/')[0]))
    parts = [main.rstrip('\n')]
    for dep in order:
        parts.append(f'{_SEPARATOR}\nMSG: {dep}\n{message_text(dep).rstrip(chr(10))}')
    full = '\n'.join(parts) + '\n'
    _FULL_DEF_CACHE[msgtype] = full
    return full


def _is_rclpy_message(msg: Any) -> bool:
    cls = type(msg)
    return hasattr(cls, '_TYPE_SUPPORT') and hasattr(msg, 'get_fields_and_field_types')


def _rclpy_type_name(msg: Any) -> str:
    cls = type(msg)
    module = cls.__module__.split('.')  # e.g. skeleton_msgs.msg._skeleton_array
    return f'{module[0]}/msg/{cls.__name__}'


# --------------------------------------------------------------------------------------------
# Writer
# --------------------------------------------------------------------------------------------
class BagWriter:
    """Writes an MCAP bag; use as a context manager (or call :meth:`close`).

    Crash-safe: the chunk being filled is closed and written to the file at least every
    ``flush_period_s`` seconds (wall clock) of writing, and on :meth:`poll` when that long has
    passed since the last flush (a recorder calls it from a timer, so a pause in the input does not
    keep the last second in memory). A process killed at any moment (SIGKILL, OOM killer, power
    cut with ``fsync``) leaves a file whose complete chunks :func:`read_messages` reads (it warns
    that the file is truncated) and :func:`recover` rewrites into a complete, indexed bag: at most
    the last ``flush_period_s`` of messages is lost. ``flush_period_s = 0`` flushes only when a
    chunk reaches ``chunk_size`` (and on close). ``fsync``: also have each flushed chunk put on
    the disk (survives a power cut); done by a background thread (an fsync takes ~5-10 ms, which
    the caller, e.g. an executor thread of the one-process pipeline, does not wait for)."""

    def __init__(self, path, compression: str = 'zstd', chunk_size: int = 1 << 20,
                 flush_period_s: float = 1.0, fsync: bool = False):
        from mcap.writer import CompressionType, Writer
        self.path = Path(path)
        if not (flush_period_s >= 0 and math.isfinite(flush_period_s)):
            raise BagError(f'{self.path}: flush_period_s must be >= 0 s, got {flush_period_s}')
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, 'wb')
        except OSError as e:
            raise BagError(f'cannot create bag {self.path}: {e.strerror or e}') from None
        comp = CompressionType.NONE
        if compression == 'zstd':
            try:
                import zstandard  # noqa: F401
                comp = CompressionType.ZSTD
            except ImportError:
                comp = CompressionType.NONE
        elif compression == 'lz4':
            comp = CompressionType.LZ4
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=comp)
        self._writer.start(profile='ros2', library='kinect_posture skeleton_core.bagio')
        self.flush_period_s = float(flush_period_s)
        self.fsync = bool(fsync)
        self._pending = False
        self._sync_thread = None
        if self.fsync:
            self._sync_wanted = threading.Event()
            self._sync_stop = False
            self._sync_thread = threading.Thread(target=self._syncer, daemon=True,
                                                 name='bagio-fsync')
            self._sync_thread.start()
        self._file.flush()   # the header is on disk from the start: a file killed now is a bag
        self._last_flush = time.monotonic()
        self._schemas: Dict[str, int] = {}
        self._encoders: Dict[str, Any] = {}
        self._channels: Dict[str, Tuple[int, str]] = {}
        self._sequence: Dict[str, int] = {}
        self._closed = False
        self.count = 0
        self.flushes = 0

    @property
    def bytes_written(self) -> int:
        """Bytes of the file so far (the chunk being filled, at most ``chunk_size``, not
        counted until it is flushed)."""
        if self._closed:
            return self.path.stat().st_size if self.path.exists() else 0
        return self._file.tell()

    def __enter__(self) -> 'BagWriter':
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _channel(self, topic: str, msgtype: str) -> int:
        ch = self._channels.get(topic)
        if ch is not None:
            if ch[1] != msgtype:
                raise BagError(f'{self.path}: topic {topic} already recorded as {ch[1]}, '
                               f'cannot also write {msgtype}')
            return ch[0]
        sid = self._schemas.get(msgtype)
        if sid is None:
            sid = self._writer.register_schema(name=msgtype, encoding='ros2msg',
                                               data=message_definition(msgtype).encode())
            self._schemas[msgtype] = sid
        cid = self._writer.register_channel(topic=topic, message_encoding='cdr', schema_id=sid,
                                            metadata={})
        self._channels[topic] = (cid, msgtype)
        return cid

    def _encode(self, msg: Any, msgtype: str) -> bytes:
        if _is_rclpy_message(msg) and _rclpy_type_name(msg) == msgtype:
            # rclpy's C serializer: exactly what a publisher sends, and ~3x faster than encoding
            # from attributes in Python
            from rclpy.serialization import serialize_message
            return serialize_message(msg)
        enc = self._encoders.get(msgtype)
        if enc is None:
            from mcap_ros2._dynamic import serialize_dynamic
            enc = serialize_dynamic(msgtype, message_definition(msgtype))[msgtype]
            self._encoders[msgtype] = enc
        try:
            return enc(msg)
        except Exception as e:
            raise BagError(f'{self.path}: cannot encode a {msgtype} from {type(msg).__name__}: '
                           f'{e}') from None

    def write(self, topic: str, msg: Any, stamp_ns: int, msgtype: Optional[str] = None) -> None:
        """Record ``msg`` on ``topic`` at log time ``stamp_ns``. ``msgtype`` defaults to the rclpy
        message's own type, else to ``skeleton_msgs/msg/SkeletonArray``. Serialized bytes (a raw
        subscription's message) are written as they are."""
        if isinstance(msg, (bytes, bytearray, memoryview)):
            self.write_raw(topic, msg, stamp_ns, msgtype or DEFAULT_MSGTYPE)
            return
        if msgtype is None:
            msgtype = _rclpy_type_name(msg) if _is_rclpy_message(msg) else DEFAULT_MSGTYPE
        msgtype = _normalize_type(msgtype)
        self.write_raw(topic, self._encode(msg, msgtype), stamp_ns, msgtype)

    def write_raw(self, topic: str, data: bytes, stamp_ns: int,
                  msgtype: str = DEFAULT_MSGTYPE) -> None:
        """Record already-serialized CDR bytes."""
        if self._closed:
            raise BagError(f'{self.path}: bag already closed')
        cid = self._channel(topic, _normalize_type(msgtype))
        seq = self._sequence.get(topic, 0)
        self._sequence[topic] = seq + 1
        self._writer.add_message(channel_id=cid, log_time=int(stamp_ns),
                                 publish_time=int(stamp_ns), sequence=seq, data=bytes(data))
        self.count += 1
        self._pending = True
        self.poll()

    def poll(self) -> bool:
        """Flush if messages are pending and ``flush_period_s`` has passed since the last flush
        (True if it flushed). Cheap: call it from a timer."""
        if (self._pending and self.flush_period_s > 0 and not self._closed
                and time.monotonic() - self._last_flush >= self.flush_period_s):
            self.flush()
            return True
        return False

    def flush(self) -> None:
        """Close the chunk being filled and write it (with its message index) to the file now."""
        if self._closed:
            return
        self._writer.flush()
        if self._sync_thread is not None:
            self._sync_wanted.set()
        self._pending = False
        self._last_flush = time.monotonic()
        self.flushes += 1

    def _syncer(self) -> None:
        while True:
            self._sync_wanted.wait()
            self._sync_wanted.clear()
            if self._sync_stop:
                return
            try:
                os.fsync(self._file.fileno())
            except (OSError, ValueError):
                pass

    def close(self) -> None:
        if self._sync_thread is not None:
            self._sync_stop = True
            self._sync_wanted.set()
            self._sync_thread.join(timeout=10.0)
            self._sync_thread = None
        if not self._closed:
            self._closed = True
            try:
                self._writer.finish()
                if self.fsync:
                    self._file.flush()
                    os.fsync(self._file.fileno())
            finally:
                self._file.close()


# --------------------------------------------------------------------------------------------
# Reader
# --------------------------------------------------------------------------------------------
def _open(path) -> Tuple[Path, Any]:
    p = Path(path)
    if p.is_dir():  # a rosbag2 bag directory: use its single .mcap file
        files = sorted(p.glob('*.mcap'))
        if len(files) != 1:
            raise BagError(f'cannot read bag {p}: expected one .mcap file in the directory, '
                           f'found {len(files)}')
        p = files[0]
    if not p.is_file():
        raise BagError(f'cannot read bag {p}: no such file')
    try:
        f = open(p, 'rb')
        magic = f.read(8)
        f.seek(0)
    except OSError as e:
        raise BagError(f'cannot read bag {p}: {e.strerror or e}') from None
    if len(magic) < len(_MAGIC) and _MAGIC.startswith(magic):
        f.close()
        raise BagError(f'cannot read bag {p}: it ends before its MCAP header ({len(magic)} bytes: '
                       f'a recorder that has not written yet, or a file cut at once)')
    if magic != _MAGIC:
        f.close()
        hint = ' (sqlite3 bags are not supported: convert with ros2 bag convert)' \
            if magic.startswith(b'SQLite') else ''
        raise BagError(f'cannot read bag {p}: not an MCAP file{hint}')
    return p, f


# --------------------------------------------------------------------------------------------
# Unfinished / truncated files
# --------------------------------------------------------------------------------------------
_MAGIC = b'\x89MCAP0\r\n'
_RECORD_HEAD = struct.Struct('<BQ')
_KNOWN_OPCODES = set(range(0x01, 0x10))
_WARNED: set = set()


class Truncation(NamedTuple):
    """Where an unfinished file ends: ``offset`` = the byte after its last complete record (the
    rest of the file is lost), ``messages`` = the complete messages before it."""
    offset: int
    messages: int
    size: int


def _complete(f, size: int) -> bool:
    """True if the file ends with a footer and the closing magic (a finished MCAP)."""
    from mcap.reader import FOOTER_SIZE
    if size < 2 * len(_MAGIC) + FOOTER_SIZE:
        return False
    f.seek(size - len(_MAGIC))
    if f.read(len(_MAGIC)) != _MAGIC:
        return False
    f.seek(size - len(_MAGIC) - FOOTER_SIZE)
    head = f.read(9)
    return len(head) == 9 and head[0] == 0x02 and _RECORD_HEAD.unpack(head)[1] == FOOTER_SIZE - 9


def _scan(f, size: int, topics: Optional[set] = None):
    """Every complete record of an unfinished file, in file order, up to the first incomplete
    or corrupt one: (schemas, channels, [(schema, channel, message)], Truncation)."""
    from mcap.data_stream import ReadDataStream
    from mcap.records import Channel, Chunk, Message, Schema
    from mcap.stream_reader import breakup_chunk
    readers = {0x03: Schema, 0x04: Channel, 0x06: Chunk}
    schemas: Dict[int, Any] = {}
    channels: Dict[int, Any] = {}
    out: List[Tuple[Any, Any, Any]] = []
    count = 0

    def take(rec) -> None:
        nonlocal count
        if isinstance(rec, Schema):
            schemas[rec.id] = rec
        elif isinstance(rec, Channel):
            channels[rec.id] = rec
        elif isinstance(rec, Message):
            ch = channels[rec.channel_id]
            count += 1
            if topics is None or ch.topic in topics:
                out.append((schemas.get(ch.schema_id), ch, rec))

    pos = len(_MAGIC)
    f.seek(pos)
    while pos + 9 <= size:
        head = f.read(9)
        if len(head) < 9:
            break
        opcode, length = _RECORD_HEAD.unpack(head)
        if opcode not in _KNOWN_OPCODES or pos + 9 + length > size:
            break   # zero-filled tail, garbage, or a record cut off by the end of the file
        if opcode == 0x02:   # a footer (without the closing magic): the records end here
            break
        body = f.read(length)
        if len(body) < length:
            break
        try:
            if opcode == 0x05:
                recs = [Message.read(ReadDataStream(BytesIO(body)), length)]
            elif opcode in readers:
                rec = readers[opcode].read(ReadDataStream(BytesIO(body)))
                recs = breakup_chunk(rec, validate_crc=True) if opcode == 0x06 else [rec]
            else:
                recs = []   # indexes, statistics, attachments, metadata: not needed here
        except Exception:   # noqa: BLE001 - a corrupt record ends the readable part
            break
        known = set(channels) | {r.id for r in recs if isinstance(r, Channel)}
        if any(isinstance(r, Message) and r.channel_id not in known for r in recs):
            break           # a message of no channel: corrupt too
        for rec in recs:
            take(rec)
        pos += 9 + length
    return schemas, channels, out, Truncation(pos, count, size)


def _scan_file(p: Path, f, size: int, topics: Optional[set] = None, warn=None, quiet=False):
    """:func:`_scan` of an unfinished file; BagError when not even its header record is whole
    (nothing of it can be read), else one warning line (unless ``quiet``)."""
    out = _scan(f, size, topics)
    t = out[3]
    if t.offset <= len(_MAGIC):
        raise BagError(f'cannot read bag {p}: corrupt or cut before its first record (byte '
                       f'{t.offset} of {size})')
    if not quiet:
        _warn(p, t, warn)
    return out


def _warn(p: Path, t: Truncation, warn) -> None:
    key = (str(p.resolve()), t.size, warn)   # once per file, size and receiver
    if key in _WARNED:
        return
    _WARNED.add(key)
    text = (f'{p.name} is truncated at byte {t.offset}: read {t.messages} messages, the rest is '
            f'lost' + (f' ({t.size - t.offset} bytes)' if t.size > t.offset else ''))
    if warn is not None:
        warn(text)
    else:
        print(f'warning: {text}', file=sys.stderr, flush=True)


def finished(path) -> bool:
    """True if the bag ends with its footer (written to the end and closed); cheap: reads only
    the last bytes. An unfinished or cut file gives False."""
    p, f = _open(path)
    with f:
        return _complete(f, os.fstat(f.fileno()).st_size)


def truncation(path) -> Optional[Truncation]:
    """None for a finished bag; where an unfinished or cut one ends otherwise (no warning)."""
    p, f = _open(path)
    with f:
        size = os.fstat(f.fileno()).st_size
        if _complete(f, size):
            return None
        return _scan_file(p, f, size, topics=set(), quiet=True)[3]


def bag_topics(path, warn=None) -> Dict[str, Tuple[str, int]]:
    """{topic: (msgtype, message count)} of a bag. An unfinished or truncated file is counted up
    to its last complete message, with one warning line (``warn(text)``, default stderr)."""
    from mcap.reader import make_reader
    p, f = _open(path)
    with f:
        size = os.fstat(f.fileno()).st_size
        if not _complete(f, size):
            schemas, channels, msgs, t = _scan_file(p, f, size, warn=warn)
            out: Dict[str, List] = {}
            for ch in channels.values():
                sc = schemas.get(ch.schema_id)
                out.setdefault(ch.topic, [sc.name if sc is not None else '', 0])
            for _, ch, _m in msgs:
                out[ch.topic][1] += 1
            return {k: (v[0], v[1]) for k, v in out.items()}
        try:
            f.seek(0)
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is not None and summary.statistics is not None:
                counts = summary.statistics.channel_message_counts
                return {ch.topic: (summary.schemas[ch.schema_id].name
                                   if ch.schema_id in summary.schemas else '',
                                   int(counts.get(cid, 0)))
                        for cid, ch in summary.channels.items()}
        except BagError:
            raise
        except Exception as e:
            raise BagError(f'cannot read bag {p}: corrupt MCAP ({e})') from None
    # no summary (a finished file written without one): count by scanning
    out2: Dict[str, List] = {}
    for m in read_messages(p, decode=False):
        out2.setdefault(m.topic, [m.msgtype, 0])[1] += 1
    return {k: (v[0], v[1]) for k, v in out2.items()}


def _rclpy_decoder(msgtype: str):
    """rclpy's C deserializer for ``msgtype`` when rclpy and the message package are importable
    (a built workspace): ~20x faster than the pure-Python CDR decoder, and the messages are the
    real ROS types. None otherwise (or with ``KP_BAGIO_PURE=1``)."""
    if os.environ.get('KP_BAGIO_PURE') or msgtype.count('/') != 2:
        return None
    try:
        import importlib
        from rclpy.serialization import deserialize_message
        pkg, kind, name = msgtype.split('/')
        cls = getattr(importlib.import_module(f'{pkg}.{kind}'), name)
    except (ImportError, AttributeError, ValueError):
        return None
    return lambda data: deserialize_message(bytes(data), cls)


def read_messages(path, topics: Optional[Iterable[str]] = None,
                  decode=True, warn=None) -> Iterator[BagMessage]:
    """Messages of a bag in log-time order (optionally only some topics). ``decode=False`` leaves
    ``msg`` as None (faster when only the raw bytes are needed); a collection of topic names
    decodes only those topics. Messages are decoded by rclpy where it is importable, else by the
    pure-Python decoder of ``mcap_ros2`` (attribute access either way).

    An unfinished file (a recording still being written, or one whose writer was killed) or a
    truncated one is read up to its last complete message, with one warning line
    ``"x.mcap is truncated at byte N: read M messages, the rest is lost"`` (passed to
    ``warn(text)``; default: stderr; once per file, size and ``warn`` in a process)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    p, f = _open(path)
    topic_list = None if topics is None else list(topics)
    factory = DecoderFactory()
    decoders: Dict[int, Any] = {}
    decode_only = None if isinstance(decode, bool) else set(decode)
    with f:
        try:
            size = os.fstat(f.fileno()).st_size
            if _complete(f, size):
                f.seek(0)
                it = make_reader(f).iter_messages(topics=topic_list, log_time_order=True)
            else:
                _, _, msgs, t = _scan_file(p, f, size, None if topic_list is None
                                           else set(topic_list), warn)
                msgs.sort(key=lambda smc: smc[2].log_time)   # stable: file order on equal times
                it = iter(msgs)
            for schema, channel, message in it:
                msg = None
                msgtype = schema.name if schema is not None else ''
                if decode if decode_only is None else channel.topic in decode_only:
                    dec = decoders.get(channel.id)
                    if dec is None:
                        if schema is None:
                            raise BagError(f'cannot decode {channel.topic} in {p}: no schema')
                        dec = (_rclpy_decoder(schema.name) if channel.message_encoding == 'cdr'
                               else None) or factory.decoder_for(channel.message_encoding, schema)
                        if dec is None:
                            raise BagError(f'cannot decode {channel.topic} in {p}: encoding '
                                           f'{channel.message_encoding}/{schema.encoding}')
                        decoders[channel.id] = dec
                    msg = dec(message.data)
                yield BagMessage(channel.topic, int(message.log_time), msgtype, msg,
                                 bytes(message.data))
        except BagError:
            raise
        except Exception as e:
            raise BagError(f'cannot read bag {p}: corrupt MCAP '
                           f'({type(e).__name__}: {e})') from None


# --------------------------------------------------------------------------------------------
# Recovery
# --------------------------------------------------------------------------------------------
def recover(src, dst, warn=None) -> Tuple[int, Optional[Truncation]]:
    """Rewrite ``src`` (an unfinished, truncated or finished bag) into ``dst``: a complete MCAP with
    summary, indexes and statistics, holding every complete message of ``src`` with its schema,
    channel, times and sequence numbers as recorded. Returns (messages written, where ``src`` was
    cut or None if it was complete). ``dst`` is written next to itself and renamed when done."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer
    p, f = _open(src)
    out = Path(dst)
    if out.resolve() == p.resolve():
        raise BagError(f'recover: the output must be another file than {p}')
    with f:
        size = os.fstat(f.fileno()).st_size
        t = None
        try:
            if _complete(f, size):
                f.seek(0)
                reader = make_reader(f)
                items = list(reader.iter_messages(log_time_order=False))
            else:
                _, _, items, t = _scan_file(p, f, size, warn=warn)
        except BagError:
            raise
        except Exception as e:
            raise BagError(f'cannot read bag {p}: corrupt MCAP ({type(e).__name__}: {e})') \
                from None
    tmp = out.with_name(out.name + '.part')
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        try:
            import zstandard  # noqa: F401
            comp = CompressionType.ZSTD
        except ImportError:
            comp = CompressionType.NONE
        with open(tmp, 'wb') as fo:
            w = Writer(fo, compression=comp)
            w.start(profile='ros2', library='kinect_posture skeleton_core.bagio recover')
            sids: Dict[int, int] = {}
            cids: Dict[int, int] = {}
            for schema, channel, message in items:
                cid = cids.get(channel.id)
                if cid is None:
                    sid = 0
                    if schema is not None:
                        sid = sids.get(schema.id)
                        if sid is None:
                            sid = sids[schema.id] = w.register_schema(
                                name=schema.name, encoding=schema.encoding, data=schema.data)
                    cid = cids[channel.id] = w.register_channel(
                        topic=channel.topic, message_encoding=channel.message_encoding,
                        schema_id=sid, metadata=dict(channel.metadata))
                w.add_message(channel_id=cid, log_time=message.log_time,
                              publish_time=message.publish_time, sequence=message.sequence,
                              data=message.data)
            w.finish()
        os.replace(tmp, out)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise BagError(f'cannot write {out}: {e.strerror or e}') from None
    return len(items), t
