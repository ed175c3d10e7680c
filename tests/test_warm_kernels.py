"""scripts/run-tests.sh compiles the numba kernels once before the suite (kinect_bringup.warm_kernels):
every kernel module it names imports and warms, with numba on and off."""
import subprocess
import sys

import pytest


@pytest.mark.parametrize('numba', ['1', '0'])
def test_warm_kernels_runs(numba, monkeypatch):
    monkeypatch.setenv('KINECT_NUMBA', numba)
    out = subprocess.run([sys.executable, '-m', 'kinect_bringup.warm_kernels'], capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    expected = 'compiled kernels ready' if numba == '1' else 'numba off'
    assert expected in out.stdout, out.stdout
