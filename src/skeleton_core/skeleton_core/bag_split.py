"""Recordings that rotate: a bag split into pieces by size and/or duration, and pieces read back in
order as one recording (no rclpy).

A recording ``out/day.mcap`` split into pieces is the folder ``out/day/`` holding ``day_0.mcap``,
``day_1.mcap``, ... (rosbag2's layout for ``--max-bag-size`` / ``--max-bag-duration``). Every
piece is a complete MCAP of its own (schemas and channels repeated, summary and footer written
when the next one starts); the piece being written is flushed like any :class:`BagWriter`, so a
recorder killed mid-piece leaves a last piece that every reader reads up to its last complete
message and ``recover_bag`` completes.

When to start the next piece is :class:`SplitPolicy`'s decision, from the bytes the piece holds
and the log times of the messages (the recorder's receive times; a test gives its own), never from
the wall clock: a 30-minute recording split every 5 minutes is 6 pieces whether it took 30
minutes or 3 seconds to write.

    with SplitBagWriter('out/day.mcap', split_duration_s=300) as w:
        w.write_raw('/kinect/skeletons', data, log_time_ns)
    for m in read_pieces(bag_pieces('out/day')):        # in order, as one recording
        ...
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Dict, Iterable, Iterator, List, Optional, Sequence, Tuple, Union

from .bagio import BagError, BagMessage, BagWriter, bag_topics, read_messages

PathLike = Union[str, Path]


class SplitPolicy:
    """When a piece is full: it holds at least one message and the next message would start
    ``split_duration_s`` or more after its first one (log times), or the piece already holds
    ``split_size_bytes`` on disk (its open chunk, at most the writer's chunk size, not counted).
    0 = no limit of that kind; both 0 = never split."""

    def __init__(self, split_size_bytes: int = 0, split_duration_s: float = 0.0):
        if split_size_bytes < 0 or not split_duration_s >= 0:
            raise BagError('split size and duration must be >= 0 (0 = no limit)')
        self.size = int(split_size_bytes)
        self.duration_ns = int(round(split_duration_s * 1e9))

    @property
    def enabled(self) -> bool:
        return bool(self.size or self.duration_ns)

    def full(self, piece_messages: int, piece_bytes: int, piece_start_ns: Optional[int],
             stamp_ns: int) -> bool:
        if not self.enabled or piece_messages == 0:
            return False
        if self.size and piece_bytes >= self.size:
            return True
        return bool(self.duration_ns and piece_start_ns is not None
                    and stamp_ns - piece_start_ns >= self.duration_ns)


def pieces_dir(path: PathLike) -> Path:
    """The folder of a split recording named ``path`` (``out/day.mcap`` -> ``out/day``)."""
    p = Path(path)
    return p.with_suffix('') if p.suffix == '.mcap' else p


def piece_path(path: PathLike, index: int) -> Path:
    d = pieces_dir(path)
    return d / f'{d.name}_{index}.mcap'


class SplitBagWriter:
    """A :class:`BagWriter` that starts a new piece when :class:`SplitPolicy` says the current one
    is full. Without a limit it writes the single file ``path``, like a BagWriter. ``pieces``:
    the pieces written so far (the last one is open until :meth:`close`); ``on_piece(path)`` is
    called when a piece is finished (closed, complete)."""

    def __init__(self, path: PathLike, split_size_bytes: int = 0, split_duration_s: float = 0.0,
                 on_piece=None, **writer_kw):
        self.path = Path(path)
        self.policy = SplitPolicy(split_size_bytes, split_duration_s)
        self._kw = writer_kw
        self._on_piece = on_piece
        self.pieces: List[Path] = []
        self.count = 0
        self._writer: Optional[BagWriter] = None
        self._start_ns: Optional[int] = None
        self._closed = False
        self._open_piece()

    def _open_piece(self) -> None:
        if self.policy.enabled:
            p = piece_path(self.path, len(self.pieces))
        else:
            p = self.path
        self._writer = BagWriter(p, **self._kw)
        self.pieces.append(p)
        self._start_ns = None

    @property
    def current(self) -> Path:
        return self.pieces[-1]

    def piece_bytes(self) -> int:
        """Bytes of the current piece on disk (and in the file's buffer)."""
        return self._writer.bytes_written

    def _piece_for(self, stamp_ns: int):
        """The writer of the piece a message stamped ``stamp_ns`` goes to (a new piece when the
        current one is full)."""
        if self._closed:
            raise BagError(f'{self.path}: bag already closed')
        if self.policy.full(self._writer.count, self.piece_bytes(), self._start_ns, int(stamp_ns)):
            self._finish_piece()
            self._open_piece()
        if self._start_ns is None:
            self._start_ns = int(stamp_ns)
        return self._writer

    def write_raw(self, topic: str, data: bytes, stamp_ns: int, msgtype: Optional[str] = None) -> None:
        w = self._piece_for(stamp_ns)
        if msgtype is None:
            w.write_raw(topic, data, stamp_ns)
        else:
            w.write_raw(topic, data, stamp_ns, msgtype=msgtype)
        self.count += 1

    def write(self, topic: str, msg, stamp_ns: int, msgtype: Optional[str] = None) -> None:
        self._piece_for(stamp_ns).write(topic, msg, stamp_ns, msgtype=msgtype)
        self.count += 1

    def _finish_piece(self) -> None:
        self._writer.close()
        if self._on_piece is not None:
            self._on_piece(self.current)

    def poll(self) -> bool:
        return self._writer.poll() if not self._closed else False

    def flush(self) -> None:
        if not self._closed:
            self._writer.flush()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._finish_piece()

    def __enter__(self) -> 'SplitBagWriter':
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _piece_key(p: Path) -> Tuple:
    """Natural order: day_2.mcap before day_10.mcap."""
    return tuple(int(s) if s.isdigit() else s for s in re.split(r'(\d+)', p.name))


def bag_pieces(source: Union[PathLike, Sequence[PathLike]]) -> List[Path]:
    """The pieces of a recording in order: one file; a folder's ``*.mcap`` files (a split
    recording, or a rosbag2 bag directory) in natural order of their names; or a list of files
    (or a comma-separated string of them) in the order given."""
    if isinstance(source, (list, tuple)):
        items = [Path(s) for s in source]
    elif isinstance(source, str) and ',' in source:
        items = [Path(s.strip()) for s in source.split(',') if s.strip()]
    else:
        items = [Path(source)]
    out: List[Path] = []
    for p in items:
        p = p.expanduser()
        if p.is_dir():
            files = sorted(p.glob('*.mcap'), key=_piece_key)
            if not files:
                raise BagError(f'cannot read bag {p}: no .mcap file in the folder')
            out.extend(files)
        elif p.is_file():
            out.append(p)
        else:
            raise BagError(f'cannot read bag {p}: no such file')
    return out


def pieces_topics(pieces: Iterable[Path], warn=None) -> Dict[str, Tuple[str, int]]:
    """:func:`bag_topics` of the pieces together ({topic: (type, messages)})."""
    out: Dict[str, List] = {}
    for p in pieces:
        for topic, (ty, n) in bag_topics(p, warn=warn).items():
            e = out.setdefault(topic, [ty, 0])
            if ty and e[0] and ty != e[0]:
                raise BagError(f'{p}: {topic} holds {ty}, the earlier pieces {e[0]}')
            e[0] = e[0] or ty
            e[1] += n
    return {k: (v[0], v[1]) for k, v in out.items()}


def read_pieces(pieces: Sequence[Path], topics: Optional[Iterable[str]] = None, decode=True,
                warn=None) -> Iterator[BagMessage]:
    """:func:`read_messages` of every piece, one after the other (each in log-time order; a cut
    piece -- the last one of a killed recorder -- up to its last complete message, with its
    warning)."""
    topic_list = None if topics is None else list(topics)
    for p in pieces:
        yield from read_messages(p, topics=topic_list, decode=decode, warn=warn)


__all__ = ['SplitPolicy', 'SplitBagWriter', 'bag_pieces', 'pieces_dir', 'piece_path',
           'pieces_topics', 'read_pieces']
