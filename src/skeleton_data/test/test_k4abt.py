"""The K4ABT (Azure Kinect / Orbbec Femto body tracking) input: the joint map, the axes, the
MarkerArray codec for both Marker layouts, captures joined from split messages, bodies coming and
going, missing joints, malformed input, confidence levels and the SDK JSON importer."""
import json
import struct

import numpy as np
import pytest

from skeleton_core.marker_cdr import MarkerArrayDecoder, MarkerCdrError, decode_markers
from skeleton_core.model import (HAND_LEFT, HEAD, INFERRED, NOT_TRACKED, SHOULDER_CENTER,
                                 TRACKED, standard_body)
from skeleton_data import k4abt as K


class _W:
    """A little-endian CDR writer (alignment from the end of the 4-byte encapsulation)."""

    def __init__(self):
        self.b = bytearray(b'\x00\x01\x00\x00')

    def al(self, k):
        while (len(self.b) - 4) % k:
            self.b.append(0)

    def put(self, fmt, *v):
        self.al(struct.calcsize('<' + fmt.lstrip('0123456789')[0]))
        self.b += struct.pack('<' + fmt, *v)

    def s(self, text):
        d = text.encode() + b'\0'
        self.put('I', len(d))
        self.b += d


def encode(markers, layout='iron'):
    """``markers``: (stamp_ns, frame, id, type, action, (x, y, z)) -> MarkerArray CDR."""
    w = _W()
    w.put('I', len(markers))
    for stamp, frame, mid, mtype, action, pos in markers:
        w.put('iI', *divmod(stamp, 1_000_000_000))
        w.s(frame)
        w.s('')
        w.put('iii', mid, mtype, action)
        w.put('7d', *pos, 0.0, 0.0, 0.0, 1.0)
        w.put('3d', 0.05, 0.05, 0.05)
        w.put('4f', 1, 0, 0, 1)
        w.put('iI', 0, 250_000_000)
        w.put('B', 0)
        w.put('I', 0)          # points
        w.put('I', 0)          # colors
        if layout == 'iron':
            w.s('')            # texture_resource
            w.put('iI', 0, 0)
            w.s('')
            w.s('')
            w.put('I', 0)      # texture data
            w.put('I', 0)      # uv
        w.s('')                # text
        w.s('')                # mesh_resource
        if layout == 'iron':
            w.s('')
            w.put('I', 0)
        w.put('B', 0)
    return bytes(w.b)


def _person(x=2.5, y=0.0):
    p = standard_body().rest_positions() * np.array([-1.0, -1.0, 1.0]) + [x, y, -0.8]
    return p


def _markers(bodies, stamp, frame='depth_camera_link', drop=()):
    cam = K.camera_to_sensor()
    out = []
    for body, p in bodies:
        k = K.k4abt_from_model(p) @ cam
        for j in range(K.NUM_K4ABT):
            if (body, j) not in drop:
                out.append((stamp, frame, body * 100 + j, 2, 0, tuple(k[j])))
    return out


def test_the_shipped_map_covers_every_model_joint_and_uses_the_extra_joints():
    m = K.load_map()
    assert len(m.anchor) == 20 and len(set(K.JOINTS)) == 32
    used = set(m.anchor)
    for r in m.refine:
        if r is not None:
            used |= set(r[0])
            assert r[1].sum() == pytest.approx(1.0)
    names = {K.JOINTS[i] for i in used}
    for j in ('CLAVICLE_LEFT', 'CLAVICLE_RIGHT', 'NECK', 'HANDTIP_LEFT', 'THUMB_RIGHT', 'NOSE',
              'EYE_LEFT', 'EAR_RIGHT'):
        assert j in names
    import yaml
    good = yaml.safe_load((K.maps_dir() / 'k4abt.yaml').read_text())
    for change, why in (({'Spine': {'NECK': 0.5}}, 'weights sum'),
                        ({'HipCenter': 'HIPS'}, 'unknown K4ABT joint'),
                        ({'Pelvis': 'PELVIS'}, 'unknown model joint')):
        with pytest.raises(K.K4abtError, match=why):
            K.parse_map({**good, 'joints': {**good['joints'], **change}}, 'x.yaml')
    del good['joints']['Head']
    with pytest.raises(K.K4abtError, match='Head has no K4ABT joint'):
        K.parse_map(good, 'x.yaml')


def test_depth_camera_axes_and_tilt_reach_the_rep103_sensor_frame():
    r = K.camera_to_sensor(0.0)
    # optical: x right, y down, z forward -> x forward, y left, z up
    assert np.allclose(r @ [0, 0, 1], [1, 0, 0]) and np.allclose(r @ [1, 0, 0], [0, -1, 0])
    assert np.allclose(r @ [0, 1, 0], [0, 0, -1])
    # the depth camera looks 6 deg down: a point on its axis is below the housing's horizon
    ahead = K.camera_to_sensor() @ [0, 0, 2.0]
    assert ahead[2] == pytest.approx(-2.0 * np.sin(np.radians(6.0)))
    assert ahead[0] == pytest.approx(2.0 * np.cos(np.radians(6.0)))


@pytest.mark.parametrize('layout', ['iron', 'humble'])
def test_markers_of_either_layout_become_the_model_skeleton(layout):
    p = _person()
    data = encode(_markers([(1, p)], 5_000_000_000), layout)
    dec = MarkerArrayDecoder()
    assert len(dec(data)) == 32 and dec.layout == layout
    s = K.MarkerStream(live=True)
    out = s.feed(data, 5_040_000_000)
    assert len(out) == 1
    stamp, frames = out[0]
    assert stamp == 5_000_000_000 and len(frames) == 1 and frames[0].user_id == 1
    assert np.allclose(frames[0].positions, p, atol=1e-9)
    assert (frames[0].tracking_state == TRACKED).all()   # markers carry no state
    assert frames[0].frame_id == 'kinect_link'


def test_bodies_come_and_go_and_a_missing_joint_is_not_tracked():
    s = K.MarkerStream(live=True)
    got = []
    a, b = _person(2.5, 0.3), _person(3.2, -0.6)
    t = 1_000_000_000
    seq = [[(1, a)], [(1, a), (2, b)], [(1, a), (2, b)], [(2, b)], [], [(7, a)]]
    for i, bodies in enumerate(seq):
        drop = {(2, K.K4ABT_INDEX['HAND_LEFT'])} if i == 2 else ()
        stamp = t + i * 33_333_333
        got += s.feed(encode(_markers(bodies, stamp, drop=drop)), stamp + 40_000_000)
    assert [sorted(f.user_id for f in fr) for _, fr in got] == [[1], [1, 2], [1, 2], [2], [], [7]]
    third = {f.user_id: f for f in got[2][1]}[2]
    assert third.tracking_state[HAND_LEFT] == NOT_TRACKED
    assert (np.delete(third.tracking_state, HAND_LEFT) == TRACKED).all()
    assert np.all(np.isfinite(third.positions))
    # the empty capture (nobody seen) comes between its neighbours in time
    stamps = [st for st, _ in got]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    assert s.counts['missing_joints'] == 1


def test_a_capture_split_over_messages_is_joined():
    a, b = _person(2.5, 0.3), _person(3.2, -0.6)
    t = 2_000_000_000
    ms = _markers([(1, a), (2, b)], t)
    nxt = _markers([(1, a), (2, b)], t + 33_333_333)
    # bag: split by body and by joints, finished by the next capture
    s = K.MarkerStream(live=False)
    out = s.feed(encode(ms[:32]), t + 1) + s.feed(encode(ms[32:50]), t + 2) + \
        s.feed(encode(ms[50:]), t + 3) + s.feed(encode(nxt), t + 33_333_334) + s.flush()
    assert [sorted(f.user_id for f in fr) for _, fr in out] == [[1, 2], [1, 2]]
    assert all((f.tracking_state == TRACKED).all() for _, fr in out for f in fr)
    # live: joints split over messages wait for the rest (or for the hold time)
    s = K.MarkerStream(live=True)
    assert s.feed(encode(ms[:20]), t + 1) == []
    out = s.feed(encode(ms[20:64]), t + 2)
    assert [sorted(f.user_id for f in fr) for _, fr in out] == [[1, 2]]
    assert s.feed(encode(ms[:10]), t + 3) == [] and s.counts['late_markers'] == 10
    s.feed(encode(nxt[:5]), t + 40_000_000)
    assert s.flush(t + 45_000_000, hold_ns=20_000_000) == []
    late = s.flush(t + 70_000_000, hold_ns=20_000_000)
    assert len(late) == 1 and late[0][1][0].tracking_state[HEAD] == NOT_TRACKED


def test_malformed_input_is_counted_and_warned_once_never_raised():
    warned = []
    s = K.MarkerStream(warn=warned.append)
    t = 3_000_000_000
    good = _markers([(1, _person())], t)
    bad = list(good)
    bad[3] = (t, 'depth_camera_link', 1 * 100 + 40, 2, 0, (0.0, 0.0, 1.0))   # joint 40
    bad[4] = (t, 'depth_camera_link', 104, 1, 0, (0.0, 0.0, 1.0))            # a CUBE
    bad[5] = (t, 'depth_camera_link', 105, 2, 0, (float('nan'), 0.0, 1.0))
    for junk in (b'', b'\x00\x01\x00\x00\xff\xff\xff\x7f', encode(good)[:-40], b'\x01' * 100):
        assert s.feed(junk, t) == []
    out = s.feed(encode(bad), t)
    assert s.counts['malformed_messages'] == 4 and s.counts['malformed_markers'] == 3
    assert len(out) == 0                 # two joints missing: waits for more...
    out = s.flush()
    assert len(out) == 1 and len(out[0][1]) == 1
    assert len(warned) == 2, warned      # once per kind
    with pytest.raises(MarkerCdrError):
        decode_markers(b'\x00\x01\x00\x00\x05\x00\x00\x00', 'iron')


def test_sdk_confidence_levels_become_tracking_states(tmp_path):
    p = _person()
    k = K.k4abt_from_model(p) @ K.camera_to_sensor()
    conf = [K.CONF_MEDIUM] * 32
    conf[K.K4ABT_INDEX['HAND_LEFT']] = K.CONF_LOW       # occluded, predicted
    conf[K.K4ABT_INDEX['HEAD']] = K.CONF_NONE           # out of range
    conf[K.K4ABT_INDEX['CLAVICLE_LEFT']] = K.CONF_LOW   # a refining joint less sure: not used
    frames = [{'frame_id': i, 'num_bodies': 1, 'timestamp_usec': 1000 + 33333 * i,
               'bodies': [{'body_id': 4, 'joint_positions': (k * 1000).tolist(),
                           'joint_orientations': [[1, 0, 0, 0]] * 32,
                           'confidence_levels': conf}]} for i in range(5)]
    frames.append({'frame_id': 5, 'timestamp_usec': 1000 + 33333 * 5, 'bodies': [{'junk': 1}]})
    src = tmp_path / 'offline.json'
    src.write_text(json.dumps({'k4abt_sdk_version': '1.1.2', 'joint_names': list(K.JOINTS),
                               'frames': frames}))
    got = list(K.read_offline_json(src))
    assert len(got) == 6 and got[-1][1] == [] and K.read_offline_json.skipped == 1
    f = got[0][1][0]
    assert f.user_id == 4 and got[0][0] == 1_000_000
    assert f.tracking_state[HAND_LEFT] == INFERRED and f.tracking_state[HEAD] == NOT_TRACKED
    assert (np.delete(f.tracking_state, [HAND_LEFT, HEAD]) == TRACKED).all()
    # the shoulder centre falls back to the neck alone (a clavicle was LOW)
    neck = K.camera_to_sensor() @ k[K.K4ABT_INDEX['NECK']]
    assert np.allclose(f.positions[SHOULDER_CENTER], neck, atol=1e-9)
    # imported to a bag that declares the tracker
    from skeleton_core import tracker as T
    from skeleton_core.bagio import read_messages
    from skeleton_core.cdr import frames_from_cdr
    s = K.import_offline_json(src, tmp_path / 'offline.mcap')
    assert s['frames'] == 6 and s['users'] == [4]
    assert T.from_bag(tmp_path / 'offline.mcap') == 'azure_kinect_bt'
    n = [len(frames_from_cdr(m.data)[2]) for m in
         read_messages(tmp_path / 'offline.mcap', topics=['/kinect/skeletons'], decode=False)]
    assert n == [1, 1, 1, 1, 1, 0]
    bad = tmp_path / 'bad.json'
    bad.write_text('{"bodies": []}')
    with pytest.raises(K.K4abtError, match='offline_processor'):
        list(K.read_offline_json(bad))
    assert K.main([str(bad)]) == 1
