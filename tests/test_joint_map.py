"""Joint-map import (YAML: source joint -> model joint, axes, units) against frames computed by
hand: a BVH chain and Plug-in-Gait pelvis markers; the built-in maps; malformed maps refused."""
import numpy as np
import pytest

from skeleton_core.model import JOINT_INDEX, JOINT_NAMES
from skeleton_data import joint_map as J
from skeleton_data.bvh import parse_bvh

BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT LeftUpLeg
  {
    OFFSET 10 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT LeftLeg
    {
      OFFSET 0 -40 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 -40 0
      }
    }
  }
}
MOTION
Frames: 1
Frame Time: 0.0333333
100 90 5 0 0 0 0 90 0 0 0 0
"""


def _map(**over):
    joints = {n: 'Hips' for n in JOINT_NAMES}
    joints.update(KneeLeft='LeftLeg', FootLeft='LeftLeg/End', HipLeft='LeftUpLeg',
                  AnkleLeft={'LeftLeg': 0.5, 'LeftLeg/End': 0.5}, Spine=['Hips', 'LeftUpLeg'])
    return {'format': J.FORMAT, 'version': 1, 'source': 'bvh', 'units': 'cm',
            'axes': ['z', 'x', 'y'], 'joints': joints, **over}


def test_bvh_through_a_joint_map_matches_the_hand_computed_frame():
    jm = J.parse(_map())
    out = J.from_bvh(parse_bvh(BVH), jm)[0]
    # by hand, source cm: Hips (100, 90, 5); LeftUpLeg +(10, 0, 0); its X rotation of 90 deg turns
    # the (0, -40, 0) offsets into (0, 0, -40): LeftLeg (110, 90, -35), its End Site (110, 90, -75).
    # REP-103 = (z, x, y) / 100
    expect = {'HipCenter': (0.05, 1.00, 0.90), 'HipLeft': (0.05, 1.10, 0.90),
              'KneeLeft': (-0.35, 1.10, 0.90), 'FootLeft': (-0.75, 1.10, 0.90),
              'AnkleLeft': (-0.55, 1.10, 0.90), 'Spine': (0.05, 1.05, 0.90)}
    for name, p in expect.items():
        np.testing.assert_allclose(out[JOINT_INDEX[name]], p, atol=1e-9, err_msg=name)


def test_plug_in_gait_through_a_joint_map_matches_the_hand_computed_hips():
    jm = J.builtin('plug_in_gait')
    rng = np.random.default_rng(0)
    rep = {n: rng.normal(scale=0.3, size=3) + (0, 0, 1.0) for n in jm.markers}
    rep.update(LASI=np.array([0.0, 0.12, 1.0]), RASI=np.array([0.0, -0.12, 1.0]),
               LPSI=np.array([-0.15, 0.05, 1.0]), RPSI=np.array([-0.15, -0.05, 1.0]))
    # the source: y up, z forward, x left, mm (REP x, y, z = source z, x, y)
    jm.axes = J._axes(['z', 'x', 'y'], 'test')
    src = np.array([[1000 * rep[n][1], 1000 * rep[n][2], 1000 * rep[n][0]] for n in jm.markers])
    out = J.from_markers(src[None], jm)[0]
    # Bell 1989 by hand: IAD 0.24 m; 22 % back, 30 % down, 14 % in from each ASIS
    np.testing.assert_allclose(out[JOINT_INDEX['HipLeft']], (-0.0528, 0.0864, 0.928), atol=1e-9)
    np.testing.assert_allclose(out[JOINT_INDEX['HipRight']], (-0.0528, -0.0864, 0.928), atol=1e-9)
    np.testing.assert_allclose(out[JOINT_INDEX['HipCenter']], (-0.0528, 0.0, 0.928), atol=1e-9)


def test_builtin_cmu_map_equals_the_cmu_importer():
    from skeleton_data import mocap
    jm = J.builtin('cmu_cgspeed')
    assert jm.scale == pytest.approx(mocap.CMU_UNIT)
    np.testing.assert_array_equal(jm.axes, mocap.BVH_TO_REP103)
    for name, terms in mocap.CMU_TO_KINECT.items():
        assert dict(jm.joints[name]) == pytest.approx(dict(terms)), name
    assert set(J.builtin_names()) >= {'cmu_cgspeed', 'generic_bvh', 'plug_in_gait'}
    assert J.builtin('generic_bvh').strip_prefix == 'mixamorig:'


@pytest.mark.parametrize('over, words', [
    ({'format': 'other'}, 'not a version 1'),
    ({'source': 'fbx'}, 'source must be one of'),
    ({'units': 'furlong'}, 'units'),
    ({'axes': ['z', 'x']}, 'three source axes'),
    ({'axes': ['z', 'z', 'y']}, 'repeat'),
    ({'axes': ['-z', 'x', 'y']}, 'mirror'),
    ({'joints': {'HipCenter': 'Hips'}}, 'not mapped'),
    ({'joints': {**{n: 'Hips' for n in JOINT_NAMES}, 'Head': {'Head': 0.4}}}, 'sum to'),
])
def test_malformed_joint_maps_are_refused_in_one_line(over, words):
    with pytest.raises(J.JointMapError) as e:
        J.parse(_map(**over), 'lab.yaml')
    assert words in str(e.value) and '\n' not in str(e.value)


def test_a_missing_source_joint_is_named(tmp_path):
    jm = J.parse(_map(joints={**{n: 'Hips' for n in JOINT_NAMES}, 'Head': 'Neck'}))
    with pytest.raises(J.JointMapError, match="'Neck'"):
        J.from_bvh(parse_bvh(BVH), jm)
    (tmp_path / 'bad.yaml').write_text('format: [')
    with pytest.raises(J.JointMapError, match='not valid YAML'):
        J.load(tmp_path / 'bad.yaml')
