"""kinect_experiments.bench: the nodes' /diagnostics become the 'where the time goes' table; the
pass-through floor beside every row and the latency targets judged against it."""
from kinect_experiments.bench import NODE_LATENCY, _node_latencies, targets, to_markdown


def test_node_latencies_parse_diagnostics_and_fill_the_table():
    diag = {'driver': {'p50_ms': '0.200', 'p95_ms': '0.800', 'rate_hz': '30.0'},
            'reconstruction': {'p50_ms': '6.100', 'p95_ms': '8.800'},
            'physics': {'p50_ms': 'nan', 'p95_ms': 'nan'},   # no samples yet: left out
            'viz': {'p50_ms': '1.0', 'p95_ms': 'n/a'}}           # not a number: left out
    nodes = _node_latencies(diag)
    assert nodes['driver'] == {'p50_ms': 0.2, 'p95_ms': 0.8}
    assert nodes['reconstruction']['p95_ms'] == 8.8
    assert 'physics' not in nodes and 'viz' not in nodes
    result = {'mode': 'processes', 'reconstruction': 'fused', 'users': 2, 'processes': {},
              'nan_outputs': 0, 'nodes': nodes, 'input': {'p50_ms': 1.5, 'p95_ms': 5.9}}
    md = to_markdown([result], {}, 'abc1234')
    row = next(line for line in md.splitlines()
               if line.startswith('| processes (fused) | 2 | 1.5 / 5.9'))
    # input, the floor (none measured: a dash), then the nodes in NODE_LATENCY order; a node
    # without figures is a dash
    assert row.split(' | ')[3:] == ['-', '0.2 / 0.8', '6.1 / 8.8', '- |']
    assert list(NODE_LATENCY) == ['driver', 'reconstruction', 'physics']


def _case(users, rec_p95, char_p95, floor_p95, dropped=0, cpu=(60.0, 50.0)):
    out = {'skeletons': 100, 'rate_hz': 30.0 * users, 'p50_ms': 1.0, 'p99_ms': 40.0,
           'dropped': dropped, 'dropped_fraction': 0.0}
    return {'mode': 'processes', 'reconstruction': 'fused', 'users': users, 'nan_outputs': 0,
            'processes': {f'p{i}': {'cpu_percent': c, 'rss_mb': 100.0} for i, c in enumerate(cpu)},
            'nodes': {}, 'input': {}, 'physics': {'real_time_factor': 9.0, 'characters': users},
            'floor': {'skeletons': 100, 'p50_ms': 2.0, 'p95_ms': floor_p95},
            'reconstructed': {**out, 'p95_ms': rec_p95}, 'character': {**out, 'p95_ms': char_p95}}


def test_targets_are_judged_against_the_floor_of_the_same_run():
    res = [_case(2, rec_p95=8.0, char_p95=16.0, floor_p95=4.0),      # +4 ok, +12 ok
           _case(6, rec_p95=20.0, char_p95=34.0, floor_p95=4.0, dropped=3, cpu=(100.0, 60.0))]
    bag = {'physics': {'x_real_time_loop': 12.0}}
    checks = {(c['case'], c['what']): c['met'] for c in targets(res, bag)}
    assert checks[('processes (fused)', '2 users reconstructed p95 <= floor p95 + 5 ms')]
    assert checks[('processes (fused)', '2 users character p95 <= floor p95 + 12 ms')]
    assert checks[('processes (fused)', '6 users reconstructed p95 <= 33 ms')]
    assert not checks[('processes (fused)', '6 users character p95 <= 33 ms')]
    assert not checks[('processes (fused)', '6 users character dropped = 0')]
    assert not checks[('processes (fused)', '6 users graph CPU <= 150 %')]       # 160 %
    assert checks[('process_bag', 'process_bag --physics >= 10x real time (loop)')]
    res[0]['character']['p95_ms'] = 16.5                                       # +12.5: too slow
    assert not next(c['met'] for c in targets(res, bag) if c['what'].startswith('2 users char'))
    md = to_markdown(res, {}, 'abc1234')
    row = next(line for line in md.splitlines() if line.startswith('| processes (fused) | 2 | character'))
    assert '| 2.0 / 4.0 | +12.5 |' in row
    assert '| **no** |' in md and '| processes (fused) | 6 | **graph** | 160 | |' in md


def test_every_case_prints_the_machine_speed_before_and_after_it():
    res = [_case(2, 8.0, 16.0, 4.0), _case(6, 20.0, 30.0, 4.0)]
    res[0]['machine_speed'] = {'before': {'factor': 1.0, 'nominal_ms': 48.0},
                               'after': {'factor': 1.049, 'nominal_ms': 48.0}, 'waited_s': 0.0}
    res[1]['machine_speed'] = {'before': {'factor': 1.27, 'nominal_ms': 48.0},
                               'after': {'factor': 1.6, 'nominal_ms': 48.0}, 'waited_s': 35.0}
    md = to_markdown(res, {}, 'abc1234')
    assert '- processes (fused), 2 users: machine speed x1.00 before / x1.05 after\n' in md
    assert ('- processes (fused), 6 users: machine speed x1.27 before / x1.60 after (waited 35 s '
            'for it)') in md
    assert 'against 48 ms = x1.00' in md
    # a result without the gauge (an older bench's JSON): no speed lines
    del res[0]['machine_speed'], res[1]['machine_speed']
    assert 'machine speed x' not in to_markdown(res, {}, 'abc1234')


def test_the_probe_cpu_is_printed_apart_from_the_graph():
    """The probe's own process (its subscriptions to every output) is listed under its own name
    in the process table and is not in the graph's CPU; a result without it (an older bench's
    JSON) has no such row."""
    from kinect_experiments.bench import PROBE, graph_cpu
    r = _case(6, 20.0, 30.0, 4.0, cpu=(100.0, 40.0))
    r['probe'] = {'cpu_percent': 4.4, 'rss_mb': 180.0}
    md = to_markdown([r], {}, 'abc1234')
    assert f'| processes (fused) | 6 | {PROBE} | 4 | 180 |' in md
    assert '| processes (fused) | 6 | **graph** | 140 | |' in md and graph_cpu(r) == 140.0
    del r['probe']
    assert PROBE not in to_markdown([r], {}, 'abc1234')
