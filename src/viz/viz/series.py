"""Skeleton time series for the offline report: one user's skeletons on one topic as arrays,
loaded from a bag (:mod:`skeleton_core.bagio`) or built from in-memory arrays. No rclpy."""
from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np

from skeleton_core.conversions import SkeletonFrame, frames_from_array_msg
from skeleton_core.model import NUM_JOINTS, TRACKED
from skeleton_core import bagio

# Report roles -> default topics (as recorded by the bringup recorder)
ROLE_TOPICS: Dict[str, str] = {
    'raw': '/kinect/skeletons',
    'reliability': '/kinect/skeletons_reliability',
    'completed': '/posture/completed',
    'reconstructed': '/posture/reconstructed',
    'character': '/character/skeletons',
    'ground_truth': '/kinect/ground_truth',
}
METHOD_ROLES: Tuple[str, ...] = ('raw', 'completed', 'reconstructed', 'character')


@dataclass
class SkeletonSeries:
    """N skeletons of one user, ordered by stamp."""

    stamps_ns: np.ndarray       # (N,) int64, header stamps
    positions: np.ndarray       # (N, 20, 3)
    tracking_state: np.ndarray  # (N, 20) uint8
    reliability: np.ndarray     # (N, 20) float32, NaN = unknown
    user_id: int = 0
    frame_id: str = ''
    duplicates: int = 0         # frames dropped because a later one had the same stamp

    def __len__(self) -> int:
        return int(self.stamps_ns.shape[0])

    @property
    def times_s(self) -> np.ndarray:
        return self.stamps_ns.astype(np.float64) * 1e-9

    @classmethod
    def from_arrays(cls, positions, stamps_ns=None, tracking_state=None, reliability=None,
                    fps: float = 30.0, user_id: int = 0, frame_id: str = '') -> 'SkeletonSeries':
        """From arrays; without stamps the frames are ``1/fps`` apart starting at 0. Frames are
        ordered by stamp; of frames with the same stamp only the last one given is kept (a
        physics character published twice for one target: its newer state), counted in
        ``duplicates``."""
        p = np.asarray(positions, dtype=float)
        if p.ndim != 3 or p.shape[1:] != (NUM_JOINTS, 3):
            raise ValueError(f'positions must be (N, {NUM_JOINTS}, 3), got {p.shape}')
        n = p.shape[0]
        if stamps_ns is None:
            stamps_ns = np.round(np.arange(n) * 1e9 / fps).astype(np.int64)
        s = np.asarray(stamps_ns, dtype=np.int64)
        if s.shape != (n,):
            raise ValueError(f'stamps_ns must have {n} entries, got {s.shape}')
        t = (np.full((n, NUM_JOINTS), TRACKED, np.uint8) if tracking_state is None
             else np.asarray(tracking_state, dtype=np.uint8).reshape(n, NUM_JOINTS))
        r = (np.full((n, NUM_JOINTS), np.nan, np.float32) if reliability is None
             else np.asarray(reliability, dtype=np.float32).reshape(n, NUM_JOINTS))
        order = np.argsort(s, kind='stable')
        s = s[order]
        keep = np.ones(n, bool)
        keep[:-1] = s[1:] != s[:-1]          # the last of every run of equal stamps
        order = order[keep]
        return cls(s[keep], p[order], t[order], r[order], user_id, frame_id,
                   duplicates=int(n - keep.sum()))

    @classmethod
    def from_frames(cls, frames: Sequence[SkeletonFrame]) -> 'SkeletonSeries':
        frames = sorted(frames, key=lambda f: f.stamp_ns)
        if not frames:
            raise ValueError('no frames')
        return cls.from_arrays(np.stack([f.positions for f in frames]),
                               np.array([f.stamp_ns for f in frames], np.int64),
                               np.stack([f.tracking_state for f in frames]),
                               np.stack([f.reliability for f in frames]),
                               user_id=frames[0].user_id, frame_id=frames[0].frame_id)

    def index_at(self, stamps_ns: np.ndarray, tolerance_ns: int) -> np.ndarray:
        """Index of the nearest frame to every stamp, -1 when none is within ``tolerance_ns``."""
        q = np.asarray(stamps_ns, dtype=np.int64)
        if len(self) == 0:
            return np.full(q.shape, -1)
        i = np.clip(np.searchsorted(self.stamps_ns, q), 1, max(len(self) - 1, 1))
        lo = np.clip(i - 1, 0, len(self) - 1)
        hi = np.clip(i, 0, len(self) - 1)
        pick = np.where(np.abs(self.stamps_ns[lo] - q) <= np.abs(self.stamps_ns[hi] - q), lo, hi)
        ok = np.abs(self.stamps_ns[pick] - q) <= tolerance_ns
        return np.where(ok, pick, -1)


    def index_held(self, stamps_ns: np.ndarray, hold_ns: int) -> np.ndarray:
        """Index of the latest frame at or before every stamp (what a display shows), -1 when
        there is none or it is older than ``hold_ns``."""
        q = np.asarray(stamps_ns, dtype=np.int64)
        if len(self) == 0:
            return np.full(q.shape, -1)
        i = np.searchsorted(self.stamps_ns, q, side='right') - 1
        ok = (i >= 0) & (q - self.stamps_ns[np.clip(i, 0, None)] <= hold_ns)
        return np.where(ok, i, -1)


@dataclass
class BagData:
    """What the report reads from a bag."""

    series: Dict[str, Dict[int, SkeletonSeries]]    # role -> user id -> series
    topic_counts: Dict[str, Tuple[str, int]]        # every topic: (msgtype, messages)
    dropped: Dict[str, int]                         # malformed skeletons by cause
    topics: Dict[str, str]                          # role -> topic used


def collect(messages: Iterable, role_topics: Optional[Dict[str, str]] = None) -> BagData:
    """Group decoded ``(topic, msg)`` SkeletonArray messages (BagMessage or pairs) into series."""
    role_topics = dict(ROLE_TOPICS if role_topics is None else role_topics)
    roles_of = collections.defaultdict(list)
    for role, topic in role_topics.items():
        roles_of[topic].append(role)
    frames: Dict[str, Dict[int, List[SkeletonFrame]]] = {r: collections.defaultdict(list)
                                                         for r in role_topics}
    counts: Dict[str, List] = {}
    dropped: Dict[str, int] = collections.Counter()
    for m in messages:
        topic, msg = (m.topic, m.msg) if hasattr(m, 'topic') else (m[0], m[1])
        msgtype = getattr(m, 'msgtype', '')
        counts.setdefault(topic, [msgtype, 0])[1] += 1
        if topic not in roles_of or msg is None:
            continue
        errors: list = []
        try:
            got = frames_from_array_msg(msg, errors)
        except (AttributeError, TypeError, ValueError) as e:
            dropped[f'unreadable message: {type(e).__name__}'] += 1
            continue
        for e in errors:
            dropped[e.cause] += 1
        for f in got:
            for role in roles_of[topic]:
                frames[role][f.user_id].append(f)
    series = {role: {uid: SkeletonSeries.from_frames(fs) for uid, fs in sorted(by_user.items())}
              for role, by_user in frames.items()}
    return BagData(series, {k: (v[0], v[1]) for k, v in counts.items()}, dict(dropped),
                   role_topics)


def load_bag(path, role_topics: Optional[Dict[str, str]] = None) -> BagData:
    """Read the skeleton topics of an MCAP bag (other topics are only counted)."""
    role_topics = dict(ROLE_TOPICS if role_topics is None else role_topics)
    wanted = set(role_topics.values())
    counts = bagio.bag_topics(path)
    present = [t for t in wanted if t in counts]
    data = collect(bagio.read_messages(path, topics=present), role_topics) if present else \
        collect([], role_topics)
    data.topic_counts = dict(counts)
    return data


def primary_user(data: BagData) -> Optional[int]:
    """The user with the most frames over the raw / reliability / reconstructed roles."""
    total: Dict[int, int] = collections.Counter()
    for role in ('raw', 'reliability', 'reconstructed', 'completed', 'character', 'ground_truth'):
        for uid, s in data.series.get(role, {}).items():
            total[uid] += len(s)
    if not total:
        return None
    return max(total, key=lambda u: (total[u], -u))
