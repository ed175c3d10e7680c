"""The Azure Kinect body tracking (tracker ``azure_kinect_bt``) through the generic correction
path, as any tracker: a lab's pairs (bags declaring ``azure_kinect_bt`` + a mocap reference on its
own clock and frame) -> ``build_correction`` -> ``cache/sensor_correction_azure_kinect_bt.npz``,
which ``sensor_correction: auto`` then finds for a stream of that tracker (and refuses for
another)."""
from __future__ import annotations

import json

import numpy as np

from pose_reconstruction import correction as C
from pose_reconstruction import correction_build as CB
from skeleton_core import tracker as T
from skeleton_core.bagio import BagWriter
from skeleton_core.conversions import SkeletonFrame, frames_to_array_msg
from skeleton_core.model import NUM_JOINTS, TRACKED
from skeleton_data.motions import builtin_clips
from skeleton_data.reference import write_csv

TRACKER = 'azure_kinect_bt'


def _azure_error(truth):
    """A posture-dependent tracker error (body frame): every joint 1.5 cm forward, the knee
    pulled forward with the shin's forward direction, the pelvis 2 cm low."""
    rot = C.body_frame(truth)
    f = C.features(truth, rot)
    delta = np.zeros_like(truth)
    delta[:, :, 0] = 0.015
    delta[:, 13, 0] += 0.05 * f[:, 3 * 12 + 0]
    delta[:, 0, 2] -= 0.02
    return truth - np.einsum('njk,nlk->njl', delta, rot)


def _pair(tmp_path, name, truth, offset_s, rng):
    t_trk = 1.7e9 + np.arange(len(truth)) / 30.0
    tracked = _azure_error(truth) + rng.normal(scale=0.003, size=truth.shape)
    with BagWriter(tmp_path / f'{name}.mcap') as bag:
        T.write_to_bag(bag, TRACKER, int(t_trk[0] * 1e9))
        for t, p in zip(t_trk, tracked):
            ns = int(round(t * 1e9))
            # the ROS driver's MarkerArray has no joint states: every joint TRACKED
            f = SkeletonFrame(user_id=1, stamp_ns=ns, positions=p,
                              tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                              reliability=np.ones(NUM_JOINTS), frame_id='kinect_link')
            bag.write('/kinect/skeletons', frames_to_array_msg([f], ns, 'kinect_link'), ns)
    t_ref = np.arange(-1.0, len(truth) / 30.0 + 1.0, 0.01) + offset_s    # 100 Hz mocap clock
    src_t = np.arange(len(truth)) / 30.0
    flat = truth.reshape(len(truth), -1)
    ref = np.stack([np.interp(t_ref - offset_s, src_t, flat[:, k]) for k in range(flat.shape[1])],
                   axis=1).reshape(len(t_ref), NUM_JOINTS, 3)
    ref[(t_ref - offset_s < 0) | (t_ref - offset_s > src_t[-1])] = np.nan
    c, s = np.cos(0.4), np.sin(0.4)
    ref = ref @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]).T + np.array([1.0, 2.0, 0.3])
    write_csv(tmp_path / f'{name}.csv', t_ref, ref * 1000.0)


def test_build_correction_learns_an_azure_kinect_correction_found_by_auto(tmp_path, monkeypatch,
                                                                         capsys):
    monkeypatch.setenv('KINECT_POSTURE_CACHE', str(tmp_path / 'cache'))
    rng = np.random.default_rng(11)
    rows = ['bag,reference,subject,units']
    for k, subj in enumerate(('s1', 's2', 's3')):
        truth = np.concatenate([c.positions for c in builtin_clips(seed=20 + k, duration=8.0)[:2]])
        _pair(tmp_path, f'rec{k}', truth, offset_s=3.0 + 4.1 * k, rng=rng)
        rows.append(f'rec{k}.mcap,rec{k}.csv,{subj},mm')
    (tmp_path / 'pairs.csv').write_text('\n'.join(rows) + '\n')
    # no --out, no --tracker: the bags' declared tracker and its default file
    assert CB.main(['--pairs', str(tmp_path / 'pairs.csv')]) == 0
    path = C.default_path(TRACKER)
    assert path == tmp_path / 'cache' / 'sensor_correction_azure_kinect_bt.npz'
    assert path.is_file()
    corr = C.load(path)
    assert corr.tracker == TRACKER
    rep = json.loads(path.with_name(path.name + '.report.json').read_text())
    o = rep['overall']
    # held-out subjects: the posture-dependent part is learned (the registration takes up some
    # of the constant part, so the MPJPE gain is the smaller one)
    assert o['corr_eq18_cm'] < 0.85 * o['raw_eq18_cm']
    assert o['corr_mpjpe_cm'] < 0.95 * o['raw_mpjpe_cm']
    assert o['corr_bone_dir_deg'] < 0.85 * o['raw_bone_dir_deg']
    # sensor_correction: auto finds it for an azure_kinect_bt stream ...
    got = C.select('auto', TRACKER)
    assert got is not None and got.tracker == TRACKER
    assert np.allclose(got.offset, corr.offset)
    # ... and never for another tracker's stream (its own file, none here)
    notes = []
    assert C.select('auto', 'nite2', log=notes.append) is None
    assert any('none learned for nite2' in n for n in notes)
    # the file named explicitly for another tracker's stream is refused in one line
    notes.clear()
    assert C.select(str(path), 'kinect_v1_sdk', warn=notes.append) is None
    assert notes and 'another tracker' in notes[0]
