"""A lab's own pairs: a recording of the input topic from any tracker plus a mocap
reference on its own clock and frame -> clock offset by cross-correlation, rigid registration, a
correction for that tracker with its leave-one-subject-out report; the tracker travels with the
bag to process_bag."""
from __future__ import annotations

import json

import numpy as np
import pytest

from pose_reconstruction import correction as C
from pose_reconstruction import correction_build as CB
from skeleton_core import tracker as T
from skeleton_core.bagio import BagWriter
from skeleton_core.conversions import SkeletonFrame, frames_to_array_msg
from skeleton_core.model import NUM_JOINTS, TRACKED
from skeleton_data.motions import builtin_clips
from skeleton_data.reference import read_csv, write_csv
from skeleton_eval.pairing import clock_offset


def _rot(axis_z, tilt_x=0.0):
    c, s = np.cos(axis_z), np.sin(axis_z)
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    c, s = np.cos(tilt_x), np.sin(tilt_x)
    rx = np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])
    return rx @ rz


def _tracker_error(truth):
    """A posture-dependent tracker error: the knees and elbows pulled forward in the body frame
    by an amount growing with their bend, plus constant joint offsets."""
    rot = C.body_frame(truth)
    f = C.features(truth, rot)
    delta = np.zeros_like(truth)
    delta[:, :, 0] = 0.02                       # every joint 2 cm forward (body frame)
    delta[:, 13, 0] += 0.06 * f[:, 3 * 12 + 0]  # knee with the shin's forward direction
    delta[:, 5, 2] -= 0.05 * f[:, 3 * 5 + 2]    # elbow with the forearm's vertical direction
    return truth - np.einsum('njk,nlk->njl', delta, rot)


def _write_bag(path, times_s, positions, tracker='nite2'):
    with BagWriter(path) as bag:
        t0 = int(times_s[0] * 1e9)
        if tracker:
            T.write_to_bag(bag, tracker, t0)
        for t, p in zip(times_s, positions):
            ns = int(round(t * 1e9))
            f = SkeletonFrame(user_id=1, stamp_ns=ns, positions=p,
                              tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                              reliability=np.ones(NUM_JOINTS), frame_id='kinect_link')
            bag.write('/kinect/skeletons', frames_to_array_msg([f], ns, 'kinect_link'), ns)


def _subject_data(seed, n_clips=3):
    clips = builtin_clips(seed=seed, duration=8.0)[:n_clips]
    truth = np.concatenate([c.positions for c in clips])     # 30 Hz, one continuous session
    return truth


def _make_pair(tmp_path, name, truth, offset_s, rng):
    """Bag (30 Hz, tracker clock from 1.7e9 s) + reference CSV (100 Hz, mocap clock and frame:
    Y up, rotated, moved, starting ``offset_s`` before... see below)."""
    t_trk = 1.7e9 + np.arange(len(truth)) / 30.0
    tracker = _tracker_error(truth) + rng.normal(scale=0.004, size=truth.shape)
    _write_bag(tmp_path / f'{name}.mcap', t_trk, tracker)
    # the mocap runs at 100 Hz on its own clock; a tracker frame at t pairs with the mocap time
    # t - t_trk[0] + offset_s
    t_ref = np.arange(-1.0, len(truth) / 30.0 + 1.0, 0.01) + offset_s
    src_t = np.arange(len(truth)) / 30.0
    flat = truth.reshape(len(truth), -1)
    ref = np.stack([np.interp(t_ref - offset_s, src_t, flat[:, k]) for k in range(flat.shape[1])],
                   axis=1).reshape(len(t_ref), NUM_JOINTS, 3)
    out_range = (t_ref - offset_s < 0) | (t_ref - offset_s > src_t[-1])
    ref[out_range] = np.nan
    ref = ref @ _rot(0.7, 0.3).T + np.array([2.0, -1.0, 0.5])   # the mocap's own frame
    csv = write_csv(tmp_path / f'{name}.csv', t_ref, ref * 1000.0)   # millimetres
    return tmp_path / f'{name}.mcap', csv


def test_clock_offset_recovered_from_a_nite2_recording_and_its_reference(tmp_path):
    rng = np.random.default_rng(3)
    truth = _subject_data(0)
    bag, csv = _make_pair(tmp_path, 'a', truth, offset_s=12.345, rng=rng)
    t, pos, tracker = CB.read_tracker_bag(bag)
    assert tracker == 'nite2' and pos.shape == truth.shape
    ref = read_csv(csv, units='mm')
    off, score = clock_offset(t, pos, ref.times, ref.positions)
    assert off == pytest.approx(12.345, abs=0.01)   # 1 ms is 1/33 of a tracker frame
    assert score > 0.9
    # a reference on the same clock shifted the other way
    bag2, csv2 = _make_pair(tmp_path, 'b', truth, offset_s=-3.21, rng=rng)
    t, pos, _ = CB.read_tracker_bag(bag2)
    ref = read_csv(csv2, units='mm')
    assert clock_offset(t, pos, ref.times, ref.positions)[0] == pytest.approx(-3.21, abs=0.01)


def test_build_correction_from_pairs_learns_the_tracker_error_with_a_loso_report(tmp_path,
                                                                                  capsys):
    rng = np.random.default_rng(5)
    rows = ['bag,reference,subject,units']
    for k, subj in enumerate(('s1', 's2', 's3')):
        truth = _subject_data(10 + k)
        bag, csv = _make_pair(tmp_path, f'rec{k}', truth, offset_s=5.0 + 7.3 * k, rng=rng)
        rows.append(f'{bag.name},{csv.name},{subj},mm')
    (tmp_path / 'pairs.csv').write_text('\n'.join(rows) + '\n')
    out = tmp_path / 'corr.npz'
    assert CB.main(['--pairs', str(tmp_path / 'pairs.csv'), '--out', str(out)]) == 0
    text = capsys.readouterr().out
    import re
    found = [float(x) for x in re.findall(r'clock offset (-?[0-9.]+) s', text)]
    assert found == pytest.approx([5.0, 12.3, 19.6], abs=0.01)   # a third of a tracker frame
    corr = C.load(out)
    assert corr.tracker == 'nite2'                       # the bags' declared tracker
    rep = json.loads((tmp_path / 'corr.npz.report.json').read_text())
    assert sorted(rep['per_subject']) == ['s1', 's2', 's3']
    o = rep['overall']
    # held-out subjects: the learned correction removes most of the simulated error
    assert o['corr_mpjpe_cm'] < 0.75 * o['raw_mpjpe_cm']
    assert o['corr_eq18_cm'] < 0.8 * o['raw_eq18_cm']
    assert o['corr_bone_dir_deg'] < o['raw_bone_dir_deg']
    md = (tmp_path / 'corr.npz.report.md').read_text().splitlines()
    assert len([ln for ln in md if ln.startswith('| s') and '->' in ln]) == 3   # one per subject
    assert len([ln for ln in md if ln.startswith('| rec') and '.' in ln]) == 3  # offsets


def test_build_correction_refuses_bags_without_a_tracker_unless_named(tmp_path, capsys):
    rng = np.random.default_rng(1)
    truth = _subject_data(0, n_clips=1)
    bag, csv = _make_pair(tmp_path, 'x', truth, 1.0, rng)
    _write_bag(bag, 1.7e9 + np.arange(len(truth)) / 30.0, truth, tracker='')
    args = ['--bag', str(bag), '--reference', str(csv), '--subject', 's1', '--units', 'mm',
            '--out', str(tmp_path / 'c.npz')]
    assert CB.main(args) == 2
    assert 'name the one they come from with --tracker' in capsys.readouterr().err
    assert CB.main(args + ['--tracker', 'kinect_v1_sdk']) == 0
    assert C.load(tmp_path / 'c.npz').tracker == 'kinect_v1_sdk'


def test_process_bag_picks_the_correction_of_the_bags_tracker(tmp_path, monkeypatch):
    from kinect_bringup.process_bag import process
    rng = np.random.default_rng(2)
    truth = _subject_data(0, n_clips=1)[:60]
    t = 1.7e9 + np.arange(len(truth)) / 30.0
    _write_bag(tmp_path / 'in.mcap', t, truth, tracker='nite2')
    b = rng.normal(scale=0.02, size=(NUM_JOINTS, 3))
    corr = C.SensorCorrection('nite2', b, np.zeros((C.NUM_FEATURES, 3 * NUM_JOINTS)),
                              np.zeros(C.NUM_FEATURES))
    from skeleton_data.database import default_path as default_database
    db = str(default_database())   # the session's database (conftest builds it), before the cache moves
    monkeypatch.setenv('KINECT_POSTURE_CACHE', str(tmp_path / 'cache'))
    corr.save(C.default_path('nite2'))
    lines = []
    s = process(tmp_path / 'in.mcap', tmp_path / 'out.mcap', 'C', database=db, progress=False,
                info=lines.append, warn=lines.append)
    assert s['tracker'] == 'nite2' and s['correction'] and 'nite2' in s['correction']
    assert any('applied' in m for m in lines)
    # an explicit tracker overrides the bag's: the nite2 correction is then refused in one line
    lines.clear()
    s = process(tmp_path / 'in.mcap', tmp_path / 'out2.mcap', 'C', database=db, progress=False,
                input_tracker='kinect_v1_sdk', correction=str(C.default_path('nite2')),
                info=lines.append, warn=lines.append)
    assert s['correction'] is None
    assert any("the input comes from 'kinect_v1_sdk', another tracker" in m for m in lines)
    # the tracker is in the output bag too
    assert T.from_bag(tmp_path / 'out.mcap') == 'nite2'


def test_c3d_markers_read_through_a_plug_in_gait_map(tmp_path):
    from skeleton_data import vicon
    from skeleton_data.c3d import read_c3d, write_c3d
    from skeleton_data.joint_map import builtin_map
    from skeleton_data.reference import load_reference
    jm = builtin_map('plug_in_gait')
    rng = np.random.default_rng(0)
    pts = rng.normal(scale=300.0, size=(25, len(jm.columns), 3))   # mm, the file's labels
    pts[3, 5] = np.nan                                            # one invalid sample
    path = write_c3d(tmp_path / 'take.c3d', [f'Sub:{c}' for c in jm.columns], pts, 100.0)
    labels, xyz, rate = read_c3d(path)
    assert rate == 100.0 and labels[0] == f'Sub:{jm.columns[0]}'
    np.testing.assert_allclose(xyz[np.isfinite(xyz)], pts[np.isfinite(pts)], rtol=1e-6)
    assert np.isnan(xyz[3, 5]).all()
    ref = load_reference(path, jm)
    assert ref.positions.shape == (25, NUM_JOINTS, 3)
    assert ref.times[1] == pytest.approx(0.01)
    # the same markers through the text reader give the same joint centres
    from skeleton_data.joint_map import marker_joint_centres
    m = (np.nan_to_num(pts) * jm.scale) @ jm.rotation.T
    m[3, 5] = np.nan
    order = [jm.markers.get(c, c) for c in jm.columns]
    want = marker_joint_centres(m[:, [order.index(n) for n in vicon.MARKERS]], jm)
    np.testing.assert_allclose(ref.positions, want, atol=1e-5)


def test_process_bag_leaves_out_joints_the_ground_truth_does_not_know(tmp_path):
    """UI-PRMD bags mark the reference hands NOT_TRACKED (the Kinect never recorded them):
    process_bag then scores the other joints only, as make evaluate --real does."""
    from kinect_bringup.process_bag import process
    truth = _subject_data(0, n_clips=1)[:30]
    t = 1.7e9 + np.arange(len(truth)) / 30.0
    with BagWriter(tmp_path / 'in.mcap') as bag:
        for ti, p in zip(t, truth):
            ns = int(round(ti * 1e9))
            raw = p.copy()
            raw[[7, 11]] += 0.5                      # hands 50 cm off: would dominate the error
            for topic, pos, state in (('/kinect/skeletons', raw, TRACKED),
                                      ('/kinect/ground_truth', p, TRACKED)):
                st = np.full(NUM_JOINTS, state, np.uint8)
                if topic == '/kinect/ground_truth':
                    st[[7, 11]] = 0                  # NOT_TRACKED: no reference there
                f = SkeletonFrame(user_id=1, stamp_ns=ns, positions=pos, tracking_state=st,
                                  frame_id='kinect_link')
                bag.write(topic, frames_to_array_msg([f], ns, 'kinect_link'), ns)
    s = process(tmp_path / 'in.mcap', tmp_path / 'out.mcap', 'C', progress=False,
                correction='')
    assert s['accuracy']['raw']['mpjpe_cm'] == pytest.approx(0.0, abs=1e-6)
