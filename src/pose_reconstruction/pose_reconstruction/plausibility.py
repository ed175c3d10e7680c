"""Plausibility of a skeleton the sensor reports as TRACKED: a reliability term for confident failures.

Shum et al. 2013's reliability (Eq. 1-8, :mod:`.reliability`) trusts the tracking state (Eq. 7)
and looks for vibration (Eq. 1-4) and stretched segments (Eq. 5-6, averaged over a joint's
segments). A Kinect that is confidently wrong — a hand snapped to a table or to the other hand, the
left and right limbs swapped when the user is side-on, a foot slid into the floor, the whole
skeleton on a second person for a few frames — reports TRACKED joints that do not vibrate. This
module gives each joint a plausibility ``R_p`` in [0, 1] per frame from what a body cannot do;
:class:`~.reliability.ReliabilityEstimator` takes ``min(Eq. 8, R_p)``, so an implausible joint is
unreliable from the frame it becomes implausible and the optimizer fills it from the database.

Terms (each 1 = plausible):

* **bone length against the user's profile** — segment ``s`` with both ends TRACKED:
  ``excess = |l_s - L_s| - (bone_tolerance L_s + bone_tolerance_m)``, score
  ``1 - excess / (bone_reject L_s)`` clipped to [0, 1]. Blame goes to the segment's child and, for
  a limb segment, to every joint below it (a snapped wrist drags its hand); a girdle or trunk
  segment blames its child only. ``L`` is the profile
  (:attr:`~.reliability.ReliabilityEstimator.profile_lengths`: captured in a reference posture,
  else the running median of the plausible tracked lengths; a segment not observed yet is not
  judged).
* **segment speed** — a segment's child moving faster than ``max_segment_speed_m_s`` relative to
  its parent between two frames (a snap onset) blames it and what hangs from it, latched until
  it jumps again (the snap ends) or ``latch_frames`` pass: a wrist and hand snapped together
  onto a point their own lengths allow keeps every bone length. A jump from a length the bone
  term rejects to one it accepts is a failure ending, not a snap onset (a wrist that
  slid onto an object slower than the speed limit, rejected by its forearm length, jumped back
  and was then latched for 1.5 s on the right place, the forearm filled by the database). So is
  a jump away from a place the segment held for fewer than ``TRANSIENT_FRAMES`` frames (since
  it was tracked, or since its last jump): that place was the transient (a real Kinect v2 leg
  that starts a recording 36 cm off and is right a frame later). After its jump frame a latched
  segment scores the trust in the sensor (:attr:`PlausibilityCheck.sensor_trust`, set by the
  reconstructor from :mod:`.trust`; 0 without one): where the database explains the user the
  snapped place is filled from it, where it does not its fill would be worse than the sensor's
  new place (a real Kinect v2 knee catching up with a hurdle step was filled 70 cm off).
* **left/right against the heading** — the shoulder and the hip lines each give a heading; the
  body heading follows the girdles that agree with it at ``heading_rate`` per frame. A girdle
  more than ``lr_flip_deg`` off the body heading while the other girdle agrees with it has its
  left and right swapped (:attr:`PlausibilityCheck.swapped`): with ``lr_unswap`` the
  reconstructor swaps the two limbs back (:func:`unswap`) and keeps them, else both limbs
  (girdle joints included) get 0. (Both girdles off at once is a fast turn or a whole-body
  mirror: the heading is taken over.)
* **floor penetration** — the floor height is a low quantile (``FLOOR_QUANTILE``), over the
  last ``floor_window`` frames, of the lowest TRACKED foot or ankle (less its height). The floor
  is where the feet are lowest: a foot lifted, or resting TRACKED on a step or an object, is
  above it on most frames (the median of such a window put the floor 25-30 cm too high and
  rejected a clean TRACKED ankle below it for 20 frames); a foot through the floor is a
  short event. A joint ``floor_tolerance_m`` below the floor starts losing plausibility,
  ``floor_reject_m`` below it has none.
* **whole-skeleton jump** — the TRACKED joints moving, in the median, more than ``jump_m`` from
  where each was last plausibly makes every joint 0 (:attr:`PlausibilityCheck.skeleton_outlier`
  True) until they are back within ``jump_m``, for at most ``jump_frames`` frames (then the new
  place is accepted: a real re-acquisition). "Where each was" moves on with the body's velocity
  before the jump (the median displacement per frame): a running user is 0.7 m on after the 6
  frames the skeleton spent on someone else, and its return to the user is a return (before:
  9 frames of a running user's right skeleton were rejected as still jumped).

``plausibility=False`` turns the whole term off (R_p = 1: the paper's reliability).
"""
from __future__ import annotations

import bisect
import collections
import dataclasses
from dataclasses import dataclass
from typing import Dict, Optional

import numpy as np

from skeleton_core import jit
from skeleton_core.params import check, defaults, names, param
from skeleton_core.model import (ANKLE_LEFT, ANKLE_RIGHT, FOOT_LEFT, FOOT_RIGHT, HIP_LEFT,
                                 HIP_RIGHT, LIMB_JOINTS, NUM_JOINTS, NUM_SEGMENTS, PARENTS, ROOT,
                                 SEGMENT_CHILDREN, SEGMENT_PARENTS, SHOULDER_LEFT, SHOULDER_RIGHT,
                                 TRACKED, standard_body)

from .quantile import sorted_quantile


@dataclass
class PlausibilityConfig:
    """Parameters of :class:`PlausibilityCheck` (nested in the reliability's configuration; our
    values, tuned on the dev clips with sensor seed 0: docs/research/2026-11-28-robustness.md)."""

    plausibility: bool = param(
        True, 'confident failures: lower the reliability of TRACKED joints a body cannot have '
        '(bone lengths against the profile, segment speed, left/right against the heading, '
        'floor, whole-skeleton jump); false = Eq. 1-8 only (paper)', public=False)
    bone_tolerance: float = param(
        0.4, 'plausibility: relative segment-length deviation from the user profile tolerated',
        range=(0.0, 10.0), public=False)
    bone_tolerance_m: float = param(
        0.03, 'plausibility: absolute segment-length deviation (m) tolerated on top',
        range=(0.0, 1.0), public=False)
    bone_reject: float = param(
        1.0, 'plausibility: relative deviation beyond the tolerance at which a segment (and what '
        'hangs from it) has no plausibility left', range=(0.01, 100.0), public=False)
    max_segment_speed_m_s: float = param(
        8.0, 'plausibility: fastest a segment end moves relative to its parent (m/s); faster is '
        'a snap onset', range=(0.1, 1000.0), public=False)
    latch_frames: int = param(
        45, 'plausibility: frames a segment stays implausible after a snap onset unless it jumps '
        'back first; 0 = the onset frame only', range=(0, 100000), public=False)
    lr_flip_deg: float = param(
        110.0, 'plausibility: a girdle (shoulders or hips) this far (deg) off the body heading, '
        'the other girdle agreeing with it, has its left and right swapped', range=(1.0, 180.0),
        public=False)
    lr_unswap: bool = param(
        True, 'plausibility: swap detected left/right limbs back (true) or make both limbs '
        'unreliable (false)', public=False)
    heading_rate: float = param(
        0.3, 'plausibility: per-frame rate at which the body heading follows the girdles that '
        'agree with it', range=(0.001, 1.0), public=False)
    floor_tolerance_m: float = param(
        0.05, 'plausibility: depth (m) below the estimated floor a joint may reach unpunished',
        range=(0.0, 2.0), public=False)
    floor_reject_m: float = param(
        0.12, 'plausibility: depth (m) below the floor at which a joint has no plausibility '
        'left', range=(0.001, 5.0), public=False)
    floor_window: int = param(
        150, 'plausibility: frames whose lowest TRACKED foot gives the floor (a low quantile)',
        range=(1, 100000), public=False)
    jump_m: float = param(
        0.35, 'plausibility: median distance (m) of the TRACKED joints from their last plausible '
        'place that makes the whole skeleton another person (last output held)',
        range=(0.01, 100.0), public=False)
    jump_frames: int = param(
        15, 'plausibility: frames a whole-skeleton jump is rejected before the new place is '
        'accepted (re-acquisition)', range=(1, 10000), public=False)

    def validate(self) -> None:
        check(self)
        if not self.floor_reject_m > self.floor_tolerance_m:
            raise ValueError('floor_tolerance_m must be below floor_reject_m')


PLAUSIBILITY_PARAMS = tuple(names(PlausibilityConfig))
PLAUSIBILITY_DEFAULTS: Dict = defaults(PlausibilityConfig)

K = jit.lazy_module('pose_reconstruction.reliability_kernels')  # (numba: when first used)

_SEG_P = np.array(SEGMENT_PARENTS)
_SEG_C = np.array(SEGMENT_CHILDREN)
_LIMB = set(LIMB_JOINTS['left_arm'][1:] + LIMB_JOINTS['right_arm'][1:]
            + LIMB_JOINTS['left_leg'][1:] + LIMB_JOINTS['right_leg'][1:])


# the floor: this quantile of the lowest TRACKED foot over floor_window frames (module docstring)
# (a foot through the floor stays rejected for floor_window * FLOOR_QUANTILE frames, 1.2 s);
# a TRACKED ankle says the floor is at most _ANKLE_HEIGHT below it (the standard body's ankle
# above its foot joint)
FLOOR_QUANTILE = 0.25
# the floor forgotten when no foot or ankle was TRACKED for more frames than this (1 s): the user
# may have moved onto other ground meanwhile (a Kinect walk on uneven terrain: a foot re-acquired
# 19 cm below the floor its window still held from 2.3 s before was rejected for 6 frames and
# filled by the database); a new floor from the next 5 tracked frames on
FLOOR_STALE_FRAMES = 30
# segment speed: a place a segment held for fewer frames than this (since it was tracked, or
# since its last jump) is a transient; a jump away from it is a failure ending, not a snap onset
# (a Kinect v2 leg that starts a recording 36 cm off and jumps to the right place one
# frame later was latched unreliable for 1.5 s)
TRANSIENT_FRAMES = 3
_ANKLE_HEIGHT = float(-standard_body().rest_offsets[FOOT_LEFT][2])


def _below(j: int) -> np.ndarray:
    """(20,) bool: ``j`` and every joint below it."""
    out = np.zeros(NUM_JOINTS, bool)
    for k in range(NUM_JOINTS):
        a = k
        while a >= 0:
            if a == j:
                out[k] = True
                break
            a = PARENTS[a] if a != ROOT else -1
    return out


# (19, 20): the joints a segment's implausibility is blamed on
BLAME = np.zeros((NUM_SEGMENTS, NUM_JOINTS), bool)
for _s, _c in enumerate(SEGMENT_CHILDREN):
    if _c in _LIMB:
        BLAME[_s] = _below(_c)
    else:
        BLAME[_s, _c] = True
# (19,) the segment above each segment (whose child is its parent joint; -1: none); segments are
# ordered parents first
PARENT_SEGMENT = np.array([SEGMENT_CHILDREN.index(_p) if _p in SEGMENT_CHILDREN else -1
                           for _p in SEGMENT_PARENTS], np.int64)
assert all(_q < _s for _s, _q in enumerate(PARENT_SEGMENT))
_GIRDLES = np.array([SHOULDER_LEFT, SHOULDER_RIGHT, HIP_LEFT, HIP_RIGHT], np.int64)
_FEET = np.array([FOOT_LEFT, FOOT_RIGHT, ANKLE_LEFT, ANKLE_RIGHT], np.int64)
_ARMS = np.zeros(NUM_JOINTS, bool)
_ARMS[list(LIMB_JOINTS['left_arm'] + LIMB_JOINTS['right_arm'])] = True
_LEGS = np.zeros(NUM_JOINTS, bool)
_LEGS[list(LIMB_JOINTS['left_leg'] + LIMB_JOINTS['right_leg'])] = True


def _wrap(a: float) -> float:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def girdle_yaw(p: np.ndarray, left: int, right: int) -> float:
    """Heading (rad, 0 facing +x) of a girdle: its right-to-left line turned by -90 deg."""
    d = p[left] - p[right]
    return float(np.arctan2(-d[0], d[1]))


_PERM = {'arms': np.arange(NUM_JOINTS), 'legs': np.arange(NUM_JOINTS)}
for _g, _limbs in (('arms', ('left_arm', 'right_arm')), ('legs', ('left_leg', 'right_leg'))):
    _a, _b = LIMB_JOINTS[_limbs[0]], LIMB_JOINTS[_limbs[1]]
    _PERM[_g][list(_a)] = _b
    _PERM[_g][list(_b)] = _a


def unswap_permutation(swapped: Dict[str, bool]) -> Optional[np.ndarray]:
    """(20,) joint index array that swaps back the girdles flagged in ``swapped`` (None: none)."""
    perm = None
    for g in ('arms', 'legs'):
        if swapped.get(g):
            perm = _PERM[g].copy() if perm is None else perm[_PERM[g]]
    return perm


def validate(values: Dict) -> Optional[str]:
    """Why a set of plausibility parameters is unusable, or None."""
    try:
        dataclasses.replace(PlausibilityConfig(), **{k: v for k, v in values.items()
                                                     if k in PLAUSIBILITY_PARAMS}).validate()
    except ValueError as exc:
        return str(exc)
    return None


class PlausibilityCheck:
    """Streaming per-user plausibility (module docstring); :meth:`update` once per frame."""

    def __init__(self, config: Optional[PlausibilityConfig] = None, fps: float = 30.0,
                 **params):
        cfg = dataclasses.replace(config or PlausibilityConfig(), **params)
        cfg.validate()
        self.config = cfg
        self.enabled = bool(cfg.plausibility)
        self.bone_tolerance = float(cfg.bone_tolerance)
        self.bone_tolerance_m = float(cfg.bone_tolerance_m)
        self.bone_reject = float(cfg.bone_reject)
        self.max_step = float(cfg.max_segment_speed_m_s) / float(fps)
        self.latch_frames = int(cfg.latch_frames)
        self.lr_flip = np.radians(float(cfg.lr_flip_deg))
        self.lr_unswap = bool(cfg.lr_unswap)
        self.heading_rate = float(cfg.heading_rate)
        self.floor_tolerance = float(cfg.floor_tolerance_m)
        self.floor_reject = float(cfg.floor_reject_m)
        self.floor_window = int(cfg.floor_window)
        self.jump_m = float(cfg.jump_m)
        self.jump_frames = int(cfg.jump_frames)
        self._jit = jit.enabled()        # the segment terms compiled (reliability_kernels)
        self.reset()

    def reset(self) -> None:
        self.heading: Optional[float] = None
        self._floor_z: collections.deque = collections.deque(maxlen=self.floor_window)
        self._floor_sorted: list = []     # the window's finite values, sorted (running median)
        self._floor_nan = 0               # NaNs in the window (np.median: NaN)
        self._floor_unseen = 0            # frames since a foot or ankle was last TRACKED
        self.floor: Optional[float] = None
        self._last_rel: Optional[np.ndarray] = None
        self._latch = np.zeros(NUM_SEGMENTS, int)
        # the trust in the sensor (trust.py), set by the owner after each frame: a latched
        # segment (after its jump frame) scores the trust
        self.sensor_trust = 0.0
        # frames each segment has stayed where it is (both ends TRACKED, no jump)
        self._held = np.zeros(NUM_SEGMENTS, np.int64)
        self._last_both = np.zeros(NUM_SEGMENTS, bool)
        self._last_bone = np.ones(NUM_SEGMENTS)   # last frame's bone-length score per segment
        self._anchor: Optional[np.ndarray] = None
        self._jumped_a = np.zeros(1, np.int64)   # frames of the current jump rejected
        self._jump_vel = np.zeros(3)              # the body's velocity (m per frame)
        self.skeleton_outlier = False
        self.swapped = {'arms': False, 'legs': False}
        self.terms: Dict[str, np.ndarray] = {}
        self.value = np.ones(NUM_JOINTS)
        # the compiled step's state (reliability_kernels.plausibility_step): heading [known,
        # value], the floor window as a ring and its sorted finite values, [start, length,
        # sorted length, NaNs, frames since a foot was TRACKED], the floor [known, value], the
        # step's flags
        self._k_lr = np.zeros(2)
        self._k_ring = np.zeros(self.floor_window)
        self._k_sorted = np.zeros(self.floor_window)
        self._k_meta = np.zeros(5, np.int64)
        self._k_floor = np.zeros(2)
        self._k_flags = np.zeros(4, np.int64)

    def lengths_plausible(self) -> np.ndarray:
        """(20,) bool: the joints whose segments were plausible in the last frame (length and
        speed; not on another person): what the user's length profile may learn from. The
        floor and left/right terms say where a joint is, not how long a segment is."""
        if not self.enabled:
            return np.ones(NUM_JOINTS, bool)
        if self.skeleton_outlier:
            return np.zeros(NUM_JOINTS, bool)
        seg = self.terms.get('segments')
        return np.ones(NUM_JOINTS, bool) if seg is None else seg >= 0.5

    # ------------------------------------------------------------------------------------
    def _jump(self, p: np.ndarray, tracked: np.ndarray) -> bool:
        """Whole-skeleton jump: the median distance of the joints TRACKED now and when last
        plausible from where they were then, moved on by the body's velocity since (a held
        INFERRED root snapping back is not a jump; fewer than 3 such joints: no judgement;
        :func:`.reliability_kernels._skeleton_jump`, compiled or not)."""
        if self._anchor is None:
            self._anchor = p.copy()
            self._anchor_ok = tracked.copy()
            return False
        step = K.skeleton_jump if self._jit else K._skeleton_jump
        return bool(step(p, tracked, self._anchor, self._anchor_ok, self._jumped_a, self.jump_m,
                         self.jump_frames, self._jump_vel))

    def _skeleton_jumped(self) -> np.ndarray:
        """R_p of a whole-skeleton jump frame: every joint 0. The segment-speed term does not
        compare the first frame back with the last one before the jump: across the gap a
        running user's limbs swing farther than a snap's step, and the right skeleton's return
        was latched as a snap of its ankles for 1.5 s; the return is judged as a
        re-acquisition (no segment TRACKED in the last frame)."""
        self._last_both = np.zeros(NUM_SEGMENTS, bool)
        self.value = np.zeros(NUM_JOINTS)
        self.terms = {'jump': self.value}
        return self.value

    def _latched_score(self) -> float:
        """The speed term of a latched segment after its jump frame: the trust in the sensor (0
        where the database explains the user: the snapped place is filled from it; up to 1 where
        it does not: its fill would be worse than the sensor's new place)."""
        return min(max(float(self.sensor_trust), 0.0), 1.0)

    def _bones(self, seg_len, both, ref) -> np.ndarray:
        with np.errstate(invalid='ignore'):
            excess = np.abs(seg_len - ref) - (self.bone_tolerance * ref + self.bone_tolerance_m)
            score = 1.0 - np.maximum(excess, 0.0) / np.maximum(self.bone_reject * ref, 1e-6)
        # a segment without a profile length yet (NaN) is not judged
        return np.where(both & np.isfinite(score), np.minimum(np.maximum(score, 0.0), 1.0), 1.0)

    def _speed(self, rel, both, bone=None) -> np.ndarray:
        """A segment whose child jumps faster than ``max_segment_speed_m_s`` relative to its parent
        is latched implausible until it jumps again (the snap ends) or ``latch_frames`` pass.
        ``bone`` (19,): this frame's bone-length score; a jump from a length the bone term
        rejected to one it accepts, or from a place held fewer than ``TRANSIENT_FRAMES`` frames,
        is the end of a failure, not a snap onset (module docstring)."""
        score = np.ones(NUM_SEGMENTS)
        if bone is None:
            bone = np.ones(NUM_SEGMENTS)
        if self._last_rel is not None:
            diff = rel - self._last_rel
            step = np.sqrt((diff * diff).sum(axis=1))      # np.linalg.norm's arithmetic
            # TRACKED in both frames: a joint re-acquired after an occlusion may jump
            steady = both & self._last_both
            jump = steady & (step > self.max_step)
            # the jump back (a latched snap ending, a wrong length becoming right, or a jump
            # away from a place just taken: the transient was that place)
            ended = jump & ((self._latch > 0) | ((self._last_bone < 1.0) & (bone >= 1.0))
                            | (self._held < TRANSIENT_FRAMES))
            # a segment's end moves relative to its parent when the parent jumps: where the
            # segment above ended a failure in this frame (a knee back from where it hung behind
            # an object), this segment's jump is that return, not a snap of its own child (the
            # ankle, right all along, was latched for 1.5 s)
            for s in range(NUM_SEGMENTS):   # parents first
                q = PARENT_SEGMENT[s]
                if q >= 0 and jump[s] and ended[q]:
                    ended[s] = True
            self._held = np.where(steady & ~jump, self._held + 1, 0)
            self._latch[jump & ~ended] = 1
            self._latch[ended] = 0
            on = self._latch > 0
            self._latch[on] += 1
            self._latch[self._latch > self.latch_frames] = 0
            score[self._latch > 0] = self._latched_score()
            score[jump] = 0.0
        self._last_rel = rel
        self._last_both = both
        self._last_bone = bone
        return score

    def _left_right(self, p) -> np.ndarray:
        out = np.ones(NUM_JOINTS)
        hs = girdle_yaw(p, SHOULDER_LEFT, SHOULDER_RIGHT)
        hh = girdle_yaw(p, HIP_LEFT, HIP_RIGHT)
        if self.heading is None:
            self.heading = float(np.arctan2(np.sin(hs) + np.sin(hh), np.cos(hs) + np.cos(hh)))
            return out
        ds, dh = abs(_wrap(hs - self.heading)), abs(_wrap(hh - self.heading))
        apart = abs(_wrap(hs - hh)) > self.lr_flip
        arms = apart and ds > self.lr_flip and dh <= self.lr_flip
        legs = apart and dh > self.lr_flip and ds <= self.lr_flip
        self.swapped = {'arms': bool(arms), 'legs': bool(legs)}
        if arms:
            if not self.lr_unswap:
                out[_ARMS] = 0.0
            target = hh
        elif legs:
            if not self.lr_unswap:
                out[_LEGS] = 0.0
            target = hs
        else:
            target = float(np.arctan2(np.sin(hs) + np.sin(hh), np.cos(hs) + np.cos(hh)))
            if ds > self.lr_flip and dh > self.lr_flip:   # both off: a fast turn or a mirror
                self.heading = target
                return out
        self.heading = _wrap(self.heading + self.heading_rate * _wrap(target - self.heading))
        return out

    def _floor(self, p, tracked) -> np.ndarray:
        low = [p[j, 2] for j in (FOOT_LEFT, FOOT_RIGHT) if tracked[j]]
        low += [p[j, 2] - _ANKLE_HEIGHT for j in (ANKLE_LEFT, ANKLE_RIGHT) if tracked[j]]
        if low:
            if self._floor_unseen > FLOOR_STALE_FRAMES:   # stale: other ground, perhaps
                self._floor_z.clear()
                self._floor_sorted.clear()
                self._floor_nan = 0
                self.floor = None
            self._floor_unseen = 0
            self._floor_push(float(min(low)))
            if len(self._floor_z) >= 5:
                self.floor = self._floor_quantile(FLOOR_QUANTILE)
        else:
            self._floor_unseen += 1
        if self.floor is None:
            return np.ones(NUM_JOINTS)
        depth = self.floor - p[:, 2]
        score = 1.0 - (depth - self.floor_tolerance) / (self.floor_reject - self.floor_tolerance)
        return np.minimum(np.maximum(score, 0.0), 1.0)

    def _floor_push(self, z: float) -> None:
        """Append ``z`` to the floor window and to its sorted copy (the running median costs
        O(window) list moves, not a sort of the window every frame)."""
        if len(self._floor_z) == self._floor_z.maxlen:
            old = self._floor_z[0]
            if old != old:
                self._floor_nan -= 1
            else:
                del self._floor_sorted[bisect.bisect_left(self._floor_sorted, old)]
        self._floor_z.append(z)
        if z != z:
            self._floor_nan += 1
        else:
            bisect.insort(self._floor_sorted, z)

    def _floor_quantile(self, q: float) -> float:
        """``np.quantile(self._floor_z, q)`` (the same value: its 'linear' method and its
        interpolation arithmetic, on the sorted window; NaN when the window holds one)."""
        if self._floor_nan:
            return float('nan')
        return sorted_quantile(self._floor_sorted, q)

    def _update_compiled(self, p, tracked, seg, seg_len, both, reference_lengths) -> np.ndarray:
        """:meth:`update`'s terms in one compiled call (reliability_kernels.plausibility_step:
        the arithmetic of _jump, the segment terms, _left_right and _floor)."""
        first = self._anchor is None
        if first:
            self._anchor = p.copy()
            self._anchor_ok = tracked.copy()
        has = self._last_rel is not None
        out_seg = np.empty(NUM_JOINTS)
        out_lr = np.empty(NUM_JOINTS)
        out_fl = np.empty(NUM_JOINTS)
        v = np.empty(NUM_JOINTS)
        flags = self._k_flags
        jump = K.plausibility_step(
            p, tracked, seg, seg_len, both, np.asarray(reference_lengths, float),
            self._anchor, self._anchor_ok, self._jumped_a, self.jump_m, self.jump_frames,
            self._jump_vel,
            not first, self._last_rel if has else seg, has, self._last_both, self._latch,
            self._last_bone, BLAME, PARENT_SEGMENT, self.bone_tolerance, self.bone_tolerance_m,
            self.bone_reject, self.max_step,
            self.latch_frames, self._held, TRANSIENT_FRAMES, self._latched_score(), self._k_lr,
            _GIRDLES, _ARMS, _LEGS, self.lr_flip,
            self.heading_rate, self.lr_unswap, self._k_ring, self._k_sorted, self._k_meta,
            self._k_floor, _FEET, _ANKLE_HEIGHT, FLOOR_STALE_FRAMES, self.floor_tolerance,
            self.floor_reject,
            FLOOR_QUANTILE, out_seg, out_lr, out_fl, v, flags)
        self.skeleton_outlier = jump
        if jump:
            return self._skeleton_jumped()
        self._last_rel = seg
        self._last_both = both
        if flags[1]:
            self.swapped = {'arms': bool(flags[2]), 'legs': bool(flags[3])}
        self.heading = float(self._k_lr[1])
        self.floor = float(self._k_floor[1]) if self._k_floor[0] else None
        self.terms = {'segments': out_seg, 'left_right': out_lr, 'floor': out_fl}
        self.value = v
        return v

    def update(self, positions: np.ndarray, tracking_state: np.ndarray,
               reference_lengths: np.ndarray, seg: Optional[np.ndarray] = None,
               seg_len: Optional[np.ndarray] = None) -> np.ndarray:
        """``R_p`` (20,) for one frame. ``reference_lengths`` (19,): the user's profile;
        ``seg`` (19, 3) / ``seg_len`` (19,): this frame's segment vectors and lengths if known."""
        if not self.enabled:
            return self.value
        p = np.ascontiguousarray(positions, dtype=float)   # one compiled layout
        tracked = np.asarray(tracking_state) == TRACKED
        if seg is None:
            seg = p[_SEG_C] - p[_SEG_P]
            seg_len = np.linalg.norm(seg, axis=1)
        both = tracked[_SEG_P] & tracked[_SEG_C]
        if self._jit:
            return self._update_compiled(p, tracked, seg, seg_len, both, reference_lengths)
        jump = self._jump(p, tracked)
        self.skeleton_outlier = jump
        if jump:
            return self._skeleton_jumped()
        if self._jit:
            has = self._last_rel is not None
            blamed = K.segment_terms(seg, seg_len, both, np.asarray(reference_lengths, float),
                                   self._last_rel if has else seg, has,
                                   self._last_both, self._latch, self._last_bone, BLAME,
                                   PARENT_SEGMENT,
                                   self.bone_tolerance,
                                   self.bone_tolerance_m, self.bone_reject, self.max_step,
                                   self.latch_frames, self._held, TRANSIENT_FRAMES,
                                   self._latched_score())
            self._last_rel = seg
            self._last_both = both
        else:
            bone = self._bones(seg_len, both, np.asarray(reference_lengths, float))
            seg_score = np.minimum(bone, self._speed(seg, both, bone))
            blamed = np.where(BLAME, seg_score[:, None], 1.0).min(axis=0)
        lr = self._left_right(p)
        fl = self._floor(p, tracked)
        self.terms = {'segments': blamed, 'left_right': lr, 'floor': fl}
        v = np.minimum(np.minimum(blamed, lr), fl)
        self.value = v
        return v
