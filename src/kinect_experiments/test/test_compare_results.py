"""compare_results: two evaluation outputs field by field, wall-clock fields left out."""
import json

from kinect_experiments.compare_results import main


def _write(path, data):
    path.write_text(json.dumps(data))
    return str(path)


def test_equal_outputs_pass_and_timings_are_ignored(tmp_path, capsys):
    a = _write(tmp_path / 'a.json', {'C': {'eq18': 0.0385, 'frame_ms': 1.2}, 'rows': [1, 2]})
    b = _write(tmp_path / 'b.json', {'C': {'eq18': 0.0385 * (1 + 1e-12), 'frame_ms': 9.9},
                                     'rows': [1, 2]})
    assert main([a, b]) == 0
    assert '3 fields compared, 0 differ' in capsys.readouterr().out


def test_a_changed_figure_fails_and_is_named(tmp_path, capsys):
    a = _write(tmp_path / 'a.json', {'C': {'eq18': 0.0385}, 'rows': [1, 2]})
    b = _write(tmp_path / 'b.json', {'C': {'eq18': 0.0386}, 'rows': [1, 2, 3]})
    assert main([a, b]) == 1
    out = capsys.readouterr().out
    assert 'DIFF /C/eq18: 0.0385 != 0.0386' in out and 'DIFF /rows: length 2 != 3' in out


def test_an_unreadable_file_is_one_line(tmp_path, capsys):
    assert main([str(tmp_path / 'missing.json'), str(tmp_path / 'missing.json')]) == 2
    err = capsys.readouterr().err
    assert err.startswith('[ERROR] compare_results:') and len(err.strip().splitlines()) == 1
