"""Method A: PCA database completion (Shum & Ho 2012, Sec. 5-6)."""
import numpy as np
import pytest

from pose_reconstruction.completion import PCACompletion
from pose_reconstruction.reconstructor import Reconstructor
from pose_reconstruction.synthetic import random_database, smooth_angles, smooth_clip
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.geometry import denormalize, NormalizeTransform, pca
from skeleton_core.model import LIMB_JOINTS, NUM_JOINTS, TRACKED, standard_body


@pytest.fixture(scope='module')
def db():
    return random_database(1500, seed=3)


def place(p, yaw=0.8, t=(2.0, -0.4, 0.9)):
    return denormalize(p, NormalizeTransform(yaw=np.asarray(yaw), translation=np.asarray(t)))


def test_pca_orthonormal_and_default_dims(db):
    c = PCACompletion(db)
    assert c.components.shape == (7, 60)
    assert np.allclose(c.components @ c.components.T, np.eye(7), atol=1e-9)
    mean, comps, var = pca(np.asarray(db.flat, float), 60)
    assert np.all(np.diff(var) <= 1e-9)  # sorted by variance


def test_completion_recovers_database_posture_with_missing_limb():
    # a database of one motion (correlated joints, as real motion is): 7 PCA dimensions hold it
    db = random_database(0, include=smooth_angles(400, np.random.default_rng(11)))
    c = PCACompletion(db, pca_dims=7)
    i = 123
    truth = place(np.asarray(db.positions[i], float))
    obs = truth.copy()
    missing = list(LIMB_JOINTS['left_arm'][1:])  # elbow, wrist, hand lost
    obs[missing] = truth[0] + 5.0 * np.random.default_rng(0).normal(size=(3, 3))  # garbage
    rel = np.ones(NUM_JOINTS)
    rel[missing] = 0.0
    res = c.complete(obs, rel, standard_body().height)
    assert res.match_index == i
    assert np.array_equal(res.substituted, rel < 0.5)
    # the observed joints are untouched, the missing limb comes back from the database posture
    keep = rel >= 0.5
    assert np.allclose(res.positions[keep], obs[keep])
    assert np.allclose(res.positions[missing], truth[missing], atol=1e-5)
    # rotations of the substituted joints come from the match, turned into the sensor frame
    assert res.orientations is not None and res.orientations.shape == (NUM_JOINTS, 4)
    # paper-literal substitution gives the same result for a standard-size user
    res2 = PCACompletion(db, substitution='absolute').complete(obs, rel, standard_body().height)
    assert np.allclose(res2.positions[missing], truth[missing], atol=1e-5)
    # a missing root is placed from the match; the missing joints below it hang off it
    rel[0] = 0.0
    res3 = c.complete(truth, rel, standard_body().height)
    assert res3.match_index == i and res3.substituted[0]
    assert np.allclose(res3.positions, truth, atol=1e-5)


def test_missing_joints_are_mean_filled_before_projection(db):
    c = PCACompletion(db, pca_dims=7)
    q = np.asarray(db.positions[5], float).copy()
    q_far = q.copy()
    q_far[list(LIMB_JOINTS['right_leg'])[1:]] += 3.0
    rel = np.ones(NUM_JOINTS)
    rel[list(LIMB_JOINTS['right_leg'])[1:]] = 0.0
    # garbage in the missing joints must not change the match
    a = c.complete(place(q), rel, 1.75).match_index
    b = c.complete(place(q_far), rel, 1.75).match_index
    assert a == b


def test_reconstructor_method_a_streams_and_preserves_header(db):
    _, clip = smooth_clip(10, seed=4)
    r = Reconstructor(db, method='A')
    for t, p in enumerate(clip):
        ts = np.full(NUM_JOINTS, TRACKED, np.uint8)
        f = SkeletonFrame(positions=p, tracking_state=ts, user_id=7, stamp_ns=1000 + t,
                          frame_id='kinect')
        out = r.process(f)
        assert (out.user_id, out.stamp_ns, out.frame_id) == (7, 1000 + t, 'kinect')
        assert out.reliability.shape == (NUM_JOINTS,) and np.all(np.isfinite(out.reliability))
    # everything tracked and steady -> nothing substituted
    assert not r.last_result.substituted.any()
    assert np.allclose(out.positions, clip[-1])


def test_fast_helpers_match_geometry_and_model():
    from pose_reconstruction.posture_space import (fast_denormalize, fast_normalize,
                                                   fast_retarget, rest_directions)
    from skeleton_core.geometry import normalize, retarget
    rng = np.random.default_rng(2)
    body = standard_body()
    p = place(body.rest_positions() + rng.normal(0, 0.05, (NUM_JOINTS, 3)), yaw=2.5)
    w = rng.random(NUM_JOINTS)
    a, ta = normalize(p, w)
    b, tb = fast_normalize(p, w)
    assert np.allclose(a, b) and np.isclose(float(ta.yaw), float(tb.yaw))
    assert np.allclose(fast_denormalize(b, tb), p)
    assert np.allclose(fast_retarget(a, body.bone_lengths_by_joint(), rest_directions(body)),
                       retarget(a, body))



def reference_complete(c, p, rel, height, orientations=None, bones=None):
    """Method A written the straightforward way (geometry.normalize / retarget, brute-force
    distances in the reduced space, one joint at a time): what PCACompletion.complete's few-call
    fast path must reproduce."""
    from pose_reconstruction.posture_space import STRICT_ANCESTORS
    from skeleton_core.geometry import normalize, quat_from_yaw, quat_multiply, retarget
    from skeleton_core.model import PARENTS, ROOT
    missing = ~(rel >= c.reliable_threshold)
    norm, tf = normalize(p, np.maximum((~missing).astype(float), 1e-3))
    scale = c.body.height / max(height, 0.5)
    q = retarget(norm, c.body)
    below = (STRICT_ANCESTORS & missing[None, :]).any(axis=1)
    q[below] = norm[below] * scale                 # uniformly scaled below a missing joint
    prepared = q.copy()
    q[missing] = c.mean.reshape(NUM_JOINTS, 3)[missing]
    z = c.components @ (q.reshape(-1) - c.mean)
    i = int(np.argmin(np.sum((c.projected - z) ** 2, axis=1)))
    match = np.asarray(c.db.positions[i], float)
    out = p.copy()
    bone = c.body.bone_lengths_by_joint() / scale if bones is None else bones
    yaw = float(tf.yaw)
    rz = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0, 0, 1]])
    rest = c.body.rest_offsets / np.maximum(np.linalg.norm(c.body.rest_offsets, axis=1),
                                            1e-12)[:, None]
    from skeleton_core.model import SPINE
    for j in np.flatnonzero(missing):
        if j == ROOT and not missing[SPINE]:
            # the root hangs below the observed spine (the match's direction, the user's length)
            d = match[SPINE] - match[ROOT]
            u = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-9 else rest[SPINE]
            out[j] = p[SPINE] - rz @ (u * bone[SPINE])
        elif j == ROOT:
            out[j] = denormalize(match[j:j + 1] / scale, tf)[0]
        else:
            d = match[j] - match[PARENTS[j]]
            u = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-9 else rest[j]
            out[j] = out[PARENTS[j]] + rz @ (u * bone[j])
    ori = quat_multiply(quat_from_yaw(np.asarray(yaw))[None, :], c.db.orientations[i])
    if orientations is not None:
        ori = np.where(missing[:, None], ori, orientations)
    return out, ori, i, prepared


def test_fast_completion_equals_the_straightforward_computation(db):
    # complete() works on cached joint sets, a (20, 19) bone-to-position matrix and Python
    # floats (posture_space.QueryPreparer.prepare_rows): the same results as the reference
    c = PCACompletion(db)
    rng = np.random.default_rng(5)
    body = standard_body()
    for k in range(60):
        height = rng.uniform(1.4, 2.0)
        p = place(body.scaled(height).rest_positions() + rng.normal(0, 0.08, (NUM_JOINTS, 3)),
                  yaw=rng.uniform(-np.pi, np.pi), t=rng.normal(0, 1, 3))
        rel = rng.uniform(0, 1, NUM_JOINTS) ** 0.3   # mostly reliable
        rel[rng.random(NUM_JOINTS) < 0.15] = 0.0
        if k % 5 == 0:
            rel[0] = np.nan                          # a NaN counts as missing, the root too
        if k % 7 == 0:
            p[9] = p[8]                              # a joint on its parent: rest direction
        ori = rng.normal(size=(NUM_JOINTS, 4)) if k % 2 else None
        bones = body.scaled(height).bone_lengths_by_joint() if k % 3 else None
        res = c.complete(p, rel, height, ori, bones)
        out, ref_ori, i, prepared = reference_complete(c, p, rel, height, ori, bones)
        assert res.match_index == i
        assert np.array_equal(res.substituted, ~(rel >= 0.5))
        np.testing.assert_allclose(res.positions, out, rtol=0, atol=1e-12)
        np.testing.assert_allclose(res.orientations, ref_ori, rtol=0, atol=1e-12)
        # method C's entry point (QueryPreparer.prepare) shares the fast preparation
        w = (rel >= 0.5).astype(float)
        np.testing.assert_allclose(c.preparer.prepare(p, w, height).query, prepared, rtol=0,
                                   atol=1e-12)
