"""Several Kinects, one skeleton: reliability-weighted multi-sensor fusion. No rclpy.

Each sensor publishes its users in its own frame (``kinect_k_link``); TF says where the sensor is
(``world <- kinect_k_link``, :mod:`skeleton_core.tf`). :class:`MultiSensorFusion` turns the latest
frames of N sensors into one list of skeletons in ``world``, which the reconstruction takes like
one sensor's:

1. **World.** Every frame is put in ``world`` through its sensor's placement (positions and
   joint orientations).
2. **Time.** The output stamp is the newest capture stamp seen. A sensor's user is interpolated
   linearly between its two frames around that stamp; a sensor whose newest frame is older than the
   stamp is held at that frame if it is at most ``max_age_ns`` (one frame period) old, and left out
   otherwise: the fusion never waits for a late sensor.
3. **Reliability.** Shum 2013 Eq. 1-8 (:class:`.reliability.ReliabilityEstimator`) per sensor and
   user, on that sensor's own stream (a frame that carries a finite reliability keeps it).
4. **Mirror.** A Kinect assumes the user faces it: seen from the back, left and right are swapped.
   Each view's body facing in ``world`` (:func:`.posture_space.heading_yaw`) is compared with a
   reference facing (the track's previous fused facing, else the most reliable view's); a view
   facing the other way (cos < -``MIRROR_COS``) has its left/right joints swapped; in between
   (a profile view) the labelling whose L/R joints lie nearer the reference skeleton wins.
5. **Association.** Users of different sensors are the same person when their pelvises are within
   ``gate`` in ``world``: Hungarian assignment of each sensor's users to the tracks on pelvis
   distance, a pair that was together before being ``HYSTERESIS`` m cheaper (no flicker when two
   people pass each other).
6. **Fusion.** Per joint, the reliability-weighted mean of the views (weight = reliability x
   tracking-state factor); the fused reliability is the best view's, the tracking state the best
   view's, the orientation that of the view with the largest weight.
7. **Lost joints.** A joint no view tracks is, in every view, held where that sensor last saw it
   *in the room* (the Kinect's INFERRED joint; the sensor model's ``hold``): it stays behind when
   the person moves. The fused joint is put where the track last saw it *from its parent* (the
   parent's fused position + the last segment vector with both ends tracked), so it moves with
   the body; its state and reliability stay the views' (INFERRED, ~0: the reconstruction still
   replaces it).

One sensor alone passes through untouched: :meth:`MultiSensorFusion.fuse` returns its frames as
they came (same arrays, same frame, same ids; the reconstruction and the physics take the sensor's
frame from TF).
"""
from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
from scipy.optimize import linear_sum_assignment

from skeleton_core import jit
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import HIP_CENTER, NUM_JOINTS, PARENTS, TRACKED
from skeleton_core.tf import Transform

from . import fusion_kernels as K
from .plausibility import unswap_permutation
from .posture_space import heading_yaw
from .reliability import ReliabilityEstimator

WORLD_FRAME = 'world'
FRAME_PERIOD_NS = 33_333_333          # Kinect v1/v2: 30 Hz; a late sensor is waited for at most this
GATE_M = 0.6                          # two views of one person: pelvises closer than this (m); two
#                                       people stand at least a shoulder width (~0.45 m) plus apart
HYSTERESIS = 0.25                     # m: a view stays with its track unless another is this much nearer
MIRROR_COS = 0.5                      # |cos| of the facing difference above which facing decides
STATE_WEIGHT = np.array([0.0, 0.05, 1.0])   # NOT_TRACKED, INFERRED, TRACKED: an inferred joint
#                                       is a guess (Eq. 7 gives it R_t = 0); it only counts when no
#                                       view tracks the joint
_EPS = 1e-9
HOLD_RELATIVE = True    # step 7 (a module switch for the evaluation's with/without comparison)
_PARENTS = np.asarray(PARENTS)
# STATE_WEIGHT of np.clip(state, 0, 2) for any uint8 state, in one lookup
_STATE_WEIGHT8 = np.full(256, STATE_WEIGHT[2])
_STATE_WEIGHT8[:3] = STATE_WEIGHT
# the mirror table and the joints with a mirror twin: one copy, shared with the compiled step
_MIRROR, _LR = K.MIRROR_I, K.LR_I


def to_world(frame: SkeletonFrame, pose: Transform, frame_id: str = WORLD_FRAME) -> SkeletonFrame:
    """``frame`` in ``world`` through its sensor's placement (world <- sensor)."""
    ori = None if frame.orientations is None else pose.apply_quat(frame.orientations)
    return frame.copy(positions=pose.apply(frame.positions), orientations=ori, frame_id=frame_id)


def mirror_labels(frame: SkeletonFrame) -> SkeletonFrame:
    """Left and right joints swapped (the labelling of a Kinect that sees the user's back)."""
    ori = None if frame.orientations is None else frame.orientations[_MIRROR]
    return frame.copy(positions=frame.positions[_MIRROR], tracking_state=frame.tracking_state[_MIRROR],
                      reliability=frame.reliability[_MIRROR], orientations=ori)


def interpolate(f0: SkeletonFrame, f1: SkeletonFrame, stamp_ns: int) -> SkeletonFrame:
    """The skeleton at ``stamp_ns`` between ``f0`` and ``f1`` (positions and reliability linear; the
    tracking state and orientations of the nearer frame). Outside [f0, f1] the nearer frame."""
    t0, t1 = f0.stamp_ns, f1.stamp_ns
    if t1 <= t0 or stamp_ns >= t1:
        return f1 if stamp_ns >= t1 or t1 < t0 else f0
    if stamp_ns <= t0:
        return f0
    a = (stamp_ns - t0) / (t1 - t0)
    near = f1 if a >= 0.5 else f0
    return near.copy(positions=(1.0 - a) * f0.positions + a * f1.positions,
                     reliability=((1.0 - a) * f0.reliability + a * f1.reliability).astype(np.float32),
                     stamp_ns=int(stamp_ns))


def _mean_reliability(r: np.ndarray) -> float:
    """``np.nanmean(r)`` (the same value), without nanmean's overhead when nothing is NaN."""
    m = r.mean()
    return np.nanmean(r) if m != m else m


def facing(positions: np.ndarray, weights=None) -> np.ndarray:
    """Unit horizontal body facing (x, y) in the positions' frame (hip and shoulder lines)."""
    yaw = heading_yaw(positions, [1.0] * NUM_JOINTS if weights is None else weights)
    return np.array([np.cos(yaw), np.sin(yaw)])


def fuse_views(views: Sequence[SkeletonFrame], user_id: int = 0, stamp_ns: int = 0,
               frame_id: str = WORLD_FRAME) -> SkeletonFrame:
    """Per-joint reliability-weighted mean of views of one person in one frame (step 6)."""
    if len(views) == 1:
        return views[0].copy(user_id=user_id, stamp_ns=stamp_ns, frame_id=frame_id)
    p = np.stack([v.positions for v in views])                      # (V, 20, 3)
    ts = np.stack([v.tracking_state for v in views])
    r = np.stack([v.reliability for v in views]).astype(float)
    r[np.isnan(r)] = 0.0                                            # np.nan_to_num(nan=0), in place
    sw = (_STATE_WEIGHT8[ts] if ts.dtype == np.uint8
          else STATE_WEIGHT[np.clip(ts.astype(np.intp), 0, 2)])
    w = np.minimum(np.maximum(r, 0.0), 1.0)                         # np.clip(r, 0, 1)
    w *= sw
    none = w.sum(axis=0) < _EPS                                     # no view trusts the joint
    w[:, none] = sw[:, none] + _EPS                                 # tracking state alone, else all
    w /= w.sum(axis=0, keepdims=True)
    best = w.argmax(axis=0)
    cols = np.arange(NUM_JOINTS)
    ori = None
    if all(v.orientations is not None for v in views):
        ori = np.stack([v.orientations for v in views])[best, cols]
    return SkeletonFrame(positions=np.einsum('vj,vjk->jk', w, p),
                         tracking_state=ts.max(axis=0).astype(np.uint8),
                         reliability=r.max(axis=0).astype(np.float32), orientations=ori,
                         user_id=user_id, stamp_ns=stamp_ns, frame_id=frame_id)


def hold_relative(track: '_Track', fused: SkeletonFrame) -> None:
    """Step 7: joints no view tracks where the track last saw them relative to their parent
    (``fused`` changed in place; ``track.rel`` learns the segments with both ends tracked)."""
    ts = fused.tracking_state
    p = fused.positions
    tracked = ts == TRACKED
    if track.rel is None:
        track.rel = np.full((NUM_JOINTS, 3), np.nan)
    rel = track.rel
    held = ~tracked & ~np.isnan(rel[:, 0])
    held[0] = False
    for j in np.flatnonzero(held).tolist():   # ascending = parents first: a held child follows
        p[j] = p[_PARENTS[j]] + rel[j]          # its (held) parent
    both = tracked.copy()
    both[1:] &= tracked[_PARENTS[1:]]
    both[0] = False
    rel[both] = p[both] - p[_PARENTS[both]]


@dataclass
class _Track:
    track_id: int
    pelvis: np.ndarray
    facing: Optional[np.ndarray] = None
    fused: Optional[SkeletonFrame] = None
    last_ns: int = 0
    rel: Optional[np.ndarray] = None      # (20, 3) each joint from its parent when last tracked


@dataclass
class FusionStats:
    frames: int = 0
    late: int = 0          # views left out: older than one frame period
    mirrored: int = 0      # views whose left/right labels were swapped
    unswapped: int = 0     # views with limbs swapped back (the per-sensor plausibility's swaps)
    tracks: int = 0
    reliability_s: float = 0.0   # time spent in Eq. 1-8 (the reconstruction then takes it as given)


@dataclass
class MultiSensorFusion:
    """Streaming fusion of N sensors (see the module docstring). ``poses``: sensor name -> placement
    world <- sensor. Call :meth:`add` per received message and :meth:`fuse` for the output."""

    poses: Dict[str, Transform]
    max_age_ns: int = FRAME_PERIOD_NS
    gate: float = GATE_M
    frame_id: str = WORLD_FRAME
    stats: FusionStats = field(default_factory=FusionStats)

    def __post_init__(self):
        if not self.poses:
            raise ValueError('fusion needs at least one sensor placement')
        self._hist: Dict[str, Dict[int, List[SkeletonFrame]]] = {s: {} for s in self.poses}
        self._latest: Dict[str, int] = {}
        self._rel: Dict[Tuple[str, int], ReliabilityEstimator] = {}
        self._raw: Dict[str, Tuple[List[SkeletonFrame], int]] = {}
        self._tracks: List[_Track] = []
        self._pair: Dict[Tuple[str, int], int] = {}     # (sensor, user) -> track id
        self._ids = itertools.count(1)
        # steps 4, 6, 7 compiled (fusion_kernels) when numba is on; the numpy code is the twin
        self._jit = jit.enabled() and not self.single
        if self._jit:
            K.warm_up()

    @property
    def single(self) -> bool:
        return len(self.poses) == 1

    def add(self, sensor: str, frames: Sequence[SkeletonFrame], stamp_ns: int) -> None:
        """One message of ``sensor`` (its users at capture time ``stamp_ns``, in its frame)."""
        if sensor not in self.poses:
            raise KeyError(f'unknown sensor {sensor!r} (known: {sorted(self.poses)})')
        self._latest[sensor] = int(stamp_ns)
        if self.single:
            self._raw[sensor] = (list(frames), int(stamp_ns))
            return
        hist = self._hist[sensor]
        seen = set()
        for f in frames:
            rel = f.reliability
            if not np.isfinite(rel).all():
                est = self._rel.get((sensor, f.user_id))
                if est is None:
                    est = self._rel[(sensor, f.user_id)] = ReliabilityEstimator()
                t0 = time.perf_counter()
                rel = est.update(f.positions, f.tracking_state).astype(np.float32)
                self.stats.reliability_s += time.perf_counter() - t0
                plaus = est.plausibility
                perm = unswap_permutation(plaus.swapped) if plaus.lr_unswap else None
                if perm is not None:
                    # the sensor swapped this view's left and right arms or legs (plausibility.py,
                    # which then keeps their reliability): swapped back, as the reconstruction
                    # does with one sensor -- else the weighted mean would average a left limb
                    # with the other view's right one
                    self.stats.unswapped += 1
                    f = f.copy(positions=np.asarray(f.positions, float)[perm],
                               tracking_state=f.tracking_state[perm],
                               orientations=None if f.orientations is None else f.orientations[perm])
                    rel = rel[perm]
            # to_world(f.copy(reliability=rel, stamp_ns=...)) in one copy
            pose = self.poses[sensor]
            w = f.copy(positions=pose.apply(f.positions), reliability=rel, stamp_ns=int(stamp_ns),
                       frame_id=self.frame_id,
                       orientations=None if f.orientations is None else pose.apply_quat(f.orientations))
            h = hist.setdefault(f.user_id, [])
            h.append(w)
            del h[:-2]
            seen.add(f.user_id)
        for uid in [u for u in hist if u not in seen]:      # a user the sensor lost
            del hist[uid]
            self._rel.pop((sensor, uid), None)
            self._pair.pop((sensor, uid), None)

    def _views(self, stamp_ns: int) -> List[Tuple[str, int, SkeletonFrame]]:
        out = []
        for sensor, hist in self._hist.items():
            latest = self._latest.get(sensor)
            if latest is None:
                continue
            if stamp_ns - latest > self.max_age_ns:
                self.stats.late += len(hist)
                continue
            for uid, h in hist.items():
                out.append((sensor, uid, interpolate(h[0], h[-1], stamp_ns) if len(h) > 1 else h[-1]))
        return out

    def _associate(self, views) -> Dict[int, List[Tuple[str, int, SkeletonFrame]]]:
        groups: Dict[int, List] = {}
        by_sensor: Dict[str, List] = {}
        for v in views:
            by_sensor.setdefault(v[0], []).append(v)
        # sensors with the most users first: they seed the tracks of a new scene
        for sensor in sorted(by_sensor, key=lambda s: -len(by_sensor[s])):
            vs = by_sensor[sensor]
            tracks = self._tracks
            pel = np.array([v[2].positions[HIP_CENTER] for v in vs])
            assigned = {}
            if tracks:
                tp = np.array([t.pelvis for t in tracks])
                diff = pel[:, None, :2] - tp[None, :, :2]
                dist = np.sqrt(np.einsum('vtk,vtk->vt', diff, diff))   # np.linalg.norm's value
                index = {t.track_id: k for k, t in enumerate(tracks)}
                prev = np.zeros(dist.shape)
                for i, v in enumerate(vs):
                    k = index.get(self._pair.get((sensor, v[1])))
                    if k is not None:
                        prev[i, k] = 1.0
                # one view per sensor and track: the assignment gives each track at most one of
                # this sensor's views, and no track holds one yet (each sensor is assigned once)
                cost = dist - HYSTERESIS * prev
                if len(vs) == 1:     # one view: the assignment is the cheapest track
                    rows, cols = np.zeros(1, np.intp), np.argmin(cost, axis=1)
                else:
                    rows, cols = linear_sum_assignment(cost)
                for i, k in zip(rows.tolist(), cols.tolist()):
                    if dist[i, k] < self.gate + HYSTERESIS * prev[i, k]:
                        assigned[i] = tracks[k]
            for i, v in enumerate(vs):
                t = assigned.get(i)
                if t is None:
                    t = _Track(next(self._ids), pel[i].copy())
                    self._tracks.append(t)
                self._pair[(sensor, v[1])] = t.track_id
                groups.setdefault(t.track_id, []).append(v)
        return groups

    def _resolve_mirror(self, track: _Track, views: List[Tuple[str, int, SkeletonFrame]]) -> List[SkeletonFrame]:
        frames = [v[2] for v in views]
        if len(frames) == 1 and track.facing is None:
            return frames
        ref_i = int(np.argmax([_mean_reliability(f.reliability) for f in frames]))
        ref_face = track.facing
        if ref_face is None:
            ref_face = facing(frames[ref_i].positions, frames[ref_i].reliability)
        ref_pos = track.fused.positions if track.fused is not None else frames[ref_i].positions
        out = []
        for i, f in enumerate(frames):
            if track.facing is None and i == ref_i:
                out.append(f)
                continue
            c = float(facing(f.positions, f.reliability) @ ref_face)
            if c > MIRROR_COS:
                flip = False
            elif c < -MIRROR_COS:
                flip = True
            else:   # a profile view: the labelling nearer the reference skeleton
                keep = np.linalg.norm(f.positions[_LR] - ref_pos[_LR], axis=1).sum()
                swap = np.linalg.norm(f.positions[_MIRROR][_LR] - ref_pos[_LR], axis=1).sum()
                flip = swap < keep
            if flip:
                self.stats.mirrored += 1
                f = mirror_labels(f)
            out.append(f)
        return out

    def _fuse_compiled(self, track: _Track, views, stamp_ns: int) -> SkeletonFrame:
        """Steps 4, 6 and 7 and the track's new facing in one compiled call
        (fusion_kernels.fuse_track: the arithmetic of _resolve_mirror, fuse_views, hold_relative
        and facing); ``track.facing`` is set."""
        frames = [v[2] for v in views]
        P = np.array([f.positions for f in frames], float)
        TS = np.array([f.tracking_state for f in frames], np.uint8)
        R = np.array([f.reliability for f in frames], np.float32)
        has_face = track.facing is not None
        fused = track.fused
        if track.rel is None:
            track.rel = np.full((NUM_JOINTS, 3), np.nan)
        out_p = np.empty((NUM_JOINTS, 3))
        out_ts = np.empty(NUM_JOINTS, np.uint8)
        out_r = np.empty(NUM_JOINTS, np.float32)
        best = np.empty(NUM_JOINTS, np.int64)
        flips = np.empty(len(frames), np.uint8)
        face = np.empty(2)
        K.fuse_track(P, TS, R, has_face, track.facing if has_face else face,
                     fused is not None, out_p if fused is None else fused.positions,
                     HOLD_RELATIVE, track.rel, K.MIRROR_I, K.LR_I, K.PARENTS_I, K.HEADING_I,
                     STATE_WEIGHT, MIRROR_COS, _EPS, out_p, out_ts, out_r, best, flips, face)
        track.facing = face
        ori = None
        if all(f.orientations is not None for f in frames):
            o = np.array([f.orientations for f in frames])
            for i in np.flatnonzero(flips).tolist():
                o[i] = o[i][_MIRROR]
            ori = o[best, np.arange(NUM_JOINTS)]
        nflip = int(flips.sum())
        if nflip:
            self.stats.mirrored += nflip
        return SkeletonFrame(positions=out_p, tracking_state=out_ts, reliability=out_r,
                             orientations=ori, user_id=track.track_id, stamp_ns=stamp_ns,
                             frame_id=self.frame_id)

    def fuse(self, stamp_ns: Optional[int] = None) -> Tuple[List[SkeletonFrame], int, str]:
        """(skeletons, stamp, frame_id) at ``stamp_ns`` (default: the newest capture stamp)."""
        self.stats.frames += 1
        if self.single:
            (sensor,) = self.poses
            frames, st = self._raw.get(sensor, ([], 0))
            fid = frames[0].frame_id if frames else ''
            return frames, st, fid
        if stamp_ns is None:
            stamp_ns = max(self._latest.values(), default=0)
        groups = self._associate(self._views(stamp_ns))
        out = []
        alive = []
        for t in self._tracks:
            views = groups.get(t.track_id)
            if not views:
                continue
            if self._jit:
                fused = self._fuse_compiled(t, views, stamp_ns)
            else:
                frames = self._resolve_mirror(t, views)
                fused = fuse_views(frames, user_id=t.track_id, stamp_ns=stamp_ns,
                                   frame_id=self.frame_id)
                if HOLD_RELATIVE:
                    hold_relative(t, fused)
                t.facing = facing(fused.positions, fused.reliability)
            t.pelvis = fused.positions[HIP_CENTER].copy()
            t.fused = fused
            t.last_ns = stamp_ns
            alive.append(t)
            out.append(fused)
        self._tracks = alive
        ids = {t.track_id for t in alive}
        self._pair = {k: v for k, v in self._pair.items() if v in ids}
        self.stats.tracks = len(alive)
        return out, stamp_ns, self.frame_id
