"""The workspace is built and registered as a user's `ros2 run` / `ros2 launch` would need it."""
import os
import re
from pathlib import Path
from xml.dom import minidom

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = sorted(p.parent.name for p in (ROOT / 'src').glob('*/package.xml'))


def test_expected_packages_exist():
    assert {'skeleton_msgs', 'skeleton_core', 'skeleton_data', 'skeleton_eval', 'kinect_driver',
            'pose_reconstruction',
            'physics_sim', 'viz', 'kinect_bringup', 'kinect_experiments'} <= set(PACKAGES)


@pytest.mark.parametrize('pkg', PACKAGES)
def test_package_registered_in_ament_index_with_its_executables(pkg):
    ament = pytest.importorskip('ament_index_python.packages')
    # an invalid package.xml makes colcon build a plain Python package that ros2 cannot find
    minidom.parse(str(ROOT / 'src' / pkg / 'package.xml'))
    prefix = Path(ament.get_package_prefix(pkg))
    setup_py = ROOT / 'src' / pkg / 'setup.py'
    if setup_py.exists():
        for exe in re.findall(r"'(\w+) = [\w.]+:main'", setup_py.read_text()):
            assert (prefix / 'lib' / pkg / exe).is_file(), f'{pkg}: lib/{pkg}/{exe} missing'


def test_every_ros_entry_point_exports_loopback_discovery():
    for script in ('scripts/distro.sh', 'scripts/run-tests.sh', '.ci/run'):
        assert 'ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST' in (ROOT / script).read_text(), script
    for script in ('scripts/env.sh', 'scripts/setup.sh'):   # both take it from distro.sh
        assert 'distro.sh' in (ROOT / script).read_text(), script
    assert os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE') == 'LOCALHOST'


def test_no_build_product_or_environment_is_tracked():
    """The venv (a directory or a worktree's symlink to one), build products and caches are never
    committed: a tracked `.venv` link replaced the real venv on every merge."""
    import subprocess
    if not (ROOT / '.git').exists():
        pytest.skip('not a git checkout')
    tracked = subprocess.run(['git', 'ls-files', '--', '.venv', 'build', 'install', 'log', 'cache', 'out'],
                             cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    assert not tracked, tracked
