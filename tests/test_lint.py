"""The workspace passes the linter configured at the root (ruff.toml): what `make lint` runs."""
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_check():
    cmd = [sys.executable, '-m', 'ruff', 'check', '--no-cache', '--output-format', 'concise', str(ROOT)]
    try:
        r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120)
    except FileNotFoundError:  # pragma: no cover
        pytest.fail('python not found to run ruff')
    if 'No module named ruff' in r.stderr:
        pytest.fail('ruff is not installed: pip install -r requirements-py.txt (or make setup)')
    assert r.returncode == 0, f'ruff check found problems (fix them, or `ruff check --fix`):\n{r.stdout}{r.stderr}'
