"""The linter runs with the suite: `ruff check` over the whole tree (configuration: ruff.toml)."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _ruff():
    exe = shutil.which('ruff') or str(Path(sys.executable).with_name('ruff'))
    if not Path(exe).exists():
        pytest.fail('ruff is not installed: run scripts/setup.sh (requirements-py.txt pins it)')
    return exe


def test_the_tree_passes_ruff():
    res = subprocess.run([_ruff(), 'check', '--no-cache', '--output-format', 'concise', str(ROOT)],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-2000:]


def test_ruff_reports_a_planted_error(tmp_path):
    bad = tmp_path / 'bad.py'
    bad.write_text('import os\n')
    res = subprocess.run([_ruff(), 'check', '--no-cache', '--config', str(ROOT / 'ruff.toml'),
                          str(bad)], capture_output=True, text=True, timeout=60)
    assert res.returncode == 1 and 'F401' in res.stdout
