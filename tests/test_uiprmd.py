"""UI-PRMD importer: forward kinematics, frame conversion, 22->20 mapping, malformed files, bags."""
import gzip

import numpy as np
import pytest

from skeleton_data import uiprmd as U
from skeleton_core.model import (HAND_LEFT, HAND_RIGHT, JOINT_NAMES, NOT_TRACKED, PARENTS,
                                 TRACKED, WRIST_LEFT, ELBOW_LEFT)


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_euler_order_is_z_x_y():
    rx, ry, rz = 20.0, -35.0, 50.0
    want = _rz(np.radians(rz)) @ _rx(np.radians(rx)) @ _ry(np.radians(ry))
    np.testing.assert_allclose(U.euler_zxy(np.array([rx, ry, rz])), want, atol=1e-12)


def test_forward_kinematics_by_hand():
    off = np.zeros((1, 22, 3))
    ang = np.zeros((1, 22, 3))
    off[0, 0] = (1.0, 2.0, 3.0)        # Waist absolute
    off[0, 1] = (0.0, 10.0, 0.0)       # Spine offset in the Waist frame
    off[0, 2] = (0.0, 5.0, 0.0)        # Chest offset in the Spine frame
    off[0, 14] = (7.0, 0.0, 0.0)       # LHip offset in the Waist frame
    ang[0, 0] = (0.0, 0.0, 90.0)       # Waist: rz = 90 deg
    ang[0, 1] = (90.0, 0.0, 0.0)       # Spine: rx = 90 deg
    p = U.forward_kinematics(off, ang)[0]
    # by hand: Rz(90) (0,10,0) = (-10,0,0); Rz(90) Rx(90) (0,5,0) = Rz(90) (0,0,5) = (0,0,5)
    np.testing.assert_allclose(p[0], (1, 2, 3), atol=1e-9)
    np.testing.assert_allclose(p[1], (1 - 10, 2, 3), atol=1e-9)
    np.testing.assert_allclose(p[2], (1 - 10, 2, 3 + 5), atol=1e-9)
    # LHip: Rz(90) (7,0,0) = (0,7,0); children of the root use the root's rotation only
    np.testing.assert_allclose(p[14], (1, 2 + 7, 3), atol=1e-9)
    # a joint's own angle does not move the joint itself, only its children
    ang2 = ang.copy()
    ang2[0, 2] = (30.0, 40.0, 50.0)
    np.testing.assert_allclose(U.forward_kinematics(off, ang2)[0, 2], p[2], atol=1e-9)


def test_file_frame_to_rep103_sensor_frame():
    # file: x subject's left (= sensor's right), y up, z towards the sensor; cm
    p = U.file_to_sensor(np.array([10.0, 100.0, -250.0]))
    np.testing.assert_allclose(p, (2.5, -0.1, 1.0))
    assert np.isclose(np.linalg.det(U.FILE_TO_SENSOR * 100), 1.0)  # a rotation, no mirror


def _is_ancestor(a, b):
    while b >= 0:
        if a == b:
            return True
        b = U.UIPRMD_PARENTS[b]
    return False


def test_mapping_keeps_the_tree():
    assert len(U.KINECT_FROM_UIPRMD) == 20 and set(U.KINECT_FROM_UIPRMD) == set(JOINT_NAMES)
    mapped = [s for s in U.SOURCE_INDEX if s >= 0]
    assert len(set(mapped)) == len(mapped)  # no UI-PRMD joint used twice
    for j, src in enumerate(U.SOURCE_INDEX):
        p = PARENTS[j]
        if p < 0 or src < 0:
            continue
        assert U.SOURCE_INDEX[p] >= 0
        assert _is_ancestor(U.SOURCE_INDEX[p], src) and U.SOURCE_INDEX[p] != src, JOINT_NAMES[j]
    assert U.SOURCE_INDEX[0] == U.UIPRMD_INDEX['Waist']
    assert set(U.MISSING_JOINTS) == {HAND_LEFT, HAND_RIGHT}


def test_hands_extrapolated_not_tracked():
    p22 = np.random.default_rng(0).normal(size=(4, 22, 3))
    p20, st = U.to_kinect20(p22)
    assert st[HAND_LEFT] == NOT_TRACKED and st[HAND_RIGHT] == NOT_TRACKED
    assert (np.delete(st, [HAND_LEFT, HAND_RIGHT]) == TRACKED).all()
    want = p20[:, WRIST_LEFT] + U.HAND_FOREARM_RATIO * (p20[:, WRIST_LEFT] - p20[:, ELBOW_LEFT])
    np.testing.assert_allclose(p20[:, HAND_LEFT], want)
    assert 0.2 < U.HAND_FOREARM_RATIO < 0.6


# ------------------------------------------------------------------------------------------
# Malformed files
# ------------------------------------------------------------------------------------------
def _good_rows(n=5):
    off = np.zeros((n, 22, 3))
    off[:, 0] = (0.0, 100.0, -250.0)
    off[:, 1:] = (0.0, 10.0, 0.0)
    return off.reshape(n, -1), np.zeros((n, 66))


def _write(path, rows, raw=None):
    path.parent.mkdir(parents=True, exist_ok=True)
    text = raw if raw is not None else '\n'.join(','.join(f'{v:.5f}' for v in r) for r in rows)
    with gzip.open(path, 'wt') as f:
        f.write(text)


def _make_src(tmp_path, name='m01_s09_e01', pos=None, ang=None, pos_raw=None):
    gp, ga = _good_rows()
    _write(tmp_path / 'Kinect' / 'Positions' / f'{name}_positions.txt.gz',
           gp if pos is None else pos, pos_raw)
    _write(tmp_path / 'Kinect' / 'Angles' / f'{name}_angles.txt.gz', ga if ang is None else ang)
    return tmp_path / 'Kinect' / 'Positions' / f'{name}_positions.txt.gz'


def test_good_tiny_file_loads(tmp_path):
    k = U.load_kinect_clip(_make_src(tmp_path))
    assert k.positions.shape == (5, 20, 3)
    np.testing.assert_allclose(k.positions[0, 0], (2.5, 0.0, 1.0))


@pytest.mark.parametrize('case', ['columns', 'nan', 'text', 'empty', 'truncated', 'frames',
                                  'missing', 'not_gzip'])
def test_malformed_file_raises_naming_file(tmp_path, case):
    gp, ga = _good_rows()
    if case == 'columns':
        p = _make_src(tmp_path, pos=gp[:, :-1])
    elif case == 'nan':
        bad = gp.copy()
        bad[2, 5] = np.nan
        p = _make_src(tmp_path, pos=bad)
    elif case == 'text':
        rows = '\n'.join(','.join(f'{v:.5f}' for v in r) for r in gp)
        p = _make_src(tmp_path, pos_raw=rows.replace('0.00000', 'abc', 1))
    elif case == 'empty':
        p = _make_src(tmp_path, pos_raw='')
    elif case == 'not_gzip':
        p = _make_src(tmp_path)
        p.write_bytes(b'this is not gzip data at all')
    elif case == 'frames':
        p = _make_src(tmp_path, pos=gp[:3])
    elif case == 'truncated':
        p = _make_src(tmp_path)
        data = p.read_bytes()
        p.write_bytes(data[:len(data) // 2])
    else:
        p = _make_src(tmp_path)
        (tmp_path / 'Kinect' / 'Angles' / 'm01_s09_e01_angles.txt.gz').unlink()
    with pytest.raises(U.UIPRMDFormatError) as ei:
        U.load_kinect_clip(p)
    assert 'm01_s09_e01' in str(ei.value)


def test_cli_skips_bad_files_and_writes_the_rest(tmp_path, capsys):
    from skeleton_eval import uiprmd_cli
    from skeleton_core.bagio import bag_topics, read_messages
    src = tmp_path / 'src'
    _make_src(src, 'm01_s09_e01')
    gp, _ = _good_rows()
    _make_src(src, 'm01_s09_e02', pos=gp[:, :-3])          # wrong column count
    bad = _make_src(src, 'm01_s09_e03')
    bad.write_bytes(bad.read_bytes()[:20])                  # truncated gzip
    out = tmp_path / 'out'
    rc = uiprmd_cli.main(['--src', str(src), '--out', str(out), '--quiet',
                          '--sensor-height', '0'])
    assert rc == 0
    text = capsys.readouterr().out
    assert '1 bags written' in text and '2 skipped' in text
    assert 'm01_s09_e02_positions' in text and 'm01_s09_e03_positions' in text
    topics = bag_topics(out / 'm01_s09_e01.mcap')
    assert topics == {'/kinect/skeletons': ('skeleton_msgs/msg/SkeletonArray', 5),
                      '/kinect/tracker': ('std_msgs/msg/String', 1)}   # the tracker travels
    from skeleton_core.tracker import from_bag
    assert from_bag(out / 'm01_s09_e01.mcap') == 'kinect_v2_sdk'
    stamps = [m.stamp_ns for m in read_messages(out / 'm01_s09_e01.mcap')]
    assert stamps == sorted(stamps) and len(set(stamps)) == 5
    assert not (out / 'm01_s09_e02.mcap').exists()


def test_real_clip_import(shared_dir, tmp_path):
    from skeleton_eval import uiprmd_cli
    from skeleton_core.bagio import bag_topics, read_messages
    from skeleton_core.conversions import frames_from_array_msg
    src = shared_dir / 'kinect' / 'ui-prmd'
    n = sum(1 for line in gzip.open(src / 'Kinect/Positions/m01_s02_e01_positions.txt.gz', 'rt')
            if line.strip())
    out = tmp_path / 'out'
    assert uiprmd_cli.main(['--src', str(src), '--out', str(out), '--subjects', 's02',
                            '--movements', 'm01,m07', '--repetitions', '1', '--quiet']) == 0
    topics = bag_topics(out / 'm01_s02_e01.mcap')
    assert topics['/kinect/skeletons'][1] == n
    assert 0.7 * n <= topics['/kinect/ground_truth'][1] <= n
    msgs = list(read_messages(out / 'm01_s02_e01.mcap', ['/kinect/skeletons']))
    stamps = [m.stamp_ns for m in msgs]
    assert all(b - a == 33_333_333 for a, b in zip(stamps, stamps[1:]))
    f = frames_from_array_msg(msgs[0].msg)[0]
    assert f.frame_id == 'kinect_link'
    assert 2.0 < f.positions[0, 0] < 3.0 and abs(f.positions[0, 1]) < 0.5  # ~2.5 m in front
    # default nominal sensor height 0.8 m: floor at z = -0.8, hips ~0.9-1.0 m above it
    assert 0.7 < f.positions[0, 2] + 0.8 < 1.2
    assert -0.9 < f.positions[[15, 19], 2].min() < -0.7                      # feet on the floor
    assert f.positions[3, 2] > f.positions[0, 2] + 0.4                       # head above hips
