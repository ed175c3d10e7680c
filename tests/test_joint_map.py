"""Joint maps (skeleton_data.joint_map): each shipped convention imported from a small file written
here, against joint positions worked out by hand; malformed maps refused in one line; the Vicon
posture database of a fold holds no clip of the held-out subject."""
import gzip
from pathlib import Path

import numpy as np
import pytest

from skeleton_core.geometry import quat_rotate
from skeleton_core.model import JOINT_INDEX, PARENTS, NUM_JOINTS
from skeleton_data import database_cli
from skeleton_data.database import MappedSource, load_or_build_default, uiprmd_vicon_source
from skeleton_data.joint_map import (JointMapError, axes_matrix, builtin_map, load_joint_map,
                                     maps_dir, parse_joint_map, rest_directions)
from skeleton_data.mocap import load_cmu_clip, load_mapped_clip
from skeleton_data.vicon import MARKERS

J = JOINT_INDEX
CMU_UNIT = 0.056444


def _bvh(tree, frames, frame_time=1 / 30):
    """BVH text from (name, offset, children, end_offset) with 3 rotation channels per joint (6 on
    the root: position first) and ``frames`` as {joint: (channel values)} per frame."""
    lines, order = ['HIERARCHY'], []

    def emit(node, depth, root=False):
        name, off, kids, end = node
        pad = '  ' * depth
        lines.append(f'{pad}{"ROOT" if root else "JOINT"} {name}')
        lines.append(pad + '{')
        lines.append(f'{pad}  OFFSET {off[0]} {off[1]} {off[2]}')
        ch = 'Xposition Yposition Zposition ' if root else ''
        lines.append(f'{pad}  CHANNELS {6 if root else 3} {ch}Zrotation Yrotation Xrotation')
        order.append((name, 6 if root else 3))
        for k in kids:
            emit(k, depth + 1)
        if end is not None:
            lines.extend([f'{pad}  End Site', pad + '  {',
                          f'{pad}    OFFSET {end[0]} {end[1]} {end[2]}', pad + '  }'])
        lines.append(pad + '}')
    emit(tree, 0, root=True)
    lines += ['MOTION', f'Frames: {len(frames)}', f'Frame Time: {frame_time}']
    for fr in frames:
        vals = []
        for name, n in order:
            vals += list(fr.get(name, (0.0,) * n))
        lines.append(' '.join(f'{v:g}' for v in vals))
    return '\n'.join(lines) + '\n'


def _check_orientations(clip):
    """The mocap convention: each orientation turns the segment's rest direction onto it."""
    a = rest_directions()
    p = clip.positions
    for j in range(1, NUM_JOINTS):
        seg = p[:, j] - p[:, PARENTS[j]]
        seg /= np.linalg.norm(seg, axis=-1, keepdims=True)
        got = quat_rotate(clip.orientations[:, j], np.broadcast_to(a[j], seg.shape))
        np.testing.assert_allclose(got, seg, atol=1e-9)


# --------------------------------------------------------------------------------------------
# cgspeed CMU BVH
# --------------------------------------------------------------------------------------------
def _cmu_tree():
    def arm(s, x):
        return (f'{s}Shoulder', (x, 1, 0), [(f'{s}Arm', (2 * x, 0, 0), [(f'{s}ForeArm', (3 * x, 0, 0), [
            (f'{s}Hand', (3 * x, 0, 0), [(f'{s}HandIndex1', (x, 0, 0), [], (0.5 * x, 0, 0))], None)],
            None)], None)], None)

    def leg(s, x):
        return (f'{s}UpLeg', (1.5 * x, -1, 0), [(f'{s}Leg', (0, -7, 0), [(f'{s}Foot', (0, -7, 0), [
            (f'{s}ToeBase', (0, -1, 2), [], (0, 0, 1))], None)], None)], None)
    spine1 = ('Spine1', (0, 2, 0), [('Head', (0, 2, 0), [], (0, 2, 0)), arm('Left', 1),
                                    arm('Right', -1)], None)
    return ('Hips', (0, 0, 0), [('LowerBack', (0, 2, 0), [('Spine', (0, 2, 0), [spine1], None)],
                                 None), leg('Left', 1), leg('Right', -1)], None)


def test_cmu_bvh_by_hand(tmp_path):
    # frame 0: the cgspeed T-pose (dropped); frame 1: hips at (10, 20, 30), left elbow bent 90 deg
    # about Z, a finger rotation that CMU did not capture (zeroed)
    frames = [{}, {'Hips': (10, 20, 30, 0, 0, 0), 'LeftForeArm': (90, 0, 0),
                   'LeftHandIndex1': (45, 0, 0)}]
    f = tmp_path / 'synthetic_cmu.bvh'
    f.write_text(_bvh(_cmu_tree(), frames + [frames[1]]))
    # by hand, BVH axes (file units): LeftForeArm = Hips + (0,6,0) + (1,1,0) + (2,0,0) + (3,0,0)
    # = (16, 27, 30); LeftHand = LeftForeArm + Rz(90) (3,0,0) = (16, 30, 30); the index finger
    # follows the hand's rotation only: (16, 31, 30); Head = mid(Head (10,28,30), end (10,30,30))
    bvh_pts = {'HipCenter': (10, 20, 30), 'Spine': (10, 24, 30), 'ShoulderCenter': (10, 27, 30),
               'Head': (10, 29, 30), 'ShoulderLeft': (13, 27, 30), 'ElbowLeft': (16, 27, 30),
               'WristLeft': (16, 30, 30), 'HandLeft': (16, 31, 30), 'ShoulderRight': (7, 27, 30),
               'WristRight': (1, 27, 30), 'HandRight': (0, 27, 30), 'HipLeft': (11.5, 19, 30),
               'KneeLeft': (11.5, 12, 30), 'AnkleLeft': (11.5, 5, 30), 'FootLeft': (11.5, 4, 32),
               'FootRight': (8.5, 4, 32)}
    for clip in (load_cmu_clip(f, 'other'), load_mapped_clip(f, builtin_map('cmu_bvh'))):
        assert len(clip) == 2  # T-pose frame dropped
        for name, (x, y, z) in bvh_pts.items():
            # REP-103 = (Z, X, Y) of the BVH, one CMU unit = 0.056444 m
            np.testing.assert_allclose(clip.positions[0, J[name]], CMU_UNIT * np.array([z, x, y]),
                                       atol=1e-9, err_msg=name)
        _check_orientations(clip)


# --------------------------------------------------------------------------------------------
# generic (Mixamo-style) BVH
# --------------------------------------------------------------------------------------------
def _mixamo_tree():
    ns = 'mixamorig:'

    def arm(s, x):
        return (ns + f'{s}Shoulder', (5 * x, 10, 0), [(ns + f'{s}Arm', (10 * x, 0, 0), [
            (ns + f'{s}ForeArm', (25 * x, 0, 0), [(ns + f'{s}Hand', (25 * x, 0, 0), [],
                                                    (16 * x, 0, 0))], None)], None)], None)

    def leg(s, x):
        return (ns + f'{s}UpLeg', (9 * x, -5, 0), [(ns + f'{s}Leg', (0, -40, 0), [
            (ns + f'{s}Foot', (0, -40, 0), [(ns + f'{s}ToeBase', (0, -8, 12), [], (0, 0, 8))],
             None)], None)], None)
    head = (ns + 'Neck', (0, 15, 0), [(ns + 'Head', (0, 10, 0), [
        (ns + 'HeadTop_End', (0, 20, 0), [], (0, 0, 0))], None)], None)
    spine2 = (ns + 'Spine2', (0, 10, 0), [head, arm('Left', 1), arm('Right', -1)], None)
    return (ns + 'Hips', (0, 0, 0), [(ns + 'Spine', (0, 10, 0), [(ns + 'Spine1', (0, 10, 0),
                                                                   [spine2], None)], None),
                                     leg('Left', 1), leg('Right', -1)], None)


def test_generic_bvh_by_hand(tmp_path):
    # frame 1: hips at (0, 100, 0) cm turned +90 deg about the BVH's Y (up): Ry(90) (x, y, z) =
    # (z, y, -x), so the body's left (+X) now points to -Z
    frames = [{'mixamorig:Hips': (0, 95, 0, 0, 0, 0)},
              {'mixamorig:Hips': (0, 100, 0, 0, 90, 0)}]
    f = tmp_path / 'mixamo.bvh'
    f.write_text(_bvh(_mixamo_tree(), frames))
    clip = load_mapped_clip(f, builtin_map('generic_bvh'))
    assert clip.name == 'mixamo' and len(clip) == 2 and clip.fps == pytest.approx(30)
    # by hand, Hips frame (cm): Spine1 (0,20,0); Spine2 (0,30,0); LeftArm (15,40,0);
    # LeftHand (65,40,0) and its end (81,40,0) -> hand = (73,40,0); Head (0,55,0),
    # HeadTop_End (0,75,0) -> head (0,65,0); LeftToeBase (9,-93,12)
    local = {'HipCenter': (0, 0, 0), 'Spine': (0, 20, 0), 'ShoulderCenter': (0, 40, 0),
             'Head': (0, 65, 0), 'ShoulderLeft': (15, 40, 0), 'ElbowLeft': (40, 40, 0),
             'WristLeft': (65, 40, 0), 'HandLeft': (73, 40, 0), 'HandRight': (-73, 40, 0),
             'HipLeft': (9, -5, 0), 'KneeLeft': (9, -45, 0), 'AnkleLeft': (9, -85, 0),
             'FootLeft': (9, -93, 12)}
    for name, (x, y, z) in local.items():
        for k, (bx, by, bz) in enumerate(((x, y + 95, z), (z, y + 100, -x))):
            # REP-103 = (Z, X, Y) of the BVH, centimetres
            np.testing.assert_allclose(clip.positions[k, J[name]], 0.01 * np.array([bz, bx, by]),
                                       atol=1e-9, err_msg=f'{name} frame {k}')
    _check_orientations(clip)


def test_axes_and_handedness():
    # CMU / Mixamo: Y up, facing +Z, right-handed -> the body's left is +X
    np.testing.assert_array_equal(axes_matrix('+Y', '+Z'), [[0, 0, 1], [1, 0, 0], [0, 1, 0]])
    # Unity-like (left-handed, Y up, Z forward, X right): left is -X, a mirror (det -1)
    m = axes_matrix('+Y', '+Z', 'left')
    np.testing.assert_array_equal(m, [[0, 0, 1], [-1, 0, 0], [0, 1, 0]])
    assert np.linalg.det(m) == pytest.approx(-1.0)
    np.testing.assert_array_equal(axes_matrix('+Z', '+X'), np.eye(3))
    np.testing.assert_array_equal(axes_matrix('+Z', '-Y'), [[0, -1, 0], [1, 0, 0], [0, 0, 1]])


# --------------------------------------------------------------------------------------------
# Plug-in-Gait markers
# --------------------------------------------------------------------------------------------
def _standing_markers():
    """A standing subject's 39 Plug-in-Gait markers, REP-103 metres (left side; right mirrored)."""
    left = {'LFHD': (0.08, 0.07, 1.70), 'LBHD': (-0.08, 0.07, 1.70), 'LSHO': (0.0, 0.19, 1.45),
            'LUPA': (0.02, 0.35, 1.40), 'LELB': (0.0, 0.50, 1.40), 'LFRM': (0.02, 0.65, 1.40),
            'LWRA': (0.03, 0.80, 1.40), 'LWRB': (-0.03, 0.80, 1.40), 'LFIN': (0.0, 0.88, 1.40),
            'LASI': (0.05, 0.12, 1.0), 'LPSI': (-0.10, 0.05, 1.0), 'LTHI': (0.05, 0.14, 0.70),
            'LKNE': (0.0, 0.13, 0.50), 'LTIB': (0.05, 0.12, 0.30), 'LANK': (0.0, 0.12, 0.08),
            'LHEE': (-0.05, 0.10, 0.05), 'LTOE': (0.15, 0.10, 0.03)}
    m = dict(left)
    for k, (x, y, z) in left.items():
        m['R' + k[1:]] = (x, -y, z)
    m.update({'C7': (-0.07, 0, 1.45), 'CLAV': (0.07, 0, 1.42), 'T10': (-0.09, 0, 1.25),
              'STRN': (0.09, 0, 1.25), 'RBAK': (-0.10, -0.08, 1.30)})
    assert set(m) == set(MARKERS)
    return m


def test_plug_in_gait_markers_by_hand(tmp_path):
    # A lab's export: Y up, facing +Z, centimetres, its own column order, one label renamed
    order = list(reversed(MARKERS))
    labels = ['L_ASIS' if c == 'LASI' else c for c in order]
    (tmp_path / 'lab.yaml').write_text(
        'format: markers\nmarker_set: plug_in_gait\naxes: {up: +Y, forward: +Z}\nunits: cm\n'
        f'frame_rate: 120\ncolumns: [{", ".join(labels)}]\nmarkers: {{L_ASIS: LASI}}\n')
    jm = load_joint_map(tmp_path / 'lab.yaml')
    m = _standing_markers()
    rows = []
    for k in range(3):
        vals = []
        for c in order:
            x, y, z = np.asarray(m[c]) + (0.5 * k, 0, 0)      # REP-103 m, walks forward
            src = (100 * y, 100 * z, 100 * x)               # (X, Y, Z) of the file: left, up, fwd
            vals += [0.0, 0.0, 0.0] if (k == 2 and c == 'LTOE') else src  # a gap on frame 2
        rows.append(','.join(f'{v:.6f}' for v in vals))
    f = tmp_path / 'trial_01.txt.gz'
    with gzip.open(f, 'wt') as fh:
        fh.write('\n'.join(rows) + '\n')
    clip = load_mapped_clip(f, jm)
    assert len(clip) == 2 and clip.fps == 120 and clip.name == 'trial_01'  # gap frame dropped
    p = clip.positions[0]
    # Bell et al. 1989: IAD 0.24 m, pelvis axes = REP axes: hip = ASIS + 0.24 (-0.22, -0.14, -0.30)
    np.testing.assert_allclose(p[J['HipLeft']], (-0.0028, 0.0864, 0.928), atol=1e-9)
    np.testing.assert_allclose(p[J['HipRight']], (-0.0028, -0.0864, 0.928), atol=1e-9)
    np.testing.assert_allclose(p[J['HipCenter']], (-0.0028, 0.0, 0.928), atol=1e-9)
    np.testing.assert_allclose(p[J['ShoulderCenter']], (0, 0, 1.435), atol=1e-9)  # mid C7/CLAV
    np.testing.assert_allclose(p[J['Spine']], (0, 0, 1.25), atol=1e-9)            # mid T10/STRN
    # Rab 2002: 17 % of the 0.38 m bi-acromial distance below the acromion marker
    np.testing.assert_allclose(p[J['ShoulderLeft']], (0, 0.19, 1.45 - 0.0646), atol=1e-9)
    np.testing.assert_allclose(p[J['WristLeft']], (0, 0.80, 1.40), atol=1e-9)     # mid WRA/WRB
    np.testing.assert_allclose(p[J['HandLeft']], (0, 0.84, 1.40), atol=1e-9)      # wrist..FIN
    np.testing.assert_allclose(p[J['FootLeft']], (0.15, 0.10, 0.023), atol=1e-9)  # TOE - radius
    np.testing.assert_allclose(p[J['Head']], (0, 0, 1.64), atol=1e-9)  # head band - 6 cm
    # chord function: the knee centre is knee_width/2 + marker radius medial of KNE, at a right
    # angle hip - knee - KNE; the elbow elbow_width/2 + radius from ELB
    for s in ('Left', 'Right'):
        kne = np.array(m[s[0] + 'KNE'])
        k = p[J['Knee' + s]]
        assert np.linalg.norm(k - kne) == pytest.approx(0.057, abs=1e-9)
        assert np.dot(p[J['Hip' + s]] - k, kne - k) == pytest.approx(0.0, abs=1e-9)
        assert abs(k[1]) < abs(kne[1])  # medial
        assert np.linalg.norm(p[J['Elbow' + s]] - m[s[0] + 'ELB']) == pytest.approx(0.042)
    np.testing.assert_allclose(clip.positions[1] - clip.positions[0],
                               np.broadcast_to((0.5, 0, 0), (NUM_JOINTS, 3)), atol=1e-9)
    _check_orientations(clip)
    # pelvis: facing +x, tilted about y by the hip-centre-to-spine lean (0.0028 m over 0.322 m)
    th = np.arctan2(0.0028, 0.322)
    np.testing.assert_allclose(clip.orientations[0, 0], (0, np.sin(th / 2), 0, np.cos(th / 2)),
                               atol=1e-9)


# --------------------------------------------------------------------------------------------
# malformed maps
# --------------------------------------------------------------------------------------------
GOOD = (maps_dir() / 'generic_bvh.yaml').read_text()


@pytest.mark.parametrize('edit, line, key, words', [
    (lambda t: t.replace('  ElbowLeft: LeftForeArm\n', '  Elbow: LeftForeArm\n'), None,
     'joints.Elbow', 'not a model joint'),
    (lambda t: t.replace('{LeftArm: 0.5, RightArm: 0.5}', '{LeftArm: 0.5, RightArm: 0.4}'), None,
     'joints.ShoulderCenter', 'sum to 0.9'),
    (lambda t: t.replace('units: cm', 'units: feet'), None, 'units', 'must be one of'),
    (lambda t: t.replace('forward: +Z', 'forward: -Y'), None, 'axes', 'different axes'),
    (lambda t: t.replace('  KneeRight: RightLeg\n', ''), None, 'joints', 'KneeRight'),
    (lambda t: t.replace('strip_namespace: true', 'strip_namespace: yes please'), None,
     'strip_namespace', 'true or false'),
    (lambda t: t + 'colour: blue\n', None, 'colour', 'unknown key'),
    (lambda t: t.replace('  HipCenter: Hips\n', '  HipCenter: [Hips\n'), 'yaml', '',
     'not valid YAML'),
])
def test_malformed_map_refused_in_one_line(tmp_path, edit, line, key, words):
    text = edit(GOOD)
    assert text != GOOD
    p = tmp_path / 'bad.yaml'
    p.write_text(text)
    with pytest.raises(JointMapError) as ei:
        load_joint_map(p)
    msg = str(ei.value)
    assert '\n' not in msg and msg.startswith(f'{p}:') and words in msg, msg
    if key:
        assert f': {key}: ' in msg, msg
        if key in ('joints.Elbow', 'units', 'colour', 'strip_namespace'):
            # the line of the offending key
            want = next(i for i, s in enumerate(text.splitlines(), 1)
                        if s.strip().startswith(key.split('.')[-1] + ':'))
            assert ei.value.line == want and msg.startswith(f'{p}:{want}: '), msg
    else:
        assert ei.value.line is not None


def test_map_that_does_not_fit_the_file(tmp_path):
    f = tmp_path / 'mixamo.bvh'
    f.write_text(_bvh(_mixamo_tree(), [{}, {}]))
    with pytest.raises(JointMapError, match=r'cmu_bvh\.yaml:\d+: joints\.HipCenter: .*mixamo\.bvh has no Hips$'):
        load_mapped_clip(f, builtin_map('cmu_bvh'))


def test_build_db_refuses_bad_map_without_traceback(tmp_path, capsys):
    (tmp_path / 'bad.yaml').write_text(GOOD.replace('units: cm', 'units: furlongs'))
    (tmp_path / 'clips').mkdir()
    rc = database_cli.main(['--bvh-dir', str(tmp_path / 'clips'), '--joint-map',
                            str(tmp_path / 'bad.yaml'), '--no-progress'])
    err = capsys.readouterr().err
    assert rc == 2 and 'Traceback' not in err
    assert err.strip().count('\n') == 0 and 'bad.yaml:' in err and 'units' in err, err


def test_shipped_maps_parse():
    for name in ('cmu_bvh', 'generic_bvh', 'plug_in_gait'):
        jm = builtin_map(name)
        assert jm.format in ('bvh', 'markers')
    assert builtin_map('plug_in_gait').scale == 0.001
    with pytest.raises(JointMapError, match='empty file'):
        parse_joint_map('', 'x.yaml')


# --------------------------------------------------------------------------------------------
# the Vicon-posture database of a fold
# --------------------------------------------------------------------------------------------
def _uiprmd_vicon(root: Path, subjects=(1, 2, 3), frames=6):
    """A UI-PRMD-like Vicon folder: one repetition per subject, 39 markers x (x,y,z) mm, z up."""
    d = root / 'Vicon' / 'Positions'
    d.mkdir(parents=True)
    m = _standing_markers()
    for s in subjects:
        rows = []
        for k in range(frames):
            # each subject raises the arms differently: postures far apart (never filtered)
            vals = []
            for c in MARKERS:
                x, y, z = m[c]
                if c[1:] in ('ELB', 'FRM', 'WRA', 'WRB', 'FIN', 'UPA'):
                    z += 0.1 * s * abs(y) + 0.02 * k
                vals += [1000 * x, 1000 * y, 1000 * z]
            rows.append(','.join(f'{v:.3f}' for v in vals))
        with gzip.open(d / f'm07_s{s:02d}_e01_positions.txt.gz', 'wt') as fh:
            fh.write('\n'.join(rows) + '\n')
    return d


def test_vicon_posture_database_excludes_held_out_subject(tmp_path, capsys):
    _uiprmd_vicon(tmp_path)
    src = uiprmd_vicon_source(tmp_path, exclude_subjects=[2])
    assert [f.name for f in src.files()] == ['m07_s01_e01_positions.txt.gz',
                                             'm07_s03_e01_positions.txt.gz']
    assert src.files() == uiprmd_vicon_source(tmp_path, subjects=[1, 3]).files()
    st = {}
    db = load_or_build_default('none', cache_dir=tmp_path / 'cache', threshold=0.0, mapped=[src],
                               stats=st)
    assert db.meta['clips'] == ['m07_s01_e01_positions', 'm07_s03_e01_positions']
    assert len(db) == 12 and set(db.posture_classes) == {'rehabilitation'}
    assert Path(st['path']).parent == tmp_path / 'cache' and not st['cache_hit']
    again = {}
    load_or_build_default('none', cache_dir=tmp_path / 'cache', threshold=0.0, mapped=[src],
                          stats=again)
    assert again['cache_hit'] and again['path'] == st['path']
    # the command line: CMU-less, s02 held out
    out = tmp_path / 'db.npz'
    rc = database_cli.main(['--source', 'none', '--marker-dir', str(tmp_path / 'Vicon' / 'Positions'),
                            '--exclude', 'm*_s02_*', '--no-filter', '--out', str(out),
                            '--no-progress'])
    assert rc == 0, capsys.readouterr().err
    from skeleton_data.database import MotionDatabase
    db2 = MotionDatabase.load(out)
    assert not any('_s02_' in c for c in db2.meta['clips']) and len(db2) == 12
    assert isinstance(src, MappedSource)


def test_fold_database_trains_on_the_other_subjects_only(tmp_path):
    from kinect_experiments.mocap_db_eval import fold_database
    _uiprmd_vicon(tmp_path, subjects=(1, 2, 3, 4))
    for held in (1, 3):
        db = fold_database(tmp_path, held, subjects=(1, 2, 3, 4), source='none',
                           cache_dir=tmp_path / 'cache')
        subjects = sorted({c.split('_')[1] for c in db.meta['clips']})
        assert subjects == [f's{s:02d}' for s in (1, 2, 3, 4) if s != held]
