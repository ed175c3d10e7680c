"""Database completion, "method A" (Shum & Ho 2012, Sec. 5-6).

Offline: PCA of the database postures (60-D flattened joint positions, default 7 dimensions kept)
and the projection of every database posture. Per query: the sensor posture is normalised and
retargeted to the database's standard body, its missing or unreliable joints (reliability below
``reliability_threshold``) are replaced by the database mean (Sec. 5.2), it is projected, and the
nearest database posture by squared distance in the reduced space is taken. Missing / unreliable
joints and their rotations (Theta) are then substituted from the match (Sec. 6.1-6.2) and the
result goes back to the sensor frame.

``substitution``:
* ``'offset'`` (default): a substituted joint hangs off its (output) parent with the match's
  parent-relative direction and the user's bone length, so a missing hand stays attached to the
  observed wrist whatever the user's size;
* ``'absolute'``: the paper's literal substitution of the match's position (normalised space,
  scaled to the user's height, then back to the sensor frame).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from skeleton_core.model import NUM_JOINTS, PARENTS

from .posture_space import (PARENT_ROWS, QueryPreparer, as_database_arrays, fast_denormalize,
                            orientations_to_sensor, rest_directions)


def pca_basis(flat: np.ndarray, dims: int):
    """Mean (60,) and the first ``dims`` principal axes (dims, 60) of the rows of ``flat``."""
    mean = flat.mean(axis=0)
    _, s, vt = np.linalg.svd(flat - mean, full_matrices=False)
    dims = int(min(dims, vt.shape[0]))
    return mean, vt[:dims], s[:dims]


@dataclass
class CompletionResult:
    positions: np.ndarray               # (20, 3) sensor frame
    orientations: Optional[np.ndarray]  # (20, 4) sensor frame, or None
    substituted: np.ndarray             # (20,) bool
    match_index: int
    match_distance: float               # squared distance in the reduced space


class PCACompletion:
    """Method A. ``complete(positions, reliability, user_height, ...)`` per frame."""

    def __init__(self, db, pca_dims: int = 7, reliability_threshold: float = 0.5,
                 substitution: str = 'offset'):
        if substitution not in ('offset', 'absolute'):
            raise ValueError("substitution must be 'offset' or 'absolute'")
        self.db = as_database_arrays(db)
        self.body = self.db.body
        self.reliability_threshold = float(reliability_threshold)
        self.substitution = substitution
        self.preparer = QueryPreparer(self.body, reliability_threshold)
        self._rest_dirs = rest_directions(self.body)
        self._standard_bones = self.body.bone_lengths_by_joint()
        self.set_dims(pca_dims)

    def set_dims(self, pca_dims: int) -> None:
        if pca_dims < 1:
            raise ValueError('pca_dims must be >= 1')
        self.pca_dims = int(pca_dims)
        # the database's PCA basis and projections, computed once per database and dimension
        # count and shared read-only (a new user costs no SVD of the database)
        key = ('completion_pca', self.pca_dims)
        arrays = self.db.derived.get(key)
        if arrays is None:
            mean, components, _ = pca_basis(self.db.flat, self.pca_dims)
            projected = np.ascontiguousarray((self.db.flat - mean) @ components.T)
            projected_sq = np.einsum('nd,nd->n', projected, projected)
            for a in (mean, components, projected, projected_sq):
                a.setflags(write=False)
            arrays = self.db.derived[key] = (mean, components, projected, projected_sq)
        self.mean, self.components, self.projected, self._projected_sq = arrays
        self._mean_pose = self.mean.reshape(NUM_JOINTS, 3)

    def search(self, query_flat: np.ndarray) -> tuple:
        """Nearest database posture to a 60-D (already mean-filled) query in the reduced space."""
        z = self.components @ (query_flat - self.mean)
        d = self._projected_sq - 2.0 * (self.projected @ z)  # + |z|^2, constant
        i = int(np.argmin(d))
        return i, max(float(d[i] + z @ z), 0.0)

    def complete(self, positions: np.ndarray, reliability: np.ndarray, user_height: float,
                 orientations: Optional[np.ndarray] = None,
                 user_bone_lengths: Optional[np.ndarray] = None) -> CompletionResult:
        p = np.asarray(positions, float)
        r = np.asarray(reliability, float)
        missing = ~(r >= self.reliability_threshold)  # NaN counts as missing
        prep = self.preparer.prepare(p, (~missing).astype(float), user_height)
        q = prep.query  # a new array of prepare's
        q[missing] = self._mean_pose[missing]  # Shum & Ho 2012 Sec. 5.2
        idx, dist = self.search(q.reshape(-1))
        match = self.db.positions[idx]
        out = p.copy()
        miss = np.flatnonzero(missing).tolist()
        yaw = float(prep.transform.yaw)
        if miss:
            if self.substitution == 'absolute':
                full = fast_denormalize(match / prep.scale, prep.transform)
                out[missing] = full[missing]
            else:
                if user_bone_lengths is None:
                    bone = self._standard_bones / prep.scale
                else:
                    bone = np.asarray(user_bone_lengths, float)
                # the match's parent-relative directions of the missing joints, turned back by
                # the removed yaw and given the user's bone lengths
                rel = match[miss] - match[PARENT_ROWS[miss]]
                n = np.sqrt(np.einsum('jk,jk->j', rel, rel))[:, None]
                unit = np.where(n > 1e-9, rel / np.maximum(n, 1e-12), self._rest_dirs[miss])
                c, s = math.cos(yaw), math.sin(yaw)
                off = unit * bone[miss][:, None]
                world_off = off @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
                for k, j in enumerate(miss):  # parents first (the joint order is a tree order)
                    if j == 0:
                        # root missing: place it from the match relative to the observed hips'
                        # centre
                        out[0] = fast_denormalize(match[:1] / prep.scale, prep.transform)[0]
                    else:
                        out[j] = out[PARENTS[j]] + world_off[k]
        ori = None
        if self.db.orientations is not None:
            db_q = orientations_to_sensor(self.db.orientations[idx], yaw)
            if orientations is None:
                ori = db_q
            else:
                ori = np.array(orientations, float)
                ori[missing] = db_q[missing]
        elif orientations is not None:
            ori = np.array(orientations, float)
        return CompletionResult(positions=out, orientations=ori, substituted=missing,
                                match_index=idx, match_distance=dist)
