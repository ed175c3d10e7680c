"""Synthetic postures and clips for tests and benchmarks (no data files needed).

Postures are built from a few joint angles (trunk lean, shoulder flexion/abduction, elbow flexion,
hip flexion/abduction, knee flexion) applied to the standard body, so every posture has exact
standard segment lengths. :func:`random_database` gives a database-like object,
:func:`smooth_clip` a 30 Hz motion with its ground truth in a sensor frame, and
:func:`corrupt_clip` the Kinect-like failures the reliability measure is meant to catch
(vibrating joints, a limb snapping onto the body while occluded, inferred/not-tracked states).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np

from skeleton_core.geometry import normalize
from skeleton_core.model import (ANKLE_LEFT, ANKLE_RIGHT, ELBOW_LEFT, ELBOW_RIGHT, FOOT_LEFT,
                                 FOOT_RIGHT, HAND_LEFT, HAND_RIGHT, HEAD, HIP_LEFT, HIP_RIGHT,
                                 INFERRED, KNEE_LEFT, KNEE_RIGHT, NUM_JOINTS, PARENTS,
                                 SHOULDER_CENTER, SHOULDER_LEFT, SHOULDER_RIGHT, SPINE, TRACKED,
                                 WRIST_LEFT, WRIST_RIGHT, Body, standard_body)

# Angle vector layout (radians): ranges used for random sampling
ANGLE_NAMES = ('trunk_flex', 'trunk_side', 'trunk_twist',
               'l_sh_flex', 'l_sh_abd', 'l_elbow', 'r_sh_flex', 'r_sh_abd', 'r_elbow',
               'l_hip_flex', 'l_hip_abd', 'l_knee', 'r_hip_flex', 'r_hip_abd', 'r_knee')
ANGLE_RANGES = np.radians(np.array([
    (-10, 35), (-12, 12), (-25, 25),
    (-40, 170), (0, 110), (0, 140), (-40, 170), (0, 110), (0, 140),
    (-25, 95), (0, 35), (0, 120), (-25, 95), (0, 35), (0, 120)]))


def _rot(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) about unit ``axis`` (..., 3) by ``angle`` (...) (Rodrigues)."""
    axis = np.broadcast_to(axis, np.shape(angle) + (3,))
    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    c, s = np.cos(angle), np.sin(angle)
    C = 1 - c
    return np.stack([np.stack([c + x * x * C, x * y * C - z * s, x * z * C + y * s], -1),
                     np.stack([y * x * C + z * s, c + y * y * C, y * z * C - x * s], -1),
                     np.stack([z * x * C - y * s, z * y * C + x * s, c + z * z * C], -1)], -2)


def _apply(R, v):
    return np.einsum('...ij,...j->...i', R, v)


def postures_from_angles(angles: np.ndarray, body: Optional[Body] = None) -> np.ndarray:
    """(..., 15) joint angles -> (..., 20, 3) positions, root at the origin, facing +x."""
    body = body or standard_body()
    a = np.asarray(angles, float)
    L = body.bone_lengths_by_joint()
    X, Y, Z = np.eye(3)
    up, down = Z, -Z
    shape = a.shape[:-1]
    dirs = np.zeros(shape + (NUM_JOINTS, 3))
    # trunk: flex (forward lean) about +y, side lean about +x, twist about the trunk axis
    R_t = _rot(Y, a[..., 0]) @ _rot(X, a[..., 1])
    trunk_up = _apply(R_t, up)
    R_tw = _rot(trunk_up, a[..., 2]) @ R_t
    dirs[..., SPINE, :] = trunk_up
    dirs[..., SHOULDER_CENTER, :] = trunk_up
    dirs[..., HEAD, :] = _apply(_rot(Y, 0.5 * a[..., 0]) @ R_tw, up)
    for side, sign, i0 in (('l', 1.0, 3), ('r', -1.0, 6)):
        sh = SHOULDER_LEFT if side == 'l' else SHOULDER_RIGHT
        el, wr, ha = ((ELBOW_LEFT, WRIST_LEFT, HAND_LEFT) if side == 'l'
                      else (ELBOW_RIGHT, WRIST_RIGHT, HAND_RIGHT))
        dirs[..., sh, :] = _apply(R_tw, sign * Y)
        # upper arm: from hanging down, abduct (about +-x) then flex forward (about -y)
        R_arm = R_tw @ _rot(-Y, a[..., i0]) @ _rot(sign * X, a[..., i0 + 1])
        upper = _apply(R_arm, down)
        # elbow flexion bends the forearm towards the front of the upper arm
        fore = _apply(R_arm @ _rot(-Y, a[..., i0 + 2]), down)
        dirs[..., el, :] = upper
        dirs[..., wr, :] = fore
        dirs[..., ha, :] = fore
    for side, sign, i0 in (('l', 1.0, 9), ('r', -1.0, 12)):
        hp, kn, an, ft = ((HIP_LEFT, KNEE_LEFT, ANKLE_LEFT, FOOT_LEFT) if side == 'l'
                          else (HIP_RIGHT, KNEE_RIGHT, ANKLE_RIGHT, FOOT_RIGHT))
        dirs[..., hp, :] = sign * Y
        R_leg = _rot(-Y, a[..., i0]) @ _rot(sign * X, a[..., i0 + 1])
        thigh = _apply(R_leg, down)
        R_shank = R_leg @ _rot(Y, a[..., i0 + 2])
        dirs[..., kn, :] = thigh
        dirs[..., an, :] = _apply(R_shank, down)
        foot_rest = body.rest_offsets[ft] / np.linalg.norm(body.rest_offsets[ft])
        dirs[..., ft, :] = _apply(R_shank, foot_rest)
    pos = np.zeros(shape + (NUM_JOINTS, 3))
    for j in range(1, NUM_JOINTS):
        pos[..., j, :] = pos[..., PARENTS[j], :] + L[j] * dirs[..., j, :]
    return pos


def segment_orientations(positions: np.ndarray, body: Optional[Body] = None) -> np.ndarray:
    """(..., 20, 4) swing quaternion taking each joint's rest direction to its current one
    (identity for the root): a stand-in for a database's joint orientations."""
    body = body or standard_body()
    p = np.asarray(positions, float)
    par = np.array([max(q, 0) for q in PARENTS])
    d = p - p[..., par, :]
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    u = d / np.maximum(n, 1e-12)
    r = body.rest_offsets / np.maximum(np.linalg.norm(body.rest_offsets, axis=1, keepdims=True),
                                       1e-12)
    cross = np.cross(r, u)
    dot = np.sum(r * u, axis=-1, keepdims=True)
    q = np.concatenate([cross, 1.0 + dot], axis=-1)
    q /= np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-12)
    q[..., 0, :] = (0.0, 0.0, 0.0, 1.0)
    return q


@dataclass
class SyntheticDatabase:
    """Same attributes as skeleton_data.database.MotionDatabase uses here."""

    positions: np.ndarray     # (N, 20, 3)
    orientations: np.ndarray  # (N, 20, 4)
    twists: np.ndarray        # (N, 19)

    @property
    def flat(self) -> np.ndarray:
        return self.positions.reshape(len(self.positions), -1)


def random_angles(n: int, rng: np.random.Generator) -> np.ndarray:
    lo, hi = ANGLE_RANGES[:, 0], ANGLE_RANGES[:, 1]
    return lo + (hi - lo) * rng.random((n, len(ANGLE_NAMES)))


def random_database(n: int = 3000, seed: int = 0, include: Optional[np.ndarray] = None
                    ) -> SyntheticDatabase:
    """``n`` random postures (plus the optional angle rows ``include``)."""
    rng = np.random.default_rng(seed)
    ang = random_angles(n, rng)
    if include is not None:
        ang = np.concatenate([ang, include.reshape(-1, len(ANGLE_NAMES))])
    pos, _ = normalize(postures_from_angles(ang))  # facing +x as the real database is
    pos = pos.astype(np.float32)
    return SyntheticDatabase(positions=pos, orientations=segment_orientations(pos),
                             twists=np.zeros((len(pos), NUM_JOINTS - 1), np.float32))


def smooth_angles(frames: int, rng: np.random.Generator, fps: float = 30.0) -> np.ndarray:
    """(frames, 15) smooth angle trajectories: a sum of two slow sinusoids per angle, in range."""
    t = np.arange(frames) / fps
    lo, hi = ANGLE_RANGES[:, 0], ANGLE_RANGES[:, 1]
    mid, amp = 0.5 * (lo + hi), 0.5 * (hi - lo)
    f1 = rng.uniform(0.15, 0.5, len(lo))
    f2 = rng.uniform(0.5, 1.0, len(lo))
    ph = rng.uniform(0, 2 * np.pi, (2, len(lo)))
    s = 0.7 * np.sin(2 * np.pi * f1 * t[:, None] + ph[0]) + 0.3 * np.sin(2 * np.pi * f2 * t[:, None] + ph[1])
    return mid + 0.9 * amp * s


def smooth_clip(frames: int = 150, seed: int = 1, height: float = 1.75, yaw: float = 0.6,
                translation=(2.5, 0.3, 0.0)) -> Tuple[np.ndarray, np.ndarray]:
    """A smooth motion of a user of ``height`` standing in front of the sensor.

    Returns ``(angles (T, 15), positions (T, 20, 3))`` in the sensor frame (REP-103).
    """
    rng = np.random.default_rng(seed)
    ang = smooth_angles(frames, rng)
    body = standard_body(height)
    p = postures_from_angles(ang, body)
    R = _rot(np.array([0.0, 0.0, 1.0]), np.asarray(yaw))
    p = np.einsum('ij,tkj->tki', R, p) + np.asarray(translation, float) + \
        np.array([0.0, 0.0, body.root_height])
    return ang, p


def corrupt_clip(truth: np.ndarray, seed: int = 2, noise: float = 0.01,
                 vibrate: Tuple[int, ...] = (HAND_RIGHT, WRIST_RIGHT), vibrate_amp: float = 0.08,
                 occlude: Tuple[int, ...] = (ELBOW_LEFT, WRIST_LEFT, HAND_LEFT),
                 occlude_span: Tuple[float, float] = (0.3, 0.8)
                 ) -> Tuple[np.ndarray, np.ndarray]:
    """Kinect-like corruption of a clip (T, 20, 3): every joint gets ``noise`` (m) Gaussian noise;
    ``vibrate`` joints jump back and forth by ``vibrate_amp`` around the truth (still reported as
    TRACKED: only the behaviour term can catch them) over the whole clip; during the
    ``occlude_span`` fraction of the clip the ``occlude`` joints snap onto the spine (as Kinect
    does when a limb is hidden behind the body) and are reported INFERRED.

    Returns ``(observed (T, 20, 3), tracking_state (T, 20) uint8)``.
    """
    rng = np.random.default_rng(seed)
    T = len(truth)
    obs = truth + rng.normal(0.0, noise, truth.shape)
    ts = np.full((T, NUM_JOINTS), TRACKED, np.uint8)
    sign = np.where(np.arange(T) % 2 == 0, 1.0, -1.0)
    for j in vibrate:
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        obs[:, j] += vibrate_amp * sign[:, None] * direction
    a, b = int(occlude_span[0] * T), int(occlude_span[1] * T)
    for k, j in enumerate(occlude):
        obs[a:b, j] = truth[a:b, SPINE] + np.array([0.12, 0.05 * (k + 1), 0.02 * k]) + \
            rng.normal(0.0, noise, (b - a, 3))
        ts[a:b, j] = INFERRED
    return obs, ts


def performances(angles: np.ndarray, count: int, seed: int = 7, jitter_deg: float = 8.0
                 ) -> np.ndarray:
    """``count`` other performances of the motion ``angles`` (T, 15): time-warped (0.8-1.2x,
    shifted) with a constant per-performance angle offset of ``jitter_deg`` standard deviation.
    A database holding them contains the kind of motion the user performs (Sec. V-A)."""
    rng = np.random.default_rng(seed)
    T = len(angles)
    out = []
    for _ in range(count):
        t = np.clip(np.arange(T) * rng.uniform(0.8, 1.2) + rng.uniform(-10, 10), 0, T - 1)
        a = np.stack([np.interp(t, np.arange(T), angles[:, k]) for k in range(angles.shape[1])], 1)
        out.append(a + rng.normal(0.0, np.radians(jitter_deg), angles.shape[1]))
    return np.concatenate(out)


def scenario(frames: int = 150, n_random: int = 2000, n_perf: int = 8, seed: int = 1,
             height: float = 1.65):
    """A ready-made test case: ``(db, truth (T, 20, 3), observed, tracking_state)``."""
    ang, truth = smooth_clip(frames, seed=seed, height=height)
    db = random_database(n_random, seed=seed + 100, include=performances(ang, n_perf, seed + 6))
    obs, ts = corrupt_clip(truth, seed=seed + 1)
    return db, truth, obs, ts
