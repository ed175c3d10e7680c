"""Evaluation harness: registry, baselines on a tiny clip, an oracle scoring 0, reports."""
import json

import numpy as np
import pytest

from skeleton_core import evaluation as E
from skeleton_core.model import HAND_LEFT, NOT_TRACKED, NUM_JOINTS, TRACKED
from skeleton_core.sensor_model import SensorModel


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
    assert {'raw', 'holt', 'one_euro'} <= set(E.available_methods())
    E.register_method('test_raw', E.RawMethod, 'test', {'x': 1})
    assert 'test_raw' in E.available_methods()
    assert E.method_info('test_raw')['defaults'] == {'x': 1}
    assert isinstance(E.make_method('test_raw'), E.Method)
    with pytest.raises(KeyError):
        E.make_method('no_such_method')
    st = E.load_plugins(('no_such_package_xyz.methods',))
    assert st['no_such_package_xyz.methods'].startswith('skipped')
    holt = E.make_method('holt', smoothing=0.7)
    assert holt.params['smoothing'] == 0.7 and holt.params['prediction'] == 0.5


def test_harness_raw_filters_and_oracle():
    clip = E.toy_clip(4.0)
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
    md = E.to_markdown(res)
    assert '| raw |' in md and '| oracle |' in md and 'Eq. 18' in md
    back = json.loads(E.to_json(res))
    assert back['results']['oracle']['a']['metrics']['eq18_cm']['overall'] == 0.0


def test_evaluate_states_data_seed_and_parameters():
    clip = E.toy_clip(2.0)
    res = E.evaluate(['raw'], [clip], scenarios=('b',), seed=3, data_source='toy')
    meta = res['meta']
    assert meta['seed'] == 3 and meta['data']['source'] == 'toy'
    assert meta['data']['clips'][0]['name'] == clip.name
    assert meta['sensor_params']['placement']['distance_m'] == 2.5
    assert 'b' in res['sensor_statistics']['scenarios']
    md = E.to_markdown(res)
    assert 'seed 3' in md and 'Sensor model noise statistics' in md


def test_table3_subsets():
    clip = E.toy_clip(2.0)
    s = SensorModel(seed=0).corrupt(clip, 'clean')
    frames = E.subset_frames(s, E.TABLE3_SUBSETS['b'][1])
    f = frames[10]
    assert f.tracking_state[HAND_LEFT] == TRACKED and f.reliability[HAND_LEFT] == 1.0
    others = [j for j in range(NUM_JOINTS) if j not in E.TABLE3_SUBSETS['b'][1]]
    assert np.all(f.tracking_state[others] == NOT_TRACKED) and np.all(f.reliability[others] == 0)
    assert np.allclose(f.positions[others], s.positions[0][others])
    res = E.table3(['raw'], [clip], subsets=('b', 'e'))
    assert res['results']['raw']['b']['metrics']['eq18_cm']['overall'] > 1.0
    # against the input skeleton (the paper's reference) raw with all parts is exact
    assert res['results']['raw']['e']['metrics']['eq18_cm']['overall'] == pytest.approx(0.0)
    res_t = E.table3(['raw'], [clip], subsets=('e',), reference='truth')
    assert res_t['results']['raw']['e']['metrics']['eq18_cm']['overall'] > 1.0
    assert 'Table III' in E.to_markdown(res)


def test_fig5_pca_matching():
    rng = np.random.default_rng(0)
    # postures on a 3-D subspace of the 60-D space plus a little noise
    basis = rng.standard_normal((3, 60))
    db = (rng.standard_normal((300, 3)) @ basis + 0.001 * rng.standard_normal((300, 60)))
    q = db[:50] + 0.001 * rng.standard_normal((50, 60))
    res = E.fig5(db.reshape(-1, 20, 3), q.reshape(-1, 20, 3), dims=(1, 3, 10, 60), repeats=1)
    pct = {r['dims']: r['error_pct'] for r in res['rows']}
    assert pct[60] == 0.0
    assert pct[1] > pct[3] and abs(pct[3]) < 5.0
    assert 'Fig. 5' in E.to_markdown(res)


def test_fig8_sweeps_with_overrides():
    E.register_method('holt_sweep', lambda k=1, **kw: E.HoltMethod(smoothing=min(0.9, 0.1 * k)))
    res = E.fig8('holt_sweep', [E.toy_clip(2.0)], params=('k',), sweeps={'k': (1, 5)},
                 max_frames=40)
    rows = res['sweeps']['k']
    assert [r['value'] for r in rows] == [1, 5] and all('eq18_cm' in r for r in rows)
    res = E.fig8('raw', [E.toy_clip(1.0)], params=('k',), sweeps={'k': (3,)}, max_frames=10)
    assert 'skipped' in res['sweeps']['k'][0]  # RawMethod takes no k


def test_evaluate_cli_writes_markdown_and_json(tmp_path, capsys):
    ev = pytest.importorskip('kinect_bringup.evaluate')
    rc = ev.run(['--source', 'builtin', '--methods', 'raw,holt', '--max-frames', '15',
                 '--scenarios', 'a', '--out', str(tmp_path), '--quiet'])
    assert rc == 0
    md = (tmp_path / 'table4.md').read_text()
    assert '| raw |' in md and '| holt |' in md and 'builtin' in md
    data = json.loads((tmp_path / 'table4.json').read_text())
    assert data['meta']['seed'] == 0 and data['results']['raw']['a']['frames'] > 0
    assert 'Sensor model noise statistics' in capsys.readouterr().out
    assert ev.run(['--methods', 'no_such_method', '--out', str(tmp_path)]) == 2
