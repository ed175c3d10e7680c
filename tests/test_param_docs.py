"""The parameter reference and the YAML files are generated from the parameter declarations:
they must be current (``make params`` rewrites them), say what every node declares, and the YAML
files must read back as exactly the declared defaults."""
from pathlib import Path

import pytest

pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

import yaml  # noqa: E402

from kinect_experiments import param_docs  # noqa: E402
from kinect_bringup.graph import NODES  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def test_generated_files_are_current():
    stale = param_docs.stale(ROOT)
    assert not stale, f'stale generated files {[str(p) for p in stale]}: run `make params`'


def test_check_command_fails_on_a_stale_file(tmp_path, capsys):
    for rel, text in param_docs.outputs().items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    assert param_docs.main(['--check', '--root', str(tmp_path)]) == 0
    path = tmp_path / 'config' / 'optimizer.yaml'
    path.write_text(path.read_text().replace('    k: 30\n', '    k: 5\n'))
    assert param_docs.main(['--check', '--root', str(tmp_path)]) == 1
    assert 'config/optimizer.yaml' in capsys.readouterr().out
    assert param_docs.main(['--root', str(tmp_path)]) == 0          # rewrites it
    assert param_docs.stale(tmp_path) == []


@pytest.mark.parametrize('node', param_docs.YAML_NODES)
def test_yaml_reads_back_as_the_declared_defaults(node):
    values = yaml.safe_load(param_docs.render_yaml(node))['/**']['ros__parameters']
    specs = param_docs.node_params(node)
    assert list(values) == [s.name for s in specs]
    for s in specs:
        assert values[s.name] == s.default and type(values[s.name]) is type(s.default), s.name


def test_reference_lists_every_parameter_of_every_node():
    text = param_docs.render_markdown()
    for node in NODES:
        section = text.split(f'\n## {node}\n', 1)[1].split('\n## ', 1)[0]
        for s in param_docs.node_params(node):
            assert f'| `{s.name}` |' in section, (node, s.name)
    # a declared range and description reach the page (OptimizerConfig.k)
    assert '| `k` | `30` | [2, 1000] | Table V: neighbours of the KNN search' in text
    # a field a preset sets is not a node parameter, and the presets are listed
    assert '`w_style`' not in text.split('\n## Presets\n')[0]
    assert '| `shum2013` |' in text


def test_yaml_values_keep_their_types():
    assert param_docs.yaml_value(1e-05) == '1.0e-05'
    for v in (1e-05, 1e6, 0.1, 3, True, "it's", [0.5, 1.0], '', '/a/b'):
        assert yaml.safe_load(f'x: {param_docs.yaml_value(v)}')['x'] == v


# a lab should find the knobs that matter in `ros2 param list`: the rest is fixed in the code or
# set by a preset (config/presets) in the evaluation
MAX_PER_NODE = 20
MAX_TOTAL = 150


def test_every_node_declares_few_parameters():
    counts = {node: len(param_docs.node_params(node)) for node in NODES}
    over = {n: c for n, c in counts.items() if c > MAX_PER_NODE}
    assert not over, f'nodes with more than {MAX_PER_NODE} public parameters: {over}'
    assert sum(counts.values()) <= MAX_TOTAL, counts


def test_descriptions_hold_no_measured_results():
    # a description says what a parameter does; figures belong in docs/*.md with their command
    import re
    figure = re.compile(r'\d\s*->\s*\d|\d\s*%|\bmeasured on\b|\d\s*(cm|us|ms)\b')
    for node in NODES:
        for s in param_docs.all_params(node):
            assert not figure.search(s.description), (node, s.name, s.description)


def test_presets_set_declared_fields_with_valid_values(tmp_path):
    from pose_reconstruction.methods import load_preset, make_method
    from pose_reconstruction.synthetic import random_database
    from skeleton_core.params import PresetError
    files = sorted((ROOT / 'config' / 'presets').glob('*.yaml'))
    assert files
    for f in files:
        assert load_preset(f), f
    paper = load_preset(ROOT / 'config' / 'presets' / 'shum2013.yaml')
    rec = make_method('C', db=random_database(300), **paper)
    assert rec.output_mode == 'blend' and rec.core.w_style == 0.5
    assert rec.reliability.reference_mode == 'standard'
    bad = tmp_path / 'bad.yaml'
    bad.write_text('w_stlye: 1.0\n')
    with pytest.raises(PresetError, match="unknown parameter 'w_stlye'"):
        load_preset(bad)
    bad.write_text('w_style: -1.0\n')
    with pytest.raises(PresetError, match=r'w_style=-1.0 is outside'):
        load_preset(bad)
