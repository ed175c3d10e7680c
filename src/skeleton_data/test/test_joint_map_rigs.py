"""Joint maps that accept real rigs: a BVH whose every joint has 6 channels, whose End
Sites sit at offset 0 and that has no finger joints builds a database through the shipped generic
map (a copy written by the test) with no warning; a zero-length segment the map cannot avoid is
refused naming the joint and the fix; a point beyond a joint (extrapolation) is expressible;
``build_db --check`` prints the mapped segment lengths against the standard body."""
from __future__ import annotations

import logging
import warnings

import numpy as np
import pytest

from skeleton_core.model import JOINT_INDEX, segment_lengths
from skeleton_data.bvh import load_bvh
from skeleton_data.joint_map import JointMapError, bvh_frames, maps_dir, parse_joint_map

# (name, parent, offset in cm: Y up, facing +Z); End Sites at offset 0 on every chain end
RIG = [
    ('Hips', None, (0, 95, 0)),
    ('Spine', 'Hips', (0, 10, 0)), ('Spine1', 'Spine', (0, 15, 0)),
    ('Neck', 'Spine1', (0, 22, 0)), ('Head', 'Neck', (0, 10, 0)),
    ('LeftShoulder', 'Spine1', (4, 18, 0)), ('LeftArm', 'LeftShoulder', (14, 0, 0)),
    ('LeftForeArm', 'LeftArm', (28, 0, 0)), ('LeftHand', 'LeftForeArm', (25, 0, 0)),
    ('RightShoulder', 'Spine1', (-4, 18, 0)), ('RightArm', 'RightShoulder', (-14, 0, 0)),
    ('RightForeArm', 'RightArm', (-28, 0, 0)), ('RightHand', 'RightForeArm', (-25, 0, 0)),
    ('LeftUpLeg', 'Hips', (9, -5, 0)), ('LeftLeg', 'LeftUpLeg', (0, -43, 0)),
    ('LeftFoot', 'LeftLeg', (0, -42, 0)), ('LeftToeBase', 'LeftFoot', (0, -6, 13)),
    ('RightUpLeg', 'Hips', (-9, -5, 0)), ('RightLeg', 'RightUpLeg', (0, -43, 0)),
    ('RightFoot', 'RightLeg', (0, -42, 0)), ('RightToeBase', 'RightFoot', (0, -6, 13)),
]
CHANNELS = 'Xposition Yposition Zposition Zrotation Xrotation Yrotation'


def _bvh_text(frames=40, seed=0):
    kids = {}
    for name, parent, _ in RIG:
        kids.setdefault(parent, []).append(name)
    off = {n: o for n, _, o in RIG}
    lines = ['HIERARCHY']

    def emit(name, depth):
        pad = '  ' * depth
        lines.append(f'{pad}{"ROOT" if depth == 0 else "JOINT"} {name}')
        lines.append(f'{pad}{{')
        lines.append(f'{pad}  OFFSET {off[name][0]} {off[name][1]} {off[name][2]}')
        lines.append(f'{pad}  CHANNELS 6 {CHANNELS}')
        if name in kids:
            for k in kids[name]:
                emit(k, depth + 1)
        else:   # End Site at offset 0: a zero-length end segment
            lines.extend([f'{pad}  End Site', f'{pad}  {{', f'{pad}    OFFSET 0 0 0', f'{pad}  }}'])
        lines.append(f'{pad}}}')

    emit('Hips', 0)
    rng = np.random.default_rng(seed)
    lines += ['MOTION', f'Frames: {frames}', 'Frame Time: 0.0333333']
    n = len(RIG)
    phase = rng.uniform(0, 2 * np.pi, size=(n, 3))
    for f in range(frames):
        row = []
        for j, (name, _, o) in enumerate(RIG):
            pos = [0.0, 95.0, 0.0] if j == 0 else [0.0, 0.0, 0.0]
            rot = 15.0 * np.sin(0.2 * f + phase[j]) * (j > 0)
            row += pos + list(rot)
        lines.append(' '.join(f'{v:.4f}' for v in row))
    return '\n'.join(lines) + '\n'


@pytest.fixture
def rig_dir(tmp_path):
    d = tmp_path / 'studio'
    d.mkdir()
    for k in range(3):
        (d / f'take{k}.bvh').write_text(_bvh_text(seed=k))
    # the lab's map: written from the shipped generic one
    (tmp_path / 'studio_map.yaml').write_text((maps_dir() / 'generic_bvh.yaml').read_text())
    return d


def test_a_rig_with_zero_length_end_sites_and_no_fingers_builds_a_database_without_warning(
        rig_dir, tmp_path, caplog):
    from skeleton_data.database import MotionDatabase
    from skeleton_data.database_cli import main
    out = tmp_path / 'db.npz'
    with warnings.catch_warnings():
        warnings.simplefilter('error')          # a numpy RuntimeWarning would fail the test
        with caplog.at_level(logging.WARNING):
            rc = main(['--source', 'none', '--bvh-dir', str(rig_dir), '--joint-map',
                       str(tmp_path / 'studio_map.yaml'), '--out', str(out), '--no-progress'])
    assert rc == 0
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING], caplog.text
    db = MotionDatabase.load(str(out))
    assert len(db) > 0 and np.isfinite(np.asarray(db.positions)).all()


def test_the_hand_is_placed_past_the_wrist_when_the_rig_has_no_fingers(rig_dir, tmp_path):
    jm = parse_joint_map((tmp_path / 'studio_map.yaml').read_text(), 'studio_map.yaml')
    kin, q = bvh_frames(load_bvh(rig_dir / 'take0.bvh'), jm)
    assert np.isfinite(kin).all() and np.isfinite(q).all()
    lens = segment_lengths(kin)
    assert (lens > 0.01).all()
    w, e, h = (kin[:, JOINT_INDEX[n]] for n in ('WristLeft', 'ElbowLeft', 'HandLeft'))
    # 35 % of the forearm past the wrist, along the forearm
    np.testing.assert_allclose(h, w + 0.35 * (w - e), atol=1e-6)


def test_an_unavoidable_zero_length_segment_is_refused_naming_the_joint_and_the_fix(rig_dir,
                                                                                     tmp_path):
    text = (tmp_path / 'studio_map.yaml').read_text()
    import re
    text = re.sub(r'  HandLeft: \[.*?\]\n', '  HandLeft: {LeftHand: 0.5, LeftHand/End: 0.5}\n',
                  text, flags=re.S)
    jm = parse_joint_map(text, 'bad_map.yaml')
    with pytest.raises(JointMapError) as e:
        bvh_frames(load_bvh(rig_dir / 'take0.bvh'), jm)
    msg = str(e.value)
    assert 'joints.HandLeft' in msg and 'lands on its parent WristLeft' in msg
    assert 'HandLeft: {LeftHand: 1.35, LeftForeArm: -0.35}' in msg    # the fix, spelled out
    assert '\n' not in msg


def test_weights_may_extrapolate_but_not_vanish(tmp_path):
    text = (maps_dir() / 'generic_bvh.yaml').read_text().replace(
        'Head: [', 'Head: [{Head: 1.5, Neck: -0.5}, ', 1)
    jm = parse_joint_map(text, 'm.yaml')
    assert jm.joints['Head'][0] == (('Head', 1.5), ('Neck', -0.5))    # above the neck's end
    with pytest.raises(JointMapError, match='non-zero'):
        parse_joint_map(text.replace('Head: 1.5, Neck: -0.5', 'Head: 1.0, Neck: 0'), 'm.yaml')
    with pytest.raises(JointMapError, match='sum to'):
        parse_joint_map(text.replace('Head: 1.5, Neck: -0.5', 'Head: 1.5, Neck: -0.2'), 'm.yaml')


def test_build_db_check_prints_segment_lengths_against_the_standard_body(rig_dir, tmp_path,
                                                                         capsys):
    from skeleton_data.database_cli import main
    rc = main(['--source', 'none', '--bvh-dir', str(rig_dir), '--joint-map',
               str(tmp_path / 'studio_map.yaml'), '--out', str(tmp_path / 'db.npz'),
               '--check', '--no-progress'])
    assert rc == 0
    out = capsys.readouterr().out
    assert 'standard body' in out
    for k in range(3):
        row = next(line for line in out.splitlines() if line.startswith(f'take{k}.bvh'))
        assert len(row.split()) == 1 + 19                      # one length per segment
