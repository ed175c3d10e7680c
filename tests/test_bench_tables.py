"""kinect_bringup.bench: the nodes' /diagnostics become the 'where the time goes' table."""
from kinect_bringup.bench import NODE_LATENCY, _node_latencies, to_markdown


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
    # input, then the nodes in NODE_LATENCY order; a node without figures is a dash
    assert row.split(' | ')[3:] == ['0.2 / 0.8', '6.1 / 8.8', '- |']
    assert list(NODE_LATENCY) == ['driver', 'reconstruction', 'physics']
