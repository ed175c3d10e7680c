"""Posture geometry shared by the database, the reconstruction and the evaluation.

* :func:`normalize` / :func:`denormalize` — remove (and restore) the global translation and the
  rotation about the vertical axis (Shum & Ho 2012, Sec. 5; Shum et al. 2013, Sec. V-A).
* :func:`retarget` — Shum & Ho 2012, Eq. 3-4: keep every segment's direction, impose the target
  body's segment lengths, from the root down the hierarchy.
* quaternion helpers (x, y, z, w order, as geometry_msgs), including a proper weighted average.

All functions take (..., 20, 3) arrays in REP-103 (z up) and work on batches.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .model import (HIP_LEFT, HIP_RIGHT, NUM_JOINTS, PARENTS, ROOT, SEGMENT_CHILD_INDEX,
                    SHOULDER_LEFT, SHOULDER_RIGHT, Body, forward_kinematics)

_PARENT_OR_SELF = [p if p >= 0 else j for j, p in enumerate(PARENTS)]  # the root's own row: d = 0


@dataclass
class NormalizeTransform:
    """What :func:`normalize` removed: yaw (rad, about +z) and root translation (m)."""

    yaw: np.ndarray          # (...)
    translation: np.ndarray  # (..., 3)


def yaw_matrix(yaw) -> np.ndarray:
    """Rotation matrices about +z by ``yaw`` (rad): (3, 3) for a scalar, (..., 3, 3) for an
    array. ``x @ R.T`` turns rows of ``x`` by ``yaw``, ``x @ R`` by ``-yaw``. A scalar's is built
    from a flat list (a nested one, or the batched stacking, costs several times as much)."""
    if isinstance(yaw, float) or np.ndim(yaw) == 0:   # (a float, np.float64 too: no dispatch)
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0]).reshape(3, 3)
    c, s = np.cos(yaw), np.sin(yaw)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1),
                     np.stack([z, z, o], -1)], -2)


def facing_yaw(positions: np.ndarray, weights: Optional[np.ndarray] = None) -> np.ndarray:
    """Heading (rad) of a body from its hip and shoulder lines: 0 when facing +x.

    ``weights`` (..., 20) in [0, 1] down-weight unreliable joints (a pair counts with the smaller
    weight of its two joints); when both lines are unusable the heading is 0.
    """
    p = np.asarray(positions, dtype=float)
    hips = p[..., HIP_LEFT, :] - p[..., HIP_RIGHT, :]
    shoulders = p[..., SHOULDER_LEFT, :] - p[..., SHOULDER_RIGHT, :]
    if weights is None:
        wh = ws = 1.0
    else:
        w = np.asarray(weights, dtype=float)
        wh = np.minimum(w[..., HIP_LEFT], w[..., HIP_RIGHT])[..., None]
        ws = np.minimum(w[..., SHOULDER_LEFT], w[..., SHOULDER_RIGHT])[..., None]
    left = wh * hips + ws * shoulders
    # left-pointing vector -> forward = left rotated by -90 deg about z
    fx, fy = left[..., 1], -left[..., 0]
    return np.arctan2(fy, fx)


def normalize(positions: np.ndarray, weights: Optional[np.ndarray] = None):
    """Move the root to the origin and turn the body to face +x.

    Returns ``(normalized, transform)``; ``denormalize(normalized, transform)`` gives the input back.
    """
    p = np.asarray(positions, dtype=float)
    yaw = facing_yaw(p, weights)
    t = p[..., ROOT, :].copy()
    r_inv = yaw_matrix(-yaw)  # (..., 3, 3)
    out = np.einsum('...ij,...kj->...ki', r_inv, p - t[..., None, :])
    return out, NormalizeTransform(yaw=yaw, translation=t)


def denormalize(normalized: np.ndarray, transform: NormalizeTransform) -> np.ndarray:
    """Inverse of :func:`normalize`."""
    r = yaw_matrix(transform.yaw)
    return np.einsum('...ij,...kj->...ki', r, np.asarray(normalized, float)) + \
        transform.translation[..., None, :]


def retarget(positions: np.ndarray, body: Body,
             lengths: Optional[np.ndarray] = None) -> np.ndarray:
    """Shum & Ho 2012 Eq. 3-4: ``P'_i = P'_j + L(i, j) (P_i - P_j) / |P_i - P_j|`` from the root down.

    ``lengths`` (19,) overrides the body's segment lengths (e.g. a user's own). A zero-length
    segment takes the direction of the standard T-pose.
    """
    seg_len = body.segment_lengths if lengths is None else np.asarray(lengths, float)
    bone = np.zeros(NUM_JOINTS)
    bone[SEGMENT_CHILD_INDEX] = seg_len
    rest_dir = body.rest_offsets / np.maximum(np.linalg.norm(body.rest_offsets, axis=1), 1e-12)[:, None]
    return retarget_by_joint(positions, bone, rest_dir)


def retarget_by_joint(positions: np.ndarray, bone: np.ndarray, rest_dirs: np.ndarray) -> np.ndarray:
    """:func:`retarget` with the lengths given per joint: ``bone`` (20,) the length of the segment
    ending at each joint (0 for the root), ``rest_dirs`` (20, 3) the direction a zero-length
    segment takes. One posture or a batch (..., 20, 3), with one ``bone`` / ``rest_dirs`` for all
    or one per posture (..., 20) / (..., 20, 3)."""
    p = np.asarray(positions, dtype=float)
    d = p - p[..., _PARENT_OR_SELF, :]
    n = np.sqrt(np.sum(d * d, axis=-1, keepdims=True))
    unit = np.where(n > 1e-9, d / np.maximum(n, 1e-12), rest_dirs)
    return forward_kinematics(np.asarray(bone, float)[..., None] * unit, p[..., ROOT, :])


# ---------------------------------------------------------------------------------------------
# Quaternions (x, y, z, w)
# ---------------------------------------------------------------------------------------------
def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = np.moveaxis(np.asarray(a, float), -1, 0)
    bx, by, bz, bw = np.moveaxis(np.asarray(b, float), -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], -1)


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    q = np.array(q, dtype=float)
    q[..., :3] *= -1.0
    return q


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` (..., 3) by unit quaternions ``q`` (..., 4)."""
    q = np.asarray(q, float)
    u, w = q[..., :3], q[..., 3:4]
    v = np.asarray(v, float)
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_from_yaw(yaw: np.ndarray) -> np.ndarray:
    yaw = np.asarray(yaw, float)
    z = np.zeros_like(yaw)
    return np.stack([z, z, np.sin(yaw / 2), np.cos(yaw / 2)], -1)


def quat_average(quats: np.ndarray, weights: Optional[np.ndarray] = None) -> np.ndarray:
    """Weighted average of unit quaternions along axis -2 (Markley et al. 2007: the principal
    eigenvector of sum w q q^T), sign-invariant. ``quats`` (..., K, 4), ``weights`` (..., K)."""
    q = np.asarray(quats, float)
    w = np.ones(q.shape[:-1]) if weights is None else np.asarray(weights, float)
    m = np.swapaxes(q * w[..., None], -1, -2) @ q           # sum_k w_k q_k q_k^T (..., 4, 4)
    _, vecs = np.linalg.eigh(m)
    avg = vecs[..., :, -1]
    # deterministic sign: w >= 0
    return avg * np.where(avg[..., 3:4] < 0, -1.0, 1.0)


def swing_twist(q: np.ndarray, axis: np.ndarray):
    """Split rotations ``q`` (..., 4) into swing * twist, twist about unit ``axis`` (..., 3).

    Returns ``(swing, twist_angle)``, twist angle in (-pi, pi].
    """
    q = np.asarray(q, float)
    a = np.asarray(axis, float)
    proj = np.sum(q[..., :3] * a, axis=-1)
    angle = 2.0 * np.arctan2(proj, q[..., 3])
    angle = (angle + np.pi) % (2 * np.pi) - np.pi
    half = angle / 2.0
    twist = np.concatenate([a * np.sin(half)[..., None], np.cos(half)[..., None]], -1)
    swing = quat_multiply(q, quat_conjugate(twist))
    return swing, angle


def pca(x: np.ndarray, dims: int, center: bool = True):
    """Principal components of the rows of ``x`` (N, D): ``(mean (D,), axes (m, D), variances
    (m,))`` with m = min(dims, rank bound), the axes orthonormal rows sorted by decreasing
    variance, the variances the sample variances along them (s^2 / (N - 1)). ``center=False``:
    about the origin (mean zeros)."""
    x = np.asarray(x, float)
    mean = x.mean(axis=0) if center else np.zeros(x.shape[1])
    _, s, vt = np.linalg.svd(x - mean, full_matrices=False)
    m = int(min(dims, vt.shape[0]))
    return mean, vt[:m].copy(), s[:m] ** 2 / max(len(x) - 1, 1)
