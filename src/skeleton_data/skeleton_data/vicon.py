"""Marker reference: joint-centre estimates from the 39 Plug-in-Gait markers of UI-PRMD's Vicon.

The Vicon files hold 39 Plug-in-Gait (PiG) full-body markers x (x, y, z) in mm, lab frame, z up,
x roughly the subject's forward direction, y left, 100 Hz. Markers sit on the skin; the Kinect
reports joint centres, so we estimate joint centres from the markers with the usual published
rules. The subject measurements PiG asks for (knee/ankle/elbow widths, marker diameter) are not
part of the data set, so :class:`SubjectParams` uses typical adult values (documented there); each
of them moves a joint centre by at most a few centimetres.

Joint centres (Kinect v1 joint <- rule):

* HipLeft/HipRight: Bell, Brand & Pedersen, "Prediction of hip joint centre location from external
  landmarks", *Human Movement Science* 8:3-16, 1989 (the Tylkowski-type regression also used as
  "Bell et al." in gait labs): in the pelvis frame (origin mid-ASIS, y = RASI -> LASI, x forward in
  the ASIS/PSIS plane, z up) the hip centre is 22 % of the inter-ASIS distance (IAD) posterior,
  30 % IAD distal and 14 % IAD medial to the ipsilateral ASIS (i.e. 36 % IAD lateral of mid-ASIS).
* HipCenter: midpoint of the two hip centres (Kinect's HipCenter/SpineBase is the pelvis centre).
* KneeLeft/KneeRight: PiG "chord function" (Vicon Plug-in Gait reference guide; Davis, Ounpuu,
  Tyburski & Gage, "A gait analysis data collection and reduction technique", *Human Movement
  Science* 10:575-587, 1991): the knee centre K lies in the plane of hip centre, thigh marker THI
  and knee marker KNE, at distance knee_width/2 + marker_radius from KNE, such that the angle
  HJC-K-KNE is 90 deg.
* AnkleLeft/AnkleRight: the same chord function with (knee centre, TIB, ANK) and
  ankle_width/2 + marker_radius.
* FootLeft/FootRight: the TOE marker (2nd metatarsal head) lowered by the marker radius (Kinect v2
  FootLeft/Right sits on the forefoot).
* ShoulderLeft/ShoulderRight: Rab, Petuskey & Bagley, "A method for determination of upper
  extremity kinematics", *Gait & Posture* 15:113-119, 2002: the gleno-humeral centre is 17 % of the
  bi-acromial (LSHO-RSHO) distance below the acromion marker along the thorax vertical.
* ElbowLeft/ElbowRight: the lateral epicondyle marker ELB moved medially by
  elbow_width/2 + marker_radius along the flexion axis (the normal of the plane shoulder centre /
  ELB / wrist centre, as in PiG's chord construction); when the arm is nearly straight that plane
  is undefined and the medial direction falls back to the horizontal direction towards the thorax,
  perpendicular to the upper arm.
* WristLeft/WristRight: midpoint of the wrist-bar markers WRA and WRB (PiG's wrist centre with
  zero wrist thickness).
* HandLeft/HandRight: midpoint of the wrist centre and the FIN marker (2nd metacarpal head), i.e.
  the centre of the hand, where Kinect v1 puts its hand joint.
* ShoulderCenter: midpoint of C7 and CLAV (PiG thorax upper origin; Kinect v2 SpineShoulder).
* Spine: midpoint of T10 and STRN (PiG thorax lower origin; Kinect v2 SpineMid).
* Head: centroid of the four head markers LFHD, RFHD, LBHD, RBHD (PiG head segment origin level)
  lowered by head_drop, the marker band sitting ~6 cm above the head centre (default 0.06 m).

The reference is a joint-centre *estimate*: regression errors of 1-3 cm for the hip (Bell 1989)
and marker-placement error of ~1 cm are part of it.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Tuple

import numpy as np

from skeleton_core.model import (ANKLE_LEFT, ANKLE_RIGHT, ELBOW_LEFT, ELBOW_RIGHT, FOOT_LEFT, FOOT_RIGHT,
                    HAND_LEFT, HAND_RIGHT, HEAD, HIP_CENTER, HIP_LEFT, HIP_RIGHT, KNEE_LEFT,
                    KNEE_RIGHT, NUM_JOINTS, SHOULDER_CENTER, SHOULDER_LEFT, SHOULDER_RIGHT, SPINE,
                    WRIST_LEFT, WRIST_RIGHT)
from .uiprmd import read_table

FRAME_RATE = 100.0  # Hz

MARKERS: Tuple[str, ...] = (
    'LFHD', 'RFHD', 'LBHD', 'RBHD', 'C7', 'T10', 'CLAV', 'STRN', 'RBAK',
    'LSHO', 'LUPA', 'LELB', 'LFRM', 'LWRA', 'LWRB', 'LFIN',
    'RSHO', 'RUPA', 'RELB', 'RFRM', 'RWRA', 'RWRB', 'RFIN',
    'LASI', 'RASI', 'LPSI', 'RPSI',
    'LTHI', 'LKNE', 'LTIB', 'LANK', 'LHEE', 'LTOE',
    'RTHI', 'RKNE', 'RTIB', 'RANK', 'RHEE', 'RTOE',
)
MARKER_INDEX: Dict[str, int] = {n: i for i, n in enumerate(MARKERS)}
NUM_MARKERS = len(MARKERS)
NUM_COLUMNS = 3 * NUM_MARKERS  # 117

# Bell, Brand & Pedersen 1989: hip centre relative to the ipsilateral ASIS, fractions of IAD
BELL_POSTERIOR, BELL_DISTAL, BELL_MEDIAL = 0.22, 0.30, 0.14
# Rab et al. 2002: shoulder centre below the acromion marker, fraction of bi-acromial distance
RAB_SHOULDER_DROP = 0.17


@dataclass(frozen=True)
class SubjectParams:
    """PiG subject measurements not in UI-PRMD; typical adult values (m)."""

    marker_radius: float = 0.007   # 14 mm markers
    knee_width: float = 0.100
    ankle_width: float = 0.070
    elbow_width: float = 0.070
    head_drop: float = 0.06        # head marker band above the head centre


def read_vicon(path) -> np.ndarray:
    """(N, 39, 3) marker positions in metres (lab frame), validated (see uiprmd.read_table).

    A few files are not gap-filled at their ends: the missing marker is written as exactly
    (0, 0, 0) (e.g. CLAV in m10_s02_e01 frames 0-47, LASI in m07_s04_e01). Those samples are
    returned as NaN, so every joint centre built from them is NaN on those frames (and takes no
    part in the registration, the ground-truth topic or any score)."""
    m = read_table(Path(path), NUM_COLUMNS).reshape(-1, NUM_MARKERS, 3) / 1000.0
    m[np.all(np.abs(m) < 1e-6, axis=-1)] = np.nan
    return m


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-12)


def chord(hip: np.ndarray, wand: np.ndarray, marker: np.ndarray, delta: float) -> np.ndarray:
    """PiG chord function: the point C in plane (hip, wand, marker) with |C - marker| = delta and
    angle hip-C-marker = 90 deg, on the side of the line hip-marker away from ``wand``.

    All inputs (..., 3). ``hip`` is the proximal joint centre, ``marker`` the lateral marker at
    the joint, ``wand`` the lateral segment marker (THI/TIB).
    """
    a = marker - hip
    length = np.linalg.norm(a, axis=-1, keepdims=True)
    ua = a / np.maximum(length, 1e-12)  # hip -> marker
    w = wand - hip
    perp = w - np.sum(w * ua, -1, keepdims=True) * ua
    m = -_unit(perp)  # in-plane, perpendicular to hip-marker, away from the wand (medial)
    # Thales: C on the circle with diameter hip-marker; |C - marker| = delta
    d = np.minimum(delta, 0.999 * length)
    cos_b = d / length            # angle at marker between marker->hip and marker->C
    sin_b = np.sqrt(1.0 - cos_b ** 2)
    return marker + d * (cos_b * (-ua) + sin_b * m)


def joint_centres(markers: np.ndarray, params: SubjectParams = SubjectParams()) -> np.ndarray:
    """Kinect v1 joint-centre estimates (N, 20, 3) from PiG markers (N, 39, 3), same frame/units."""
    mk = np.asarray(markers, dtype=float)
    g = {n: mk[:, i] for n, i in MARKER_INDEX.items()}
    out = np.zeros((mk.shape[0], NUM_JOINTS, 3))

    # Pelvis frame and hips (Bell et al. 1989)
    lasi, rasi = g['LASI'], g['RASI']
    mid_asis = 0.5 * (lasi + rasi)
    mid_psis = 0.5 * (g['LPSI'] + g['RPSI'])
    y = _unit(lasi - rasi)
    fwd = mid_asis - mid_psis
    x = _unit(fwd - np.sum(fwd * y, -1, keepdims=True) * y)
    z = np.cross(x, y)
    iad = np.linalg.norm(lasi - rasi, axis=-1, keepdims=True)
    for hip, asis, side in ((HIP_LEFT, lasi, 1.0), (HIP_RIGHT, rasi, -1.0)):
        out[:, hip] = asis + iad * (-BELL_POSTERIOR * x - BELL_DISTAL * z
                                    - side * BELL_MEDIAL * y)
    out[:, HIP_CENTER] = 0.5 * (out[:, HIP_LEFT] + out[:, HIP_RIGHT])

    # Legs (PiG chord function)
    r = params.marker_radius
    for s, hip, knee, ankle, foot in (('L', HIP_LEFT, KNEE_LEFT, ANKLE_LEFT, FOOT_LEFT),
                                      ('R', HIP_RIGHT, KNEE_RIGHT, ANKLE_RIGHT, FOOT_RIGHT)):
        out[:, knee] = chord(out[:, hip], g[s + 'THI'], g[s + 'KNE'], params.knee_width / 2 + r)
        out[:, ankle] = chord(out[:, knee], g[s + 'TIB'], g[s + 'ANK'],
                              params.ankle_width / 2 + r)
        out[:, foot] = g[s + 'TOE'] - np.array([0.0, 0.0, r])

    # Thorax
    top = 0.5 * (g['C7'] + g['CLAV'])
    bottom = 0.5 * (g['T10'] + g['STRN'])
    out[:, SHOULDER_CENTER] = top
    out[:, SPINE] = bottom
    tz = _unit(top - bottom)

    # Arms
    biacromial = np.linalg.norm(g['LSHO'] - g['RSHO'], axis=-1, keepdims=True)
    for s, sh, el, wr, hd, sign in (('L', SHOULDER_LEFT, ELBOW_LEFT, WRIST_LEFT, HAND_LEFT, 1.0),
                                    ('R', SHOULDER_RIGHT, ELBOW_RIGHT, WRIST_RIGHT, HAND_RIGHT,
                                     -1.0)):
        sjc = g[s + 'SHO'] - RAB_SHOULDER_DROP * biacromial * tz
        wjc = 0.5 * (g[s + 'WRA'] + g[s + 'WRB'])
        elb = g[s + 'ELB']
        upper = _unit(elb - sjc)
        fore = wjc - elb
        n = np.cross(upper, fore)
        nn = np.linalg.norm(n, axis=-1, keepdims=True)
        # medial = +n for the left arm, -n for the right (see docstring geometry)
        flex_dir = sign * n / np.maximum(nn, 1e-12)
        to_thorax = 0.5 * (top + bottom) - elb
        to_thorax = to_thorax - np.sum(to_thorax * upper, -1, keepdims=True) * upper
        fallback = _unit(to_thorax)
        sin_flex = nn / np.maximum(np.linalg.norm(fore, axis=-1, keepdims=True), 1e-12)
        wgt = np.clip((sin_flex - 0.2) / 0.3, 0.0, 1.0)  # full flexion-plane weight above ~30 deg
        medial = _unit(wgt * flex_dir + (1.0 - wgt) * fallback)
        out[:, sh] = sjc
        out[:, el] = elb + (params.elbow_width / 2 + r) * medial
        out[:, wr] = wjc
        out[:, hd] = 0.5 * (wjc + g[s + 'FIN'])

    head = 0.25 * (g['LFHD'] + g['RFHD'] + g['LBHD'] + g['RBHD'])
    hz = _unit(head - 0.5 * (g['C7'] + g['CLAV']))  # neck base -> head marker centroid
    out[:, HEAD] = head - params.head_drop * hz
    return out


def load_reference(path, params: SubjectParams = SubjectParams()) -> np.ndarray:
    """Read a Vicon file and return the joint-centre reference (N, 20, 3) m at 100 Hz."""
    return joint_centres(read_vicon(path), params)


def vicon_path_for(src, clip_name: str) -> Path:
    return Path(src) / 'Vicon' / 'Positions' / f'{clip_name}_positions.txt.gz'
