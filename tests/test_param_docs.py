"""The parameter reference and the YAML files are generated from the parameter declarations:
they must be current (``make params`` rewrites them), say what every node declares, and the YAML
files must read back as exactly the declared defaults."""
import pytest

pytest.importorskip('rclpy')
pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

import yaml  # noqa: E402

from kinect_bringup import param_docs  # noqa: E402
from kinect_bringup.graph import NODES  # noqa: E402

from conftest import ROOT  # noqa: E402


def test_generated_files_are_current():
    stale = param_docs.stale(ROOT)
    assert not stale, f'stale generated files {[str(p) for p in stale]}: run `make params`'


def test_check_command_fails_on_a_stale_file(tmp_path, capsys):
    for rel, text in param_docs.outputs().items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    assert param_docs.main(['--check', '--root', str(tmp_path)]) == 0
    path = tmp_path / 'config' / 'optimizer.yaml'
    path.write_text(path.read_text().replace('w_style: 8.0', 'w_style: 0.5'))
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
    # a declared range and description reach the page (OptimizerConfig.w_style)
    assert '| `w_style` | `8.0` | [0.0, 1000.0] | Eq. 15: weight of the style term' in text


def test_yaml_values_keep_their_types():
    assert param_docs.yaml_value(1e-05) == '1.0e-05'
    for v in (1e-05, 1e6, 0.1, 3, True, "it's", [0.5, 1.0], '', '/a/b'):
        assert yaml.safe_load(f'x: {param_docs.yaml_value(v)}')['x'] == v
