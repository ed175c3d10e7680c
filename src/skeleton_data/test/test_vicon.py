"""Plug-in-Gait joint-centre reference from the Vicon markers."""
import numpy as np

from skeleton_data import vicon as V
from skeleton_core.model import (ANKLE_LEFT, HEAD, HIP_CENTER, HIP_LEFT, HIP_RIGHT, KNEE_LEFT,
                                 NUM_JOINTS, SHOULDER_LEFT, segment_lengths, SEGMENT_NAMES)


def test_marker_table():
    assert V.NUM_MARKERS == 39 and V.NUM_COLUMNS == 117 and len(set(V.MARKERS)) == 39


def test_chord_function_geometry():
    hip = np.array([0.0, 0.09, 0.95])
    knee_marker = np.array([0.0, 0.15, 0.50])
    thigh = np.array([0.02, 0.19, 0.72])  # lateral of the line hip-knee marker
    d = 0.057
    c = V.chord(hip, thigh, knee_marker, d)
    assert np.isclose(np.linalg.norm(c - knee_marker), d)
    assert np.isclose(np.dot(hip - c, knee_marker - c), 0.0, atol=1e-12)   # right angle at C
    n = np.cross(thigh - hip, knee_marker - hip)
    assert np.isclose(np.dot(c - hip, n), 0.0, atol=1e-12)                 # in the plane
    assert c[1] < knee_marker[1]                                            # medial (towards y=0)


def _pelvis_markers():
    m = np.zeros((1, V.NUM_MARKERS, 3))
    idx = V.MARKER_INDEX
    m[0, idx['LASI']] = (0.0, 0.12, 1.0)
    m[0, idx['RASI']] = (0.0, -0.12, 1.0)
    m[0, idx['LPSI']] = (-0.15, 0.05, 1.0)
    m[0, idx['RPSI']] = (-0.15, -0.05, 1.0)
    return m


def test_bell_hip_centres():
    m = _pelvis_markers()
    out = V.joint_centres(m)
    iad = 0.24
    np.testing.assert_allclose(out[0, HIP_LEFT], (-0.22 * iad, 0.12 - 0.14 * iad, 1 - 0.30 * iad),
                               atol=1e-12)
    np.testing.assert_allclose(out[0, HIP_RIGHT], (-0.22 * iad, -0.12 + 0.14 * iad,
                                                   1 - 0.30 * iad), atol=1e-12)
    np.testing.assert_allclose(out[0, HIP_CENTER], (-0.22 * iad, 0.0, 1 - 0.30 * iad), atol=1e-12)


def test_real_vicon_reference_is_a_plausible_skeleton(shared_dir):
    path = shared_dir / 'kinect/ui-prmd/Vicon/Positions/m01_s02_e01_positions.txt.gz'
    ref = V.load_reference(path)
    assert ref.shape[1:] == (NUM_JOINTS, 3) and np.isfinite(ref).all()
    first = ref[0]
    assert first[HEAD, 2] > first[SHOULDER_LEFT, 2] > first[HIP_CENTER, 2] > first[KNEE_LEFT, 2] \
        > first[ANKLE_LEFT, 2] > 0.0
    lengths = dict(zip(SEGMENT_NAMES, segment_lengths(ref).mean(0)))
    assert 0.35 < lengths['HipLeft-KneeLeft'] < 0.5       # thigh
    assert 0.33 < lengths['KneeLeft-AnkleLeft'] < 0.48    # shank
    assert 0.22 < lengths['ShoulderLeft-ElbowLeft'] < 0.36
    assert 0.06 < lengths['HipCenter-HipLeft'] < 0.11
    # thigh length varies little over a deep squat (the estimate moves ~2 cm with flexion)
    assert segment_lengths(ref)[:, SEGMENT_NAMES.index('HipLeft-KneeLeft')].std() < 0.025


def test_tilted_pelvis_rotates_the_hip_offsets():
    m = _pelvis_markers()
    ang = np.radians(20.0)  # rotate the whole marker set about y: hips follow the pelvis frame
    rot = np.array([[np.cos(ang), 0, np.sin(ang)], [0, 1, 0], [-np.sin(ang), 0, np.cos(ang)]])
    out0 = V.joint_centres(m)
    out1 = V.joint_centres(m @ rot.T)
    np.testing.assert_allclose(out1[0, HIP_LEFT], out0[0, HIP_LEFT] @ rot.T, atol=1e-12)
