"""Database completion, "method A" (Shum & Ho 2012, Sec. 5-6).

Offline: PCA of the database postures (60-D flattened joint positions, default 7 dimensions kept)
and the projection of every database posture. Per query: the sensor posture is normalised and
retargeted to the database's standard body, its missing or unreliable joints (reliability below
``reliable_threshold``) are replaced by the database mean (Sec. 5.2), it is projected, and the
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

import dataclasses
from dataclasses import dataclass
from typing import Optional

import numpy as np

from skeleton_core.geometry import NormalizeTransform, pca
from skeleton_core.model import NUM_JOINTS, PARENTS, ROOT, SPINE
from skeleton_core.params import check, param

from .posture_space import (PARENT_ROWS, QueryConfig, QueryPreparer, as_database_arrays,
                            fast_denormalize, heading_yaw, joint_set, orientations_to_sensor,
                            rest_directions)


@dataclass
class CompletionResult:
    positions: np.ndarray               # (20, 3) sensor frame
    orientations: Optional[np.ndarray]  # (20, 4) sensor frame, or None
    substituted: np.ndarray             # (20,) bool
    match_index: int
    match_distance: float               # squared distance in the reduced space


SUBSTITUTIONS = ('offset', 'absolute')


@dataclass
class CompletionConfig(QueryConfig):
    """Parameters of method A (:class:`PCACompletion`)."""

    pca_dims: int = param(7, 'PCA dimensions of the database search (Shum & Ho: 7 of 60)',
                          range=(1, 60), public=False)
    substitution: str = param('offset', 'offset: hang substituted joints off their parent with '
                              "the user's bone length; absolute: the match's position (paper)",
                              choices=SUBSTITUTIONS, public=False)


class PCACompletion:
    """Method A. ``complete(positions, reliability, user_height, ...)`` per frame. Parameters:
    :class:`CompletionConfig` fields as keywords (or ``config``)."""

    def __init__(self, db, config: Optional[CompletionConfig] = None, **params):
        cfg = dataclasses.replace(config or CompletionConfig(), **params)
        check(cfg)
        self.config = cfg
        pca_dims, substitution = cfg.pca_dims, cfg.substitution
        self.db = as_database_arrays(db)
        self.body = self.db.body
        self.reliable_threshold = float(cfg.reliable_threshold)
        self.substitution = substitution
        self.preparer = QueryPreparer(self.body, self.reliable_threshold)
        self._rest_dirs = rest_directions(self.body)
        self._standard_bones = self.body.bone_lengths_by_joint()
        self._match_dirs = match_directions(self.db, self._rest_dirs)
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
            mean, components, _ = pca(self.db.flat, self.pca_dims)
            projected = np.ascontiguousarray((self.db.flat - mean) @ components.T)
            projected_sq = np.einsum('nd,nd->n', projected, projected)
            # -2 x the projections, transposed, for the search: the distance is then one product
            # and one sum, and the (7, N) layout makes the product a plain matrix-vector one
            # (~2x faster than (N, 7) @ z; it sums each dot product in another order: distances
            # within ~1e-15)
            projected_m2 = np.ascontiguousarray(-2.0 * projected.T)
            for a in (mean, components, projected, projected_sq, projected_m2):
                a.setflags(write=False)
            arrays = self.db.derived[key] = (mean, components, projected, projected_sq,
                                             projected_m2)
        self.mean, self.components, self.projected, self._projected_sq, self._projected_m2 = \
            arrays
        self._mean_pose = self.mean.reshape(NUM_JOINTS, 3)

    def search(self, query_flat: np.ndarray) -> tuple:
        """Nearest database posture to a 60-D (already mean-filled) query in the reduced space."""
        return self._nearest(np.dot(self.components, query_flat - self.mean))

    def _nearest(self, z: np.ndarray) -> tuple:
        """(index, squared distance) of the database projection nearest to ``z``."""
        d = self._projected_sq + np.dot(z, self._projected_m2)  # + |z|^2, constant
        i = int(d.argmin())
        return i, max(float(d[i] + z @ z), 0.0)

    def complete(self, positions: np.ndarray, reliability: np.ndarray, user_height: float,
                 orientations: Optional[np.ndarray] = None,
                 user_bone_lengths: Optional[np.ndarray] = None) -> CompletionResult:
        # Everything here is a handful of rows: numpy's per-call overhead (~1 us) is the cost.
        # So the missing joints are a cached posture_space.JointSet (index array, row mask,
        # weights: no per-frame list conversion or comparison), rows are read with ``take`` and
        # set with ``np.copyto(where=)`` rather than fancy indexing, products use np.dot rather
        # than @ (the same BLAS call, less dispatch), and the few substituted joints are placed
        # with Python floats.
        p = np.asarray(positions, float)
        r = np.asarray(reliability, float)
        thr = self.reliable_threshold
        bits = 0
        for j, x in enumerate(r.tolist()):
            if not x >= thr:  # NaN counts as missing
                bits |= 1 << j
        ms = joint_set(bits)
        # normalise (heading from the reliable hip / shoulder joints) and retarget: what
        # ``self.preparer.prepare(p, ms.weights, user_height)`` does, keeping the rotation
        yaw = heading_yaw(p, ms.weights)
        q, t, rot, scale = self.preparer.prepare_rows(p, bits, user_height, yaw)
        # Shum & Ho 2012 Sec. 5.2: a missing joint takes the database mean, i.e. it adds
        # nothing to the projection (the same numbers as filling in the mean: mean - mean = 0)
        x = q - self._mean_pose
        if bits:
            np.copyto(x, 0.0, where=ms.column)
        idx, dist = self._nearest(np.dot(self.components, x.reshape(-1)))
        out = p.copy()
        if bits:
            match = self.db.positions[idx]
            if self.substitution == 'absolute':
                tf = NormalizeTransform(yaw=np.asarray(yaw), translation=t)
                np.copyto(out, fast_denormalize(match / scale, tf), where=ms.column)
            else:
                if user_bone_lengths is None:
                    bone = self._standard_bones.take(ms.index) / scale
                else:
                    bone = np.asarray(user_bone_lengths, float).take(ms.index)
                # the match's parent-relative directions of the missing joints, turned back by
                # the removed yaw and given the user's bone lengths
                world_off = np.dot(self._match_dirs[idx].take(ms.index, 0) * bone[:, None],
                                   rot.T)
                # each hangs off its parent's output position, parents first (the joint order
                # is a tree order); Python floats, as a numpy row operation costs ~1 us each
                placed = {}
                for j, o in zip(ms.rows, world_off.tolist()):
                    if j == ROOT and not (bits >> SPINE) & 1:
                        # root missing, the spine seen: the root hangs below the observed spine
                        # with the match's direction and the user's length (anchored at the
                        # tracked joint, not at a stale INFERRED hip centre)
                        ln = (self._standard_bones[SPINE] / scale if user_bone_lengths is None
                              else float(user_bone_lengths[SPINE]))
                        d = np.dot(self._match_dirs[idx][SPINE] * ln, rot.T)
                        row = (p[SPINE] - d).tolist()
                    elif j == ROOT:
                        # root missing: place it from the match relative to the observed hips'
                        # centre
                        tf = NormalizeTransform(yaw=np.asarray(yaw), translation=t)
                        row = fast_denormalize(match[:1] / scale, tf)[0].tolist()
                    else:
                        a = placed.get(PARENTS[j])
                        if a is None:
                            a = p[PARENTS[j]].tolist()
                        row = [a[0] + o[0], a[1] + o[1], a[2] + o[2]]
                    placed[j] = out[j] = row
        ori = None
        db_ori = self.db.orientations
        if db_ori is not None:
            # the match's rotations turned back by the removed yaw; not computed when no row of
            # them is used
            if orientations is None:
                ori = orientations_to_sensor(db_ori[idx], yaw)
            else:
                ori = np.array(orientations, float)
                if bits:
                    np.copyto(ori, orientations_to_sensor(db_ori[idx], yaw), where=ms.column)
        elif orientations is not None:
            ori = np.array(orientations, float)
        return CompletionResult(positions=out, orientations=ori, substituted=ms.mask.copy(),
                                match_index=idx, match_distance=dist)


def match_directions(db, rest_dirs: np.ndarray) -> np.ndarray:
    """(N, 20, 3) unit parent-relative directions of every database posture (the rest direction
    where a joint sits on its parent; the root's row is its rest direction): what the offset
    substitution reads from the match, computed once per database and shared read-only."""
    dirs = db.derived.get('completion_dirs')
    if dirs is None:
        rel = db.positions - db.positions[:, PARENT_ROWS]
        n = np.sqrt(np.einsum('njk,njk->nj', rel, rel))[..., None]
        dirs = np.where(n > 1e-9, rel / np.maximum(n, 1e-12), rest_dirs)
        dirs.setflags(write=False)
        db.derived['completion_dirs'] = dirs
    return dirs
