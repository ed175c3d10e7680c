"""Motion database: normalisation, retargeting, twists, filtering, save/load, default + cache."""
import json
import logging

import numpy as np
import pytest

from skeleton_data.database import (DEFAULT_THRESHOLD, DatabaseError, MotionDatabase,
                                    build_database, filter_postures, load_or_build_default,
                                    segment_twists)
from skeleton_core.geometry import quat_from_yaw, quat_multiply, quat_rotate
from skeleton_data.mocap import MotionClip, load_cmu_clip
from skeleton_core.model import HEAD, SEGMENT_OF_JOINT, segment_lengths, standard_body
from skeleton_data.motions import builtin_clips


@pytest.fixture(scope='module')
def clips():
    return builtin_clips(seed=1)


def _moved(clip, yaw, shift, name='moved'):
    """The clip rotated about z by ``yaw`` and shifted by ``shift``."""
    q = quat_from_yaw(np.array(yaw))
    p = quat_rotate(np.broadcast_to(q, clip.positions.shape[:-1] + (4,)), clip.positions) + shift
    o = quat_multiply(np.broadcast_to(q, clip.orientations.shape), clip.orientations)
    return MotionClip(name, clip.motion_class, clip.fps, p, o, 'test')


def test_normalisation_removes_yaw_and_translation(clips):
    c = clips[3]
    a, _ = build_database([c], threshold=0, progress=False)
    b, _ = build_database([_moved(c, 2.1, np.array([3.0, -1.5, 0.0]))], threshold=0,
                          progress=False)
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-5)
    np.testing.assert_allclose(a.twists, b.twists, atol=1e-4)
    qa, qb = a.orientations, b.orientations
    np.testing.assert_allclose(np.abs(np.sum(qa * qb, -1)), 1.0, atol=1e-5)
    assert np.abs(a.positions[:, 0]).max() == 0.0  # root at the origin
    assert a.positions.dtype == np.float32 and a.flat.shape == (len(a), 60)


def test_retargeting_keeps_standard_bone_lengths(shared_dir):
    clip = load_cmu_clip(shared_dir / 'mocap' / 'cmu' / '09_02.bvh')
    body = standard_body()
    assert np.abs(segment_lengths(clip.positions) - body.segment_lengths).max() > 0.05
    db, _ = build_database([clip], threshold=0, progress=False)
    np.testing.assert_allclose(segment_lengths(db.positions.astype(float)),
                               np.broadcast_to(body.segment_lengths, (len(db), 19)), atol=1e-5)
    tall = standard_body(1.95)
    db2, _ = build_database([clip], body=tall, threshold=0, progress=False)
    np.testing.assert_allclose(segment_lengths(db2.positions.astype(float))[0],
                               tall.segment_lengths, atol=1e-5)
    assert db2.meta['body_height'] == 1.95
    np.testing.assert_allclose(db2.body.segment_lengths, tall.segment_lengths)


def test_twists_are_axial_rotations():
    rest = np.zeros((1, 20, 4))
    rest[..., 3] = 1.0
    assert np.allclose(segment_twists(rest), 0.0)
    # turn the head segment 30 deg about its own (vertical) axis, the upper arm 40 deg about y
    q = rest.copy()
    q[0, HEAD] = [0, 0, np.sin(np.radians(15)), np.cos(np.radians(15))]
    q[0, 5] = [0, np.sin(np.radians(20)), 0, np.cos(np.radians(20))]  # ElbowLeft: axis +y
    tw = segment_twists(q)
    assert tw[0, SEGMENT_OF_JOINT[HEAD]] == pytest.approx(np.radians(30))
    assert tw[0, SEGMENT_OF_JOINT[5]] == pytest.approx(np.radians(40))
    # a pure swing (head tilted forward about y) has no twist
    q[0, HEAD] = [0, np.sin(np.radians(20)), 0, np.cos(np.radians(20))]
    assert segment_twists(q)[0, SEGMENT_OF_JOINT[HEAD]] == pytest.approx(0.0, abs=1e-12)


def test_filter_threshold_behaviour(clips):
    c = clips[1]
    dup = MotionClip('dup', c.motion_class, c.fps, c.positions, c.orientations, 'test')
    one, _ = build_database([c], threshold=DEFAULT_THRESHOLD, progress=False)
    both, st = build_database([c, dup], threshold=DEFAULT_THRESHOLD, progress=False)
    assert len(both) == len(one)            # exact duplicates add nothing
    assert st['frames_before'] == 2 * len(c) and st['frames_after'] == len(one)
    assert np.all(both.clip_index == 0)
    keep_all, _ = build_database([c, dup], threshold=0.0, progress=False)
    assert len(keep_all) == 2 * len(c)      # threshold 0 keeps everything
    # kept postures are pairwise at least the threshold apart; every dropped one is close to one
    rng = np.random.default_rng(0)
    x = rng.normal(size=(400, 6))
    thr = 4.0
    kept = filter_postures(x, thr)
    d = ((x[kept][:, None] - x[kept][None]) ** 2).sum(-1)
    assert d[np.triu_indices(len(kept), 1)].min() >= thr
    dropped = np.setdiff1d(np.arange(len(x)), kept)
    dd = ((x[dropped][:, None] - x[kept][None]) ** 2).sum(-1)
    assert np.all(dd.min(1) < thr)
    # same as the plain sequential greedy loop (several KD-tree rebuilds on the way)
    ref = []
    for i in range(len(x)):
        if all(((x[i] - x[k]) ** 2).sum() >= thr for k in ref):
            ref.append(i)
    assert kept.tolist() == ref
    assert 0 < len(kept) < len(x)
    xs = rng.normal(size=(3000, 6))
    kept_s = filter_postures(xs, 1.0, chunk=64)
    ref = []
    for i in range(len(xs)):
        if not ref or (((xs[ref] - xs[i]) ** 2).sum(1) >= 1.0).all():
            ref.append(i)
    assert kept_s.tolist() == ref and len(ref) > 1100  # KD-tree rebuilt at least once


def test_save_load_round_trip_and_errors(clips, tmp_path):
    db, _ = build_database(clips[:3], progress=False)
    p = db.save(tmp_path / 'db.npz')
    back = MotionDatabase.load(p)
    for k in ('positions', 'orientations', 'twists', 'clip_index', 'frame_index'):
        np.testing.assert_array_equal(getattr(back, k), getattr(db, k))
    assert back.class_names == db.class_names
    assert back.meta['frames_after'] == len(db) and back.meta['joint_names'][0] == 'HipCenter'
    with pytest.raises(DatabaseError, match='does not exist'):
        MotionDatabase.load(tmp_path / 'none.npz')
    bad = tmp_path / 'bad.npz'
    bad.write_bytes(p.read_bytes()[:1000])
    with pytest.raises(DatabaseError, match='corrupt'):
        MotionDatabase.load(bad)
    bad.write_text('hello')
    with pytest.raises(DatabaseError, match='corrupt'):
        MotionDatabase.load(bad)
    # wrong version
    meta = dict(db.meta, format_version=99, class_names=db.class_names)
    np.savez(bad.open('wb'), positions=db.positions, orientations=db.orientations,
             twists=db.twists, clip_index=db.clip_index, frame_index=db.frame_index,
             meta=np.array(json.dumps(meta)))
    with pytest.raises(DatabaseError, match='version 99'):
        MotionDatabase.load(bad)


class _Records(logging.Handler):
    def __init__(self):
        super().__init__(logging.INFO)
        self.messages = []

    def emit(self, record):
        self.messages.append(record.getMessage())


def test_default_builtin_is_cached(tmp_path):
    st1, st2 = {}, {}
    logger = logging.getLogger('skeleton_data.database')
    rec, old_level = _Records(), logger.level
    logger.addHandler(rec)
    logger.setLevel(logging.INFO)
    try:
        a = load_or_build_default('builtin', cache_dir=tmp_path, stats=st1)
        b = load_or_build_default('builtin', cache_dir=tmp_path, stats=st2)
    finally:
        logger.removeHandler(rec)
        logger.setLevel(old_level)
    assert st1['cache_hit'] is False and st2['cache_hit'] is True
    assert any('cache hit' in m for m in rec.messages)
    np.testing.assert_array_equal(a.positions, b.positions)
    assert st1['frames_before'] > len(a) > 300
    assert set(a.class_names) == {'locomotion', 'object_handling', 'upper_body', 'boxing',
                                  'sword_fighting'}
    c = load_or_build_default('builtin', cache_dir=tmp_path, threshold=0.05, stats=st2)
    assert st2['cache_hit'] is False and len(c) < len(a)  # parameters are part of the key
    with pytest.raises(DatabaseError, match='CMU'):
        load_or_build_default('cmu', cache_dir=tmp_path, shared_dir=tmp_path)
    auto = load_or_build_default('auto', cache_dir=tmp_path, shared_dir=tmp_path / 'no')
    assert auto.meta['source'] == 'builtin'


def test_build_db_cli(tmp_path, capsys):
    from skeleton_data import database_cli
    out = tmp_path / 'db.npz'
    assert database_cli.main(['--source', 'builtin', '--out', str(out), '--no-progress',
                              '--threshold', '0.05']) == 0
    text = capsys.readouterr().out
    db = MotionDatabase.load(out)
    assert f'-> {len(db)} after' in text and f'written: {out}' in text
    assert db.meta['threshold'] == 0.05 and db.meta['frames_before'] == 8100
    assert database_cli.main(['--source', 'builtin', '--classes', 'dancing']) == 2
    assert 'unknown class' in capsys.readouterr().err
