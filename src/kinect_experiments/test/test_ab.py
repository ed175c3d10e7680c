"""kinect_experiments.ab (``bench --against``): the load guard waits for a quiet machine and
refuses a busy one; the figures of two benches are paired per alternation; the CI guard fails
only on a large regression seen on every alternation."""
import json
import subprocess

import pytest

from kinect_experiments import ab


def _bench_json(rec_p95, char_p95, dropped=0, cpu=(30.0, 40.0), users=6):
    out = {'p50_ms': rec_p95 / 2, 'dropped': dropped, 'skeletons': 300 * users}
    return {'results': [{
        'mode': 'processes', 'users': users, 'sensors': 1, 'seconds': 10.0,
        'input': {'rate_hz': 30.0, 'p50_ms': 1.0, 'p95_ms': 2.0, 'skeletons': 300 * users},
        'reconstructed': {**out, 'p95_ms': rec_p95},
        'character': {**out, 'p95_ms': char_p95},
        'processes': {'reconstruction': {'cpu_percent': cpu[0]},
                      'physics': {'cpu_percent': cpu[1]}}}]}


def test_figures_of_a_run_include_cpu_time_per_frame():
    fig = ab.run_figures(_bench_json(20.0, 30.0, cpu=(30.0, 60.0)))['processes 6u 1s']
    assert fig['reconstructed.p95_ms'] == 20.0 and fig['character.dropped'] == 0
    assert fig['cpu.graph'] == 90.0
    # 30 % of a core at 30 frames/s = 10 ms of CPU per frame
    assert fig['cpu_ms_per_frame.reconstruction'] == pytest.approx(10.0)
    # a node that output half the frames (the rest dropped) spent twice as much per frame
    run = _bench_json(20.0, 30.0, cpu=(30.0, 60.0))
    run['results'][0]['character']['skeletons'] = 150 * 6
    assert ab.run_figures(run)['processes 6u 1s']['cpu_ms_per_frame.physics'] == pytest.approx(40.0)
    assert 'input.p95_ms' not in fig   # the input is judged only with several sensors


def _compare(pairs):
    cmp = ab.Comparison()
    for a, b in pairs:
        cmp.add('a', ab.run_figures(a))
        cmp.add('b', ab.run_figures(b))
    return cmp.rows()


def test_guard_fails_only_when_every_alternation_regresses():
    slow = [(_bench_json(10.0, 20.0), _bench_json(10.5, 40.0))] * 3   # character 2x, +20 ms
    bad = ab.regressions(_compare(slow), 1.5)
    assert [r['figure'] for r in bad] == ['character.p95_ms']
    # one alternation of the three was not slower (a stall in an A run, say): no failure
    mixed = slow[:2] + [(_bench_json(10.0, 38.0), _bench_json(10.0, 40.0))]
    assert ab.regressions(_compare(mixed), 1.5) == []
    # fewer than three alternations never fail
    assert ab.regressions(_compare(slow[:2]), 1.5) == []
    # doubled but tiny (2 -> 4 ms): noise, not a regression
    tiny = [(_bench_json(2.0, 3.0), _bench_json(4.0, 6.0))] * 3
    assert ab.regressions(_compare(tiny), 1.5) == []


def test_guard_fails_on_drops_where_the_reference_had_none_and_on_cpu():
    drops = [(_bench_json(10.0, 20.0), _bench_json(10.0, 20.0, dropped=4))] * 3
    assert {r['figure'] for r in ab.regressions(_compare(drops))} == {
        'reconstructed.dropped', 'character.dropped'}
    cpu = [(_bench_json(10.0, 20.0, cpu=(30, 40)), _bench_json(10.0, 20.0, cpu=(60, 60)))] * 3
    assert [r['figure'] for r in ab.regressions(_compare(cpu))] == ['cpu.graph']


def test_ratio_per_alternation_and_of_the_medians():
    rows = {r['figure']: r for r in _compare([(_bench_json(10.0, 20.0), _bench_json(5.0, 20.0)),
                                              (_bench_json(20.0, 20.0), _bench_json(10.0, 20.0))])}
    r = rows['reconstructed.p95_ms']
    assert r['ratios'] == [0.5, 0.5] and r['ratio'] == pytest.approx(7.5 / 15.0)
    assert rows['character.dropped']['ratios'] == [1.0, 1.0]   # 0 and 0: equal, not a division


def test_load_guard_waits_for_quiet_then_refuses():
    t = [0.0]

    def clock():
        return t[0]

    def busy_then_quiet(seq):
        it = iter(seq)

        def busy():
            t[0] += 10.0
            return next(it)
        return busy
    chk = ab.wait_for_quiet(0.25, 60.0, busy_then_quiet([0.9, 0.6, 0.1]), clock, lambda: 1.0)
    assert chk.ok and chk.busy == 0.1 and chk.waited_s == 30.0
    t[0] = 0.0
    chk = ab.wait_for_quiet(0.25, 25.0, busy_then_quiet([0.9] * 10), clock, lambda: 3.0)
    assert not chk.ok and chk.busy == 0.9 and chk.waited_s >= 25.0


def test_machine_busy_from_cpu_jiffies():
    samples = iter([(100.0, 1000.0), (150.0, 1200.0)])
    assert ab.machine_busy(0, lambda: next(samples), lambda s: None) == pytest.approx(0.25)
    busy, total = ab.cpu_times()     # the real /proc/stat
    assert 0 <= busy <= total


def test_report_says_not_valid_on_a_busy_machine():
    cmp = ab.Comparison()
    cmp.add('a', ab.run_figures(_bench_json(10.0, 20.0)))
    cmp.add('b', ab.run_figures(_bench_json(10.0, 20.0)))
    loads = [{'side': 'a', 'busy': 0.8, 'loadavg': 5.0, 'waited_s': 120.0},
             {'side': 'b', 'busy': 0.1, 'loadavg': 1.0, 'waited_s': 0.0}]
    md = ab.to_markdown(cmp, 'HEAD^', 'abc', 'def', loads, False, 0.25, '--against')
    assert '**NOT VALID**' in md and '| 1 | A | 80 % | 5.00 | 120 |' in md
    assert 'NOT VALID' not in ab.to_markdown(cmp, 'HEAD^', 'abc', 'def', loads, True, 0.25, '')


def test_reference_must_exist_in_the_clone(tmp_path):
    subprocess.run(['git', 'init', '-q', str(tmp_path)], check=True)
    with pytest.raises(ValueError, match='no such commit'):
        ab.resolve(tmp_path, 'HEAD^')


def test_an_older_bench_gets_only_the_options_it_knows(tmp_path):
    src = tmp_path / 'src' / 'kinect_bringup' / 'kinect_bringup'
    src.mkdir(parents=True)
    (src / 'bench.py').write_text("p.add_argument('--users')\np.add_argument('--skip-bag', "
                                  "action='store_true')\np.add_argument('--seconds')\n")
    cmd = ab.bench_command(tmp_path, ['--users', '6', '--sensors', '1', '--skip-bag',
                                      '--seconds', '8'], tmp_path / 'o')[-1]
    assert 'python -m kinect_bringup.bench --users 6 --skip-bag --seconds 8 --out' in cmd
    # an option that changes what is measured is not dropped: that side is refused
    with pytest.raises(ValueError, match='has no --drivers-elsewhere'):
        ab.bench_command(tmp_path, ['--users', '6', '--drivers-elsewhere'], tmp_path / 'o')


def _fake_reference(tmp_path, body):
    tree = tmp_path / 'cache' / 'ab' / 'abc' / 'tree'
    mod = tree / 'src' / 'kinect_bringup' / 'kinect_bringup'
    mod.mkdir(parents=True)
    (mod / '__init__.py').write_text('')
    (mod / 'warm_kernels.py').write_text(body)
    (tree / 'scripts').mkdir()
    (tree / 'scripts' / 'env.sh').write_text('export PYTHONPATH="$PWD/src/kinect_bringup"\n')
    return tree


def test_the_reference_compiles_its_kernels_once_before_any_run(tmp_path):
    """Its first run must not compile inside the graph (every frame of that run lost)."""
    from kinect_experiments.ab import warm
    tree = _fake_reference(tmp_path, 'open("compiled", "a").write("x")\n')
    assert warm(tmp_path, tree, log=lambda *_: None) == tree
    assert (tree / 'compiled').read_text() == 'x'
    warm(tmp_path, tree, log=lambda *_: None)                # cached: not again
    assert (tree / 'compiled').read_text() == 'x'


def test_a_reference_whose_kernels_fail_to_compile_is_an_error(tmp_path):
    from kinect_experiments.ab import warm
    tree = _fake_reference(tmp_path, 'raise SystemExit("no compiler")\n')
    with pytest.raises(RuntimeError, match='no compiler'):
        warm(tmp_path, tree, log=lambda *_: None)
    assert not (tree / '.ab-warm').exists()


def _fake_ab(monkeypatch, tmp_path, factors):
    """run_ab with the reference, git and the benches faked: each run writes the same figures;
    the speed gauge reads ``factors`` in turn."""
    from pathlib import Path
    from kinect_experiments import speed_gauge as sg
    monkeypatch.setattr(ab, 'resolve', lambda root, ref: 'a' * 40)
    monkeypatch.setattr(ab, 'git', lambda root, *a: '')
    monkeypatch.setattr(ab, 'prepare', lambda root, sha, log: tmp_path)
    monkeypatch.setattr(ab, 'bench_command', lambda tree, case, out: ['bench', str(out)])
    monkeypatch.setattr(ab, 'wait_for_quiet', lambda *a: ab.LoadCheck(0.0, 0.5, 0.0, True))

    def run(cmd, **kw):
        out = Path(cmd[-1])
        out.mkdir(parents=True, exist_ok=True)
        (out / 'bench.json').write_text(json.dumps(_bench_json(10.0, 20.0)))
        return subprocess.CompletedProcess(cmd, 0)
    monkeypatch.setattr(ab.subprocess, 'run', run)
    it = iter(factors)
    return lambda: sg.Reading(next(it), 60.0, 60.0)


def test_a_run_in_a_slower_minute_than_the_comparison_so_far_is_refused(monkeypatch, tmp_path):
    # A at x1.00 before and after, then B's gauge reads x1.40 (> 1.25 x the fastest): refused
    gauge = _fake_ab(monkeypatch, tmp_path, [1.0, 1.0, 1.4, 1.4])
    logs = []
    rc = ab.run_ab(tmp_path, 'HEAD^', [], 2, tmp_path / 'out', speed_wait_s=0.0, gauge=gauge,
                   log=logs.append)
    assert rc == 3 and any('x1.40' in m and 'refusing' in m for m in logs)
    # the same speeds within the allowed change: compared, every run's gauge in the report
    gauge = _fake_ab(monkeypatch, tmp_path, [1.0, 1.1, 1.2, 1.2, 1.1, 1.0, 1.0, 1.0])
    rc = ab.run_ab(tmp_path, 'HEAD^', [], 2, tmp_path / 'out', speed_wait_s=0.0, gauge=gauge,
                   log=logs.append)
    md = (tmp_path / 'out' / 'ab.md').read_text()
    assert rc == 0 and '| 2 | B | 0 % | 0.50 | 0 | x1.20 / x1.20 |' in md
    assert 'NOT VALID' not in md
    loads = json.loads((tmp_path / 'out' / 'ab.json').read_text())['loads']
    assert [ld['speed_before'] for ld in loads] == [1.0, 1.2, 1.1, 1.0]
    # the CPU per frame at nominal speed: each run's divided by the mean of its two readings
    row = next(r for r in json.loads((tmp_path / 'out' / 'ab.json').read_text())['rows']
               if r['figure'] == 'cpu_ms_per_frame_x1.graph')
    raw = ab.run_figures(_bench_json(10.0, 20.0))['processes 6u 1s']['cpu_ms_per_frame.graph']
    assert row['a'] == pytest.approx([raw / 1.05, raw / 1.05])
    assert row['b'] == pytest.approx([raw / 1.2, raw / 1.0])
    # off (0): a slow minute is only reported; the alternation whose A and B differ is named
    gauge = _fake_ab(monkeypatch, tmp_path, [1.0, 1.0, 1.6, 1.6])
    rc = ab.run_ab(tmp_path, 'HEAD^', [], 1, tmp_path / 'out', speed_wait_s=0.0, gauge=gauge,
                   log=logs.append, max_speed_change=0)
    md = (tmp_path / 'out' / 'ab.md').read_text()
    assert rc == 0 and '| 2 | B | 0 % | 0.50 | 0 | x1.60 / x1.60 |' in md
    assert 'Alternation 1: A and B ran at speeds 1.60x apart' in md


def test_uneven_alternations():
    loads = [{'speed_before': 1.0, 'speed_after': 1.1}, {'speed_before': 1.1, 'speed_after': 1.2},
             {'speed_before': 1.0, 'speed_after': 1.0}, {'speed_before': 1.5, 'speed_after': 1.4},
             {}, {}]   # an older report without the gauge
    assert [(n, round(s, 2)) for n, s in ab.uneven(loads, 1.25)] == [(2, 1.5)]


def test_cpu_per_frame_at_nominal_speed():
    fig = ab.run_figures(_bench_json(20.0, 30.0, cpu=(30.0, 60.0)))
    adj = ab.at_nominal_speed(fig, 1.5)['processes 6u 1s']
    # 30 % of a core at 30 frames/s = 10 ms per frame; read at x1.5: 6.67 ms at nominal speed
    assert adj['cpu_ms_per_frame_x1.reconstruction'] == pytest.approx(10.0 / 1.5)
    assert adj['cpu_ms_per_frame.reconstruction'] == pytest.approx(10.0)   # kept as measured
    assert adj['cpu_ms_per_frame_x1.graph'] == pytest.approx(fig['processes 6u 1s']
                                                            ['cpu_ms_per_frame.graph'] / 1.5)
    assert 'cpu_x1.graph' not in adj and 'cpu_ms_per_frame_x1.graph' not in fig['processes 6u 1s']
    assert ab.at_nominal_speed(fig, float('nan')) == fig   # no reading: nothing added
