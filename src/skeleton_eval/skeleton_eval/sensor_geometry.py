"""Geometry of the sensor model's corrupter: lines of sight (2-D point-segment distances, rays
through the scenario's object), which body segments can hide which joint, angle wrapping and
sub-frame time shifts."""
from __future__ import annotations

import numpy as np

from skeleton_core.model import CHILDREN, NUM_JOINTS, PARENTS, SEGMENT_CHILDREN, SEGMENT_PARENTS


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi

def _point_segment_2d(p, a, b):
    """Distance and parameter of 2-D points p (J,2) to segments a-b (S,2) -> (J,S)."""
    ab = b - a                                     # (S,2)
    ap = p[:, None, :] - a[None, :, :]             # (J,S,2)
    den = np.maximum((ab * ab).sum(-1), 1e-12)     # (S,)
    t = np.clip((ap * ab[None]).sum(-1) / den[None], 0.0, 1.0)
    d = np.linalg.norm(ap - t[..., None] * ab[None], axis=-1)
    return d, t


def _ray_box(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Does the segment from the sensor origin to each point (J,3) pass through the box?"""
    p = np.asarray(points, float)
    with np.errstate(divide='ignore', invalid='ignore'):
        inv = 1.0 / p
        t1 = lo[None] * inv
        t2 = hi[None] * inv
    tmin = np.nanmax(np.where(np.isfinite(np.minimum(t1, t2)), np.minimum(t1, t2), -np.inf), axis=1)
    tmax = np.nanmin(np.where(np.isfinite(np.maximum(t1, t2)), np.maximum(t1, t2), np.inf), axis=1)
    return (tmax >= np.maximum(tmin, 0.0)) & (tmin < 1.0)


def _box_distance(points: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    closest = np.clip(points, lo[None], hi[None])
    return np.linalg.norm(points - closest, axis=1), closest


def _occludable() -> np.ndarray:
    """(20, 19) mask: a joint is never hidden by a segment touching it or its tree neighbours."""
    m = np.ones((NUM_JOINTS, len(SEGMENT_CHILDREN)), bool)
    for j in range(NUM_JOINTS):
        near = {j, PARENTS[j], *CHILDREN[j]}
        for s in range(len(SEGMENT_CHILDREN)):
            if SEGMENT_CHILDREN[s] in near or SEGMENT_PARENTS[s] in near:
                m[j, s] = False
    return m


_OCCLUDABLE = _occludable()


def _shifted(positions: np.ndarray, frames: float) -> np.ndarray:
    """(T, J, 3) positions at frame times ``i + frames`` (linear; the ends held)."""
    t = np.clip(np.arange(len(positions)) + frames, 0, len(positions) - 1)
    i0 = np.floor(t).astype(int)
    i1 = np.minimum(i0 + 1, len(positions) - 1)
    w = (t - i0)[:, None, None]
    return positions[i0] * (1 - w) + positions[i1] * w
