"""Shared test setup: DDS on loopback, a private ROS_DOMAIN_ID, helpers to spin rclpy."""
import os
import sys
from pathlib import Path

# Before any ROS process or rclpy import: keep discovery on this machine.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
if os.environ.get('ROS_DISTRO') in ('humble', 'iron'):
    os.environ['ROS_LOCALHOST_ONLY'] = '1'
# a private DDS domain per test run (scripts/env.sh's default 42 would be shared by every shell)
os.environ['ROS_DOMAIN_ID'] = os.environ.get('KP_TEST_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.setdefault('MPLBACKEND', 'Agg')

import pytest  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get('KP_SHARED', ROOT.parent / 'shared'))


def pytest_configure(config):
    config.addinivalue_line('markers', 'ros: needs rclpy and the built skeleton_msgs')
    config.addinivalue_line('markers', 'launch_tooling: needs ros2 launch / launch_pytest')
    config.addinivalue_line('markers', 'shared: needs ../shared data')
    config.addinivalue_line('markers', 'slow: takes more than ~20 s')


@pytest.fixture(scope='session')
def shared_dir():
    if not SHARED.is_dir():
        pytest.skip(f'no shared data at {SHARED} (CMU mocap / UI-PRMD live there)')
    return SHARED


@pytest.fixture(scope='session', autouse=True)
def default_database():
    """The default motion database file the nodes load (``cache/motion_db.npz``): nodes never
    build it, so the suite calls its producer (``make build-db``'s ``build_db``) once when it is
    missing (CMU clips from ../shared, else the built-in motions)."""
    try:
        from skeleton_data import database, database_cli
    except ImportError:   # the workspace is not built: the tests that need it skip
        return None
    path = database.default_path()
    if not path.is_file():
        assert database_cli.main(['--no-progress']) == 0, 'build_db failed'
    return path


@pytest.fixture
def rclpy_context():
    """A fresh rclpy context, shut down after the test."""
    rclpy = pytest.importorskip('rclpy')
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    try:
        rclpy.shutdown(context=ctx)
    except Exception:
        pass


sys.path.insert(0, str(ROOT / 'tests'))
