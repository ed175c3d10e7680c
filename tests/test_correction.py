"""Learned sensor correction, user profiles and the leave-one-subject-out protocol."""
from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from pose_reconstruction import correction as C
from pose_reconstruction import profile as P
from skeleton_core.model import (HAND_LEFT, NUM_JOINTS, NUM_SEGMENTS, WRIST_LEFT,
                                 standard_body)


def _rotz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _postures(n, rng):
    """Standard-body postures with randomly swung arms and legs, random heading and place."""
    body = standard_body()
    rest = body.rest_positions()
    out = np.empty((n, NUM_JOINTS, 3))
    for i in range(n):
        p = rest.copy()
        # rotate each limb chain about its root joint by a random small rotation
        for root, chain in ((4, (5, 6, 7)), (8, (9, 10, 11)), (12, (13, 14, 15)),
                            (16, (17, 18, 19))):
            ax = rng.normal(size=3)
            ax /= np.linalg.norm(ax)
            ang = rng.uniform(-0.8, 0.8)
            K = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
            R = np.eye(3) + np.sin(ang) * K + (1 - np.cos(ang)) * K @ K
            for j in chain:
                p[j] = p[root] + R @ (p[j] - p[root])
        yaw = rng.uniform(-np.pi, np.pi)
        out[i] = p @ _rotz(yaw).T + np.array([rng.uniform(1.5, 3.5), rng.uniform(-1, 1), 0.0])
    return out


def _true_field(rng):
    b = rng.normal(scale=0.03, size=(NUM_JOINTS, 3))
    W = np.zeros((C.NUM_FEATURES, 3 * NUM_JOINTS))
    # a sparse posture-dependent part: a few joints move with a few bone directions
    for _ in range(12):
        W[rng.integers(C.NUM_FEATURES), rng.integers(3 * NUM_JOINTS)] = rng.normal(scale=0.05)
    for h, w in ((HAND_LEFT, WRIST_LEFT), (11, 10)):  # hands take the wrists' correction
        b[h] = b[w]
        W[:, 3 * h:3 * h + 3] = W[:, 3 * w:3 * w + 3]
    return b, W


def _apply_field(kin, b, W, mean_f):
    rot = C.body_frame(kin)
    f = C.features(kin, rot) - mean_f
    c = b + (f @ W).reshape(len(kin), NUM_JOINTS, 3)
    return kin + np.einsum('njk,nlk->njl', c, rot)


def test_learned_correction_recovers_a_known_offset_field():
    rng = np.random.default_rng(3)
    b, W = _true_field(rng)
    train = [_postures(150, rng) for _ in range(4)]            # four "subjects"
    mean_f = C.features(np.concatenate(train), C.body_frame(np.concatenate(train))).mean(0)
    refs = [_apply_field(k, b, W, mean_f) for k in train]
    corr = C.fit(train, refs, 'kinect_v2_sdk', groups=['s1', 's2', 's3', 's4'])
    assert corr.meta['ridge_alpha'] in C.RIDGE_GRID and corr.tracker == 'kinect_v2_sdk'
    # unseen postures, headings and places: the correction moves them onto the reference
    test = _postures(100, rng)
    truth = _apply_field(test, b, W, mean_f)
    before = np.linalg.norm(truth - test, axis=-1).mean()
    after = np.linalg.norm(truth - corr.apply(test), axis=-1).mean()
    assert before > 0.03
    assert after < 0.05 * before, (before, after)
    # the offset-only model recovers the posture-independent part
    off = C.fit(train, refs, 'kinect_v2_sdk', posture=False)
    assert np.abs(off.weights).max() == 0.0
    np.testing.assert_allclose(off.offset, np.concatenate([
        C.targets(k, r, C.body_frame(k)) for k, r in zip(train, refs)]).mean(0), atol=1e-12)


def test_correction_is_in_the_body_frame():
    """The same posture turned and moved gets the same correction, turned with it."""
    rng = np.random.default_rng(5)
    b, W = _true_field(rng)
    corr = C.SensorCorrection('kinect_v2_sdk', b, W, np.zeros(C.NUM_FEATURES))
    p = _postures(1, rng)[0]
    d0 = corr.delta(p)
    R = _rotz(1.1)
    d1 = corr.delta(p @ R.T + np.array([0.4, -0.3, 0.0]))
    np.testing.assert_allclose(d1, d0 @ R.T, atol=1e-12)
    # stage 'reliable': unreliable joints do not move, their bones do not count
    rel = np.ones(NUM_JOINTS)
    rel[[6, 7]] = 0.0
    d2 = corr.delta(p, rel, 0.5)
    assert np.all(d2[[6, 7]] == 0.0) and np.any(d2 != 0.0)


def test_correction_file_round_trip_and_malformed(tmp_path):
    rng = np.random.default_rng(0)
    b, W = _true_field(rng)
    corr = C.SensorCorrection('kinect_v2_sdk', b, W, rng.normal(size=C.NUM_FEATURES),
                              meta={'subjects': ['s01']})
    path = corr.save(tmp_path / 'c.npz')
    back = C.load(path)
    assert back.tracker == 'kinect_v2_sdk' and back.meta['subjects'] == ['s01']
    np.testing.assert_array_equal(back.weights, corr.weights)
    (tmp_path / 'bad.npz').write_bytes(b'not a zip file')
    np.savez(tmp_path / 'short.npz', offset=np.zeros((3, 3)), weights=W,
             feature_mean=np.zeros(C.NUM_FEATURES),
             meta=np.array(json.dumps({'format': C.FORMAT, 'version': 1,
                                       'tracker': 'kinect_v2_sdk'})))
    np.savez(tmp_path / 'tracker.npz', offset=b, weights=W, feature_mean=np.zeros(C.NUM_FEATURES),
             meta=np.array(json.dumps({'format': C.FORMAT, 'version': 1, 'tracker': 'kinect9'})))
    for name, words in (('bad.npz', 'cannot be read'), ('short.npz', 'offset must have shape'),
                        ('tracker.npz', 'unknown tracker'), ('missing.npz', 'does not exist')):
        with pytest.raises(C.CorrectionFileError) as e:
            C.load(tmp_path / name)
        assert words in str(e.value) and '\n' not in str(e.value)


def test_correction_is_never_applied_to_another_tracker():
    from pose_reconstruction.node_common import load_user_terms
    from pose_reconstruction.reconstructor import Reconstructor
    db = standard_body().rest_positions()[None].repeat(40, axis=0)
    corr = C.SensorCorrection('kinect_v2_sdk', np.zeros((NUM_JOINTS, 3)),
                              np.zeros((C.NUM_FEATURES, 3 * NUM_JOINTS)),
                              np.zeros(C.NUM_FEATURES))
    for tracker in ('', 'nite2'):
        with pytest.raises(C.TrackerMismatch):
            Reconstructor(db, method='C', correction=corr, input_tracker=tracker)
    assert Reconstructor(db, method='C', correction=corr,
                         input_tracker='kinect_v2_sdk').correction is corr
    logged = []
    log = SimpleNamespace(info=logged.append, warning=logged.append)
    # the default file is for kinect_v2_sdk: a NiTE2 stream gets no correction, one log line
    terms = load_user_terms({'sensor_correction': 'auto', 'input_tracker': 'nite2',
                             'correction_stage': 'input', 'user_profile': ''}, log)
    assert terms['correction'] is None and len(logged) == 1 and 'nite2' in logged[0]


def test_profile_round_trip_and_malformed(tmp_path):
    rng = np.random.default_rng(1)
    seq = _postures(50, rng)
    prof = P.measure([seq], 'alice', tracker='nite2')
    L = np.asarray(standard_body().segment_lengths, float)
    np.testing.assert_allclose(prof.segment_lengths, 0.5 * (L + L[P._MIRROR_SEG]), atol=1e-9)
    path = prof.save(P.profile_path('alice', tmp_path))
    back = P.load_by_name('alice', tmp_path)
    np.testing.assert_allclose(back.segment_lengths, prof.segment_lengths, atol=1e-5)
    assert back.tracker == 'nite2' and back.frames == 50
    good = json.loads(path.read_text())
    cases = {'notjson': ('{"format": ', 'not valid JSON'),
             'count': ({**good, 'segment_lengths_m': [0.3] * 5}, 'must hold 19'),
             'negative': ({**good, 'segment_lengths_m': [-0.3] + [0.3] * 18}, 'outside'),
             'text': ({**good, 'segment_lengths_m': ['a'] * 19}, 'list of 19 numbers'),
             'format': ({**good, 'format': 'other'}, 'not a version 1'),
             'name': ({**good, 'name': '../x'}, 'profile name')}
    for name, (content, words) in cases.items():
        f = tmp_path / f'{name}.json'
        f.write_text(content if isinstance(content, str) else json.dumps(content))
        with pytest.raises(P.ProfileError) as e:
            P.load(f)
        assert words in str(e.value) and '\n' not in str(e.value), name
    with pytest.raises(P.ProfileError):
        P.profile_path('../../etc/passwd')


def test_reconstructor_uses_the_profile_lengths_from_the_first_frame():
    from skeleton_core.conversions import SkeletonFrame
    from skeleton_core.model import SEGMENT_CHILDREN, SEGMENT_PARENTS, TRACKED
    from pose_reconstruction.reconstructor import Reconstructor
    rng = np.random.default_rng(2)
    seq = _postures(5, rng)
    db = seq.repeat(10, axis=0) - seq[:1, :1]
    L = np.full(NUM_SEGMENTS, 0.25)
    rec = Reconstructor(db, method='C', profile=L, symmetric_lengths=False)
    out = rec.process(SkeletonFrame(positions=seq[0], tracking_state=np.full(NUM_JOINTS, TRACKED)))
    got = np.linalg.norm(out.positions[list(SEGMENT_CHILDREN)] - out.positions[list(SEGMENT_PARENTS)],
                         axis=1)
    np.testing.assert_allclose(got, L, atol=1e-9)


def test_loso_never_puts_a_subject_on_both_sides():
    from kinect_experiments import real_loso

    def clip(subject, movement, rep, ref=True):
        return SimpleNamespace(clip=SimpleNamespace(subject=subject, movement=movement,
                                                    repetition=rep,
                                                    is_tracking_failure=False),
                               reference=np.zeros(1) if ref else None)
    clips = [clip(s, m, r, ref=(s, m) != (3, 3)) for s in range(1, 6) for m in (1, 3)
             for r in (1, 2)]
    for held in range(1, 6):
        train = real_loso.training_clips(clips, held)
        assert train and all(c.clip.subject != held for c in train)
        assert {c.clip.subject for c in train} == set(range(1, 6)) - {held}
        assert all(c.reference is not None for c in train)


def test_profiles_never_use_the_scored_clip():
    from kinect_experiments import real_loso
    rest = standard_body().rest_positions()

    def stream(name, scale):
        return SimpleNamespace(clip_name=name, positions=np.repeat(rest[None] * scale, 3, 0))
    streams = [stream('m01_s01_e01', 1.0), stream('m01_s01_e02', 1.1), stream('m02_s01_e01', 1.2),
               stream('m03_s01_e01', 3.0),  # tracking failure: scored, never a source
               stream('m01_s02_e01', 2.0)]
    prof = real_loso.profiles_leave_clip_out(streams)
    L = np.asarray(standard_body().segment_lengths, float)
    sym = 0.5 * (L + L[P._MIRROR_SEG])
    np.testing.assert_allclose(prof['m01_s01_e01'], 1.15 * sym, rtol=1e-9)  # median of 1.1, 1.2
    np.testing.assert_allclose(prof['m03_s01_e01'], 1.1 * sym, rtol=1e-9)   # of 1.0, 1.1, 1.2
    assert 'm01_s02_e01' not in prof  # no other clip of s02


def test_node_terms_load_a_named_correction_and_profile(tmp_path):
    from pose_reconstruction.node_common import load_user_terms
    corr = C.SensorCorrection('nite2', np.zeros((NUM_JOINTS, 3)),
                              np.zeros((C.NUM_FEATURES, 3 * NUM_JOINTS)), np.zeros(C.NUM_FEATURES))
    path = corr.save(tmp_path / 'lab.npz')
    P.UserProfile('bob', np.full(NUM_SEGMENTS, 0.3)).save(tmp_path / 'bob.json')
    logged = []
    log = SimpleNamespace(info=logged.append, warning=logged.append)
    values = {'sensor_correction': str(path), 'input_tracker': 'nite2',
              'correction_stage': 'reliable', 'user_profile': 'bob',
              'profiles_dir': str(tmp_path)}
    terms = load_user_terms(values, log)
    assert terms['correction'].tracker == 'nite2' and terms['correction_stage'] == 'reliable'
    assert terms['profile'].name == 'bob'
    (tmp_path / 'broken.json').write_text('{')
    for key, value, err in (('sensor_correction', str(tmp_path / 'none.npz'),
                             C.CorrectionFileError), ('user_profile', 'broken', P.ProfileError)):
        with pytest.raises(err) as e:
            load_user_terms({**values, key: value}, log)
        assert '\n' not in str(e.value)
