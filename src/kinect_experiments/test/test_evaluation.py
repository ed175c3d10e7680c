"""Evaluation harness: registry, baselines on a tiny clip, an oracle scoring 0, reports."""
import json
from dataclasses import replace

import numpy as np
import pytest

from skeleton_core.model import HAND_LEFT, NOT_TRACKED, NUM_JOINTS, TRACKED
from skeleton_eval import evaluation as E
from skeleton_eval.baselines import HoltMethod, RawMethod
from skeleton_eval.clips import toy_clip
from skeleton_eval.figures import _database_postures, fig5, fig8
from skeleton_eval.registry import (Method, available_methods, load_plugins, make_method, method_info,
                                    register_method)
from skeleton_eval.report import json_safe, to_json, to_markdown
from skeleton_eval.sensor_model import SensorModel
from skeleton_eval.table3 import (TABLE3_SUBSETS, calibration_frames, calibration_stream, subset_frames,
                                  table3)


class Oracle:
    """Replays the true joints of the streams in order (reset() moves to the next stream)."""

    name = 'oracle'

    def __init__(self, streams):
        self.truths = [s.truth for s in streams]
        self.k = -1
        self.i = 0

    def reset(self):
        self.k = (self.k + 1) % len(self.truths)
        self.i = 0

    def process(self, frame):
        out = frame.copy(positions=self.truths[self.k][self.i].copy())
        self.i += 1
        return out


def test_registry_has_the_baselines_and_accepts_plugins():
    assert {'raw', 'holt', 'one_euro'} <= set(available_methods())
    register_method('test_raw', RawMethod, 'test', {'x': 1})
    assert 'test_raw' in available_methods()
    assert method_info('test_raw')['defaults'] == {'x': 1}
    assert isinstance(make_method('test_raw'), Method)
    with pytest.raises(KeyError):
        make_method('no_such_method')
    st = load_plugins(('no_such_package_xyz.methods',))
    assert st['no_such_package_xyz.methods'].startswith('skipped')
    holt = make_method('holt', smoothing=0.7)
    assert holt.params['smoothing'] == 0.7 and holt.params['prediction'] == 0.5


def test_harness_raw_filters_and_oracle():
    clip = toy_clip(4.0)
    streams = E.make_streams([clip], ('a', 'c'), seed=0, sensor=SensorModel(seed=0))
    flat = [s for lst in streams.values() for s in lst]
    res = E.evaluate_streams(['raw', 'holt', 'one_euro', lambda: Oracle(flat)], streams)
    r = res['results']
    assert set(r) == {'raw', 'holt', 'one_euro', 'oracle'}
    for sc in ('a', 'c'):
        raw = r['raw'][sc]['metrics']
        assert raw['eq18_cm']['overall'] > 0.5 and raw['mpjpe_cm']['overall'] > 0.5
        assert r['oracle'][sc]['metrics']['eq18_cm']['overall'] == pytest.approx(0.0, abs=1e-9)
        assert r['oracle'][sc]['metrics']['mpjpe_cm']['overall'] == pytest.approx(0.0, abs=1e-9)
        assert r['raw'][sc]['frames'] == 120 and r['raw'][sc]['missing_frames'] == 0
        # the filters reduce jitter (mean acceleration)
        assert r['holt'][sc]['metrics']['jitter_ms2']['overall'] < raw['jitter_ms2']['overall']
        assert r['one_euro'][sc]['metrics']['jitter_ms2']['overall'] < raw['jitter_ms2']['overall']
        assert r['holt'][sc]['time']['mean_ms'] > 0
    res['experiment'] = 'table4'
    md = to_markdown(res)
    assert '| raw |' in md and '| oracle |' in md and 'Eq. 18' in md
    back = json.loads(to_json(res))
    assert back['results']['oracle']['a']['metrics']['eq18_cm']['overall'] == 0.0


def test_evaluate_states_data_seed_and_parameters():
    clip = toy_clip(2.0)
    res = E.evaluate(['raw'], [clip], scenarios=('b',), seed=3, data_source='toy')
    meta = res['meta']
    assert meta['seed'] == 3 and meta['data']['source'] == 'toy'
    assert meta['data']['clips'][0]['name'] == clip.name
    assert meta['sensor_params']['placement']['distance_m'] == 2.5
    assert 'b' in res['sensor_statistics']['scenarios']
    md = to_markdown(res)
    assert 'seed 3' in md and 'Sensor model noise statistics' in md


def test_table3_subsets():
    clip = toy_clip(2.0)
    s = SensorModel(seed=0).corrupt(clip, 'clean')
    frames = subset_frames(s, TABLE3_SUBSETS['b'][1])
    f = frames[10]
    assert f.tracking_state[HAND_LEFT] == TRACKED and f.reliability[HAND_LEFT] == 1.0
    others = [j for j in range(NUM_JOINTS) if j not in TABLE3_SUBSETS['b'][1]]
    assert np.all(f.tracking_state[others] == NOT_TRACKED) and np.all(f.reliability[others] == 0)
    assert np.allclose(f.positions[others], s.positions[0][others])
    res = table3(['raw'], [clip], subsets=('b', 'e'))
    assert res['results']['raw']['b']['metrics']['eq18_cm']['overall'] > 1.0
    # against the input skeleton (the paper's reference) raw with all parts is exact
    assert res['results']['raw']['e']['metrics']['eq18_cm']['overall'] == pytest.approx(0.0)
    res_t = table3(['raw'], [clip], subsets=('e',), reference='truth')
    assert res_t['results']['raw']['e']['metrics']['eq18_cm']['overall'] > 1.0
    assert 'Table III' in to_markdown(res)


def test_fig5_pca_matching():
    rng = np.random.default_rng(0)
    # postures on a 3-D subspace of the 60-D space plus a little noise
    basis = rng.standard_normal((3, 60))
    db = (rng.standard_normal((300, 3)) @ basis + 0.001 * rng.standard_normal((300, 60)))
    q = db[:50] + 0.001 * rng.standard_normal((50, 60))
    res = fig5(db.reshape(-1, 20, 3), q.reshape(-1, 20, 3), dims=(1, 3, 10, 60), repeats=1)
    pct = {r['dims']: r['error_pct'] for r in res['rows']}
    assert pct[60] == 0.0
    assert pct[1] > pct[3] and abs(pct[3]) < 5.0
    assert 'Fig. 5' in to_markdown(res)


def test_fig8_sweeps_with_overrides():
    register_method('holt_sweep', lambda k=1, **kw: HoltMethod(smoothing=min(0.9, 0.1 * k)))
    res = fig8('holt_sweep', [toy_clip(2.0)], params=('k',), sweeps={'k': (1, 5)},
                 max_frames=40)
    rows = res['sweeps']['k']
    assert [r['value'] for r in rows] == [1, 5] and all('eq18_cm' in r for r in rows)
    res = fig8('raw', [toy_clip(1.0)], params=('k',), sweeps={'k': (3,)}, max_frames=10)
    assert 'skipped' in res['sweeps']['k'][0]  # RawMethod takes no k


def test_evaluate_cli_writes_markdown_and_json(tmp_path, capsys):
    ev = pytest.importorskip('kinect_experiments.evaluate')
    rc = ev.run(['--source', 'builtin', '--methods', 'raw,holt', '--max-frames', '15',
                 '--scenarios', 'a', '--out', str(tmp_path), '--quiet'])
    assert rc == 0
    md = (tmp_path / 'table4.md').read_text()
    assert '| raw |' in md and '| holt |' in md and 'builtin' in md
    data = json.loads((tmp_path / 'table4.json').read_text())
    assert data['meta']['seed'] == 0 and data['results']['raw']['a']['frames'] > 0
    assert 'Sensor model noise statistics' in capsys.readouterr().out
    assert ev.run(['--methods', 'no_such_method', '--out', str(tmp_path)]) == 2


# ------------------------------------------------------------------------------------------
# Table III calibration protocol
# ------------------------------------------------------------------------------------------
class Recorder:
    """Returns every frame unchanged and keeps a copy of each (class-level, for inspection)."""

    name = 'recorder'
    seen = []

    def reset(self):
        pass

    def process(self, frame):
        Recorder.seen.append(frame.copy())
        return frame


def test_calibration_stream_is_the_same_user_in_a_tpose_all_tracked():
    from skeleton_core.model import ELBOW_LEFT, SHOULDER_LEFT, SHOULDER_RIGHT, segment_lengths
    clip = toy_clip(2.0)
    sensor = SensorModel(seed=0)
    s = sensor.corrupt(clip, 'clean', seed=0)
    cs = calibration_stream(sensor, clip, 'tpose', seed=0, seconds=1.0,
                              start_ns=int(s.stamps_ns[0]))
    assert len(cs) == 30 and cs.scenario == 'clean'
    # stamps: 30 Hz, ending one frame before the subset stream starts
    assert np.all(np.diff(cs.stamps_ns) > 0) and cs.stamps_ns[-1] == s.stamps_ns[0] - 33333333
    # the true skeleton is the clip's (standard) body standing still in a T-pose: arms level
    # with the shoulders, the same segment lengths as the clip, at the stream's distance
    assert np.ptp(cs.truth, axis=0).max() < 1e-9
    assert abs(cs.truth[0, HAND_LEFT, 2] - cs.truth[0, SHOULDER_LEFT, 2]) < 1e-6
    assert abs(cs.truth[0, ELBOW_LEFT, 2] - cs.truth[0, SHOULDER_LEFT, 2]) < 1e-6
    assert np.allclose(segment_lengths(cs.truth[0]), segment_lengths(s.truth[0]), atol=1e-6)
    assert abs(cs.truth[0, 0, 0] - np.mean(s.truth[:, 0, 0])) < 0.05
    # noisy like the stream (cm level), every joint reported
    err = np.linalg.norm(cs.positions - cs.truth, axis=-1)
    assert 0.002 < err.mean() < 0.10
    frames = calibration_frames(cs)
    assert len(frames) == 30
    for f in frames:
        assert np.all(f.tracking_state == TRACKED) and np.all(f.reliability == 1.0)
    # standing: the same skeleton with the arms hanging down
    st = calibration_stream(sensor, clip, 'standing', seed=0, seconds=0.5)
    assert len(st) == 15
    assert st.truth[0, HAND_LEFT, 2] < st.truth[0, SHOULDER_LEFT, 2] - 0.4
    assert np.allclose(segment_lengths(st.truth[0]), segment_lengths(s.truth[0]), atol=1e-6)
    assert abs(np.linalg.norm(st.truth[0, HAND_LEFT] - st.truth[0, SHOULDER_RIGHT]) -
               np.linalg.norm(cs.truth[0, HAND_LEFT] - cs.truth[0, SHOULDER_RIGHT])) > 0.3


def test_calibration_is_the_same_session_with_independent_noise():
    clip = toy_clip(2.0)
    quiet = SensorModel({'jitter': {'depth_coeff_mm': 0.0,
                                    'base_mm': {g: 0.0 for g in ('torso', 'head', 'shoulder',
                                                                 'elbow', 'wrist', 'hand', 'hip',
                                                                 'knee', 'ankle', 'foot')}},
                         'slow_drift': {'sigma_mm': {g: 0.0 for g in (
                             'torso', 'head', 'shoulder', 'elbow', 'wrist', 'hand', 'hip', 'knee',
                             'ankle', 'foot')}}}, seed=0)
    s = quiet.corrupt(clip, 'clean', seed=4)
    cs = calibration_stream(quiet, clip, 'tpose', seed=4)
    # only the systematic joint-centre offsets are left: the same per joint (rotated with the
    # body, so compare lengths) as in the clip's stream
    off_s = np.linalg.norm(s.positions - s.truth, axis=-1)
    off_c = np.linalg.norm(cs.positions - cs.truth, axis=-1)
    assert off_s.mean() > 0.01
    assert np.allclose(off_c, off_s[0][None], atol=1e-9)
    # another seed is another session
    other = calibration_stream(quiet, clip, 'tpose', seed=5)
    assert not np.allclose(np.linalg.norm(other.positions - other.truth, axis=-1), off_c, atol=1e-3)
    # with the default noise, the calibration's random noise is not the stream's first second
    noisy = SensorModel(seed=0)
    s = noisy.corrupt(clip, 'clean', seed=0)
    cs = calibration_stream(noisy, clip, 'tpose', seed=0)
    de = (cs.positions - cs.truth) - (s.positions[:30] - s.truth[:30])
    assert np.abs(de).max() > 0.005


def test_table3_calibration_frames_are_fed_first_and_not_scored():
    clip = toy_clip(2.0)  # 60 frames
    runs = {}
    for cal in ('none', 'tpose'):
        Recorder.seen = []
        res = table3([Recorder, 'raw'], [clip], subsets=('c', 'e'), calibration=cal)
        runs[cal] = (list(Recorder.seen), res)
    seen_none, res_none = runs['none']
    seen_cal, res_cal = runs['tpose']
    assert len(seen_none) == 2 * 60 and len(seen_cal) == 2 * (30 + 60)
    for k in range(2):  # subsets c and e
        cal, sub = seen_cal[k * 90:k * 90 + 30], seen_cal[k * 90 + 30:(k + 1) * 90]
        old = seen_none[k * 60:(k + 1) * 60]
        # calibration: every joint tracked with reliability 1, before the subset frames
        assert all(np.all(f.tracking_state == TRACKED) and np.all(f.reliability == 1) for f in cal)
        assert max(f.stamp_ns for f in cal) < sub[0].stamp_ns
        # the subset frames are exactly those of the protocol without calibration
        for a, b in zip(sub, old):
            assert np.array_equal(a.positions, b.positions)
            assert np.array_equal(a.tracking_state, b.tracking_state)
            assert np.array_equal(a.reliability, b.reliability) and a.stamp_ns == b.stamp_ns
    for res in (res_none, res_cal):
        r = res['results']
        assert r['raw']['c']['frames'] == 60 and r['raw']['c']['missing_frames'] == 0
        # scored frames are the subset frames only: raw with all parts is the input itself
        assert r['raw']['e']['metrics']['eq18_cm']['overall'] == pytest.approx(0.0, abs=1e-12)
    # the same scores for a method that ignores the calibration
    for k in ('c', 'e'):
        assert (res_cal['results']['raw'][k]['metrics']['eq18_cm']['overall'] ==
                res_none['results']['raw'][k]['metrics']['eq18_cm']['overall'])
    assert res_none['calibration']['pose'] == 'none' and res_none['calibration']['frames'] == 0
    assert res_cal['calibration'] == {**res_cal['calibration'], 'pose': 'tpose', 'frames': 30,
                                      'seconds': 1.0, 'scored': False}
    assert res_cal['meta']['calibration']['pose'] == 'tpose'
    md_none, md_cal = to_markdown(res_none), to_markdown(res_cal)
    assert 'calibration: none' in md_none and 'calibration: tpose' in md_none.replace(
        'none', 'tpose') and '| method (calibration: none) |' in md_none
    assert '| method (calibration: tpose) |' in md_cal and '30 frames' in md_cal
    assert json.loads(to_json(res_cal))['calibration']['pose'] == 'tpose'
    with pytest.raises(ValueError):
        table3(['raw'], [clip], subsets=('e',), calibration='sitting')


def test_table3_none_is_the_old_protocol():
    """calibration='none' runs exactly what table3 ran before the option existed."""
    clip = toy_clip(2.0)
    res = table3(['holt'], [clip], subsets=('b',), calibration='none', seed=2)
    sensor = SensorModel(None, seed=2)
    base = E.make_streams([clip], ('clean',), 2, None, sensor)['clean']
    base = [replace(s, truth=s.positions.copy()) for s in base]
    old = E.evaluate_streams(['holt'], {'b': base},
                             frame_transform=lambda s: subset_frames(s, TABLE3_SUBSETS['b'][1]))
    # bit for bit (NaN -> None: the root has no Eq. 18 term)
    assert (json_safe(res['results']['holt']['b']['metrics']) ==
            json_safe(old['results']['holt']['b']['metrics']))
    # the calibration changes a stateful method's output (the filter starts from the T-pose)
    cal = table3(['holt'], [clip], subsets=('b',), calibration='tpose', seed=2)
    a = cal['results']['holt']['b']['metrics']['eq18_cm']['overall']
    b = res['results']['holt']['b']['metrics']['eq18_cm']['overall']
    assert a != b and abs(a - b) < 0.5 * b


def test_method_c_takes_its_segment_lengths_from_the_calibration():
    rc = pytest.importorskip('pose_reconstruction.reconstructor')
    from skeleton_core.model import SEGMENT_CHILDREN, MIRROR, segment_lengths
    clip = toy_clip(2.0)
    db = _database_postures(clips=[toy_clip(4.0, name='db')])
    sensor = SensorModel(seed=0)
    s = sensor.corrupt(clip, 'clean', seed=0, max_frames=20)
    cs = calibration_stream(sensor, clip, 'tpose', seed=0, start_ns=int(s.stamps_ns[0]))
    from pose_reconstruction.bone_lengths import robust_mean
    m = rc.Reconstructor(db, method='C', k=5, steps=2, samples=10, length_tolerance=0.0)
    out, _ = E.run_method(m, s, subset_frames(s, TABLE3_SUBSETS['c'][1]),
                          warmup=calibration_frames(cs))
    # frozen after length_frames (15) calibration frames (length_tolerance 0: never fewer):
    # their robust mean, left/right averaged
    cal = np.array([robust_mean(c) for c in
                    segment_lengths(cs.positions[:m.segment_output.length_frames]).T])
    mirror = [SEGMENT_CHILDREN.index(MIRROR[c]) for c in SEGMENT_CHILDREN]
    want = 0.5 * (cal + cal[mirror])
    got = segment_lengths(out)
    assert np.allclose(got, want[None], atol=1e-9)
    # without the calibration the hidden segments cannot have these lengths
    out0, _ = E.run_method(m, s, subset_frames(s, TABLE3_SUBSETS['c'][1]))
    assert np.abs(segment_lengths(out0)[-1] - want).max() > 0.005


def test_evaluate_cli_table3_states_the_calibration(tmp_path):
    ev = pytest.importorskip('kinect_experiments.evaluate')
    for cal in ('none', 'tpose'):
        out = tmp_path / cal
        rc = ev.run(['--experiment', 'table3', '--source', 'builtin', '--methods', 'raw',
                     '--max-frames', '10', '--calibration', cal, '--out', str(out), '--quiet'])
        assert rc == 0
        md = (out / 'table3.md').read_text()
        assert f'calibration: {cal}' in md and f'| method (calibration: {cal}) |' in md
        data = json.loads((out / 'table3.json').read_text())
        assert data['calibration']['pose'] == cal
        assert data['meta']['calibration']['pose'] == cal
    assert data['calibration']['frames'] == 30
    assert data['calibration']['sources'] and 'built-in' in data['calibration']['sources'][0]
