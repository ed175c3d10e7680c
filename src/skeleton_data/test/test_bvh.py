"""BVH parser: structure, forward kinematics against hand-computed values, errors name file+line."""
import numpy as np
import pytest

from skeleton_data.bvh import BvhError, load_bvh, parse_bvh

GOOD = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Chest
  {
    OFFSET 0 2 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    End Site
    {
      OFFSET 0 1 0
    }
  }
  JOINT Leg
  {
    OFFSET 1 0 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    End Site
    {
      OFFSET 0 -3 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333
1 2 3 0 0 0 0 0 0 0 0 0
0 0 0 90 0 0 0 0 90 0 0 0
"""


def test_structure_and_fk():
    b = parse_bvh(GOOD, 'good.bvh')
    assert b.names == ['Hips', 'Chest', 'Leg']
    assert b.parents == [-1, 0, 0]
    assert b.channel_start == [0, 6, 9]
    assert b.motion.shape == (2, 12)
    assert b.fps == pytest.approx(30.0, rel=1e-5)
    pos, rot, ends = b.forward_kinematics(scale=2.0)
    # frame 0: pure translation
    np.testing.assert_allclose(pos[0], 2 * np.array([[1, 2, 3], [1, 4, 3], [2, 2, 3]]))
    np.testing.assert_allclose(ends[0], 2 * np.array([[1, 5, 3], [2, -1, 3]]))
    # frame 1: root turned 90 deg about z: chest offset (0,2,0) -> (-2,0,0), leg (1,0,0) -> (0,1,0)
    np.testing.assert_allclose(pos[1, 1], 2 * np.array([-2, 0, 0]), atol=1e-9)
    np.testing.assert_allclose(pos[1, 2], 2 * np.array([0, 1, 0]), atol=1e-9)
    # chest End Site: root Rz(90), chest Xrot 90: (0,1,0) -> Rx (0,0,1) -> Rz (0,0,1)
    np.testing.assert_allclose(ends[1, 0], 2 * np.array([-2, 0, 1]), atol=1e-9)
    np.testing.assert_allclose(rot[1, 0] @ [1, 0, 0], [0, 1, 0], atol=1e-9)


def test_channel_order_is_intrinsic():
    # Zrotation 90 then Xrotation 90 (intrinsic): R = Rz Rx; applied to (0, 1, 0): Rx -> (0,0,1)
    text = GOOD.replace('0 0 0 90 0 0 0 0 90 0 0 0', '0 0 0 90 0 90 0 0 0 0 0 0')
    b = parse_bvh(text)
    _, rot, _ = b.forward_kinematics()
    np.testing.assert_allclose(rot[1, 0] @ [0, 1, 0], [0, 0, 1], atol=1e-9)
    np.testing.assert_allclose(rot[1, 0] @ [1, 0, 0], [0, 1, 0], atol=1e-9)


def _err(text, tmp_path, name='bad.bvh'):
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(BvhError) as e:
        load_bvh(p)
    return e.value, str(e.value)


def test_truncated_motion_names_file_and_line(tmp_path):
    text = GOOD.rsplit('\n', 2)[0] + '\n'  # drop the last motion line
    err, msg = _err(text, tmp_path)
    assert msg.startswith(f'{tmp_path / "bad.bvh"}:')
    assert 'truncated MOTION' in msg and 'Frames: 2' in msg
    assert err.line == len(text.splitlines()) + 1


def test_unknown_channel_names_line(tmp_path):
    text = GOOD.replace('CHANNELS 3 Zrotation Yrotation Xrotation',
                        'CHANNELS 3 Zrotation Wrotation Xrotation')
    err, msg = _err(text, tmp_path)
    assert err.line == 9 and 'bad.bvh:9:' in msg and "'Wrotation'" in msg


def test_bad_number_names_line(tmp_path):
    text = GOOD.replace('0 0 0 90 0 0 0 0 90 0 0 0', '0 0 0 90 0 0 0 x 90 0 0 0')
    err, msg = _err(text, tmp_path)
    assert err.line == 29 and 'bad number' in msg


def test_wrong_count_and_unbalanced_braces(tmp_path):
    err, msg = _err(GOOD.replace('0 0 0 90 0 0 0 0 90 0 0 0', '0 0 0 90 0'), tmp_path)
    assert err.line == 29 and 'expected 12' in msg
    lines = GOOD.splitlines()
    del lines[22]  # line 23: the '}' closing Leg
    err, msg = _err('\n'.join(lines) + '\n', tmp_path)
    assert 'unbalanced braces' in msg and err.line == 3  # ROOT's '{' never closed
    err, msg = _err(GOOD.replace('MOTION', '}\nMOTION'), tmp_path)
    assert 'unbalanced braces' in msg and err.line == 25


def test_missing_file_and_header_errors(tmp_path):
    with pytest.raises(BvhError, match='cannot read'):
        load_bvh(tmp_path / 'nope.bvh')
    err, msg = _err(GOOD.replace('Frames: 2', 'Frames: two'), tmp_path)
    assert err.line == 26 and 'frame count' in msg
    err, msg = _err(GOOD.replace('HIERARCHY', 'HIERARCH'), tmp_path)
    assert err.line == 1
