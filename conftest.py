"""Shared test setup (tests/ and src/*/test/): DDS on loopback, a private ROS_DOMAIN_ID, helpers to spin rclpy."""
import os
import sys
from pathlib import Path

# Before any ROS process or rclpy import: keep discovery on this machine (the variables per distro:
# skeleton_core.compat; scripts/distro.sh does the same for the shell; here for a bare `pytest`).
try:
    from skeleton_core.compat import apply_localhost_discovery
    apply_localhost_discovery()
except ImportError:   # not built yet: the tests that need it fail and say so
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
# a private DDS domain per test run (scripts/env.sh's default 42 would be shared by every shell)
os.environ['ROS_DOMAIN_ID'] = os.environ.get('KP_TEST_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.setdefault('MPLBACKEND', 'Agg')

import importlib  # noqa: E402
import itertools  # noqa: E402
import time  # noqa: E402

import pytest  # noqa: E402

ROOT = Path(__file__).resolve().parent
SHARED = Path(os.environ.get('KP_SHARED', ROOT.parent / 'shared'))

# What `make setup` installs is never optional: a test that needs it fails, naming the cure, instead
# of skipping (a broken setup must not pass as "skipped"). Only data or hardware a user may lack
# (../shared, a Kinect, the OpenNI2 runtime) skips. This covers every `pytest.importorskip` of
# these top-level modules, in the suite's files and in any added later.
SETUP_PROVIDES = frozenset({
    'rclpy', 'ament_index_python', 'launch', 'launch_ros', 'launch_pytest', 'launch_testing',
    'launch_testing_ros', 'ros2cli', 'tf2_msgs', 'diagnostic_msgs', 'geometry_msgs', 'sensor_msgs',
    'visualization_msgs', 'std_msgs', 'skeleton_msgs', 'skeleton_core', 'skeleton_data',
    'skeleton_eval', 'kinect_driver', 'pose_reconstruction', 'physics_sim', 'performance_control',
    'viz', 'kinect_bringup', 'kinect_experiments', 'mcap', 'mcap_ros2', 'numba', 'mujoco', 'openni',
    'hri_msgs'})
_importorskip = pytest.importorskip


def _import_or_fail(modname, minversion=None, reason=None, **kwargs):
    if modname.split('.')[0] not in SETUP_PROVIDES:
        return _importorskip(modname, minversion=minversion, reason=reason, **kwargs)
    try:
        return importlib.import_module(modname)
    except ImportError as e:
        pytest.fail(f'{modname} is not importable ({e}); `make setup` installs it: run `make setup`, '
                    f'then `source scripts/env.sh` (ROS_DISTRO={os.environ.get("ROS_DISTRO", "unset")})',
                    pytrace=False)


pytest.importorskip = _import_or_fail


def pytest_report_header(config):
    return (f'ROS 2 {os.environ.get("ROS_DISTRO", "?")} '
            f'({os.environ.get("KINECT_POSTURE_ROS", "environment not from scripts/env.sh")}), '
            f'../shared: {"yes" if SHARED.is_dir() else "no (tests of its data skip)"}')


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
    destroy_nodes(live_nodes(ctx))
    try:
        rclpy.shutdown(context=ctx)
    except Exception:
        pass


def live_nodes(ctx=None) -> list:
    """The rclpy nodes of this process not destroyed yet (of ``ctx`` only, when given)."""
    import gc

    from rclpy.node import Node
    found = []
    for obj in gc.get_objects():
        try:
            if isinstance(obj, Node) and (ctx is None or obj.context is ctx):
                obj.get_name()   # raises once the node is destroyed
                found.append(obj)
        except Exception:
            pass
    return found


def destroy_nodes(nodes) -> list:
    """Destroy ``nodes``: shutting a context down does not remove its nodes from the graph while
    they exist, and a left-over ``/driver`` answers the next test's ``/driver/change_state``
    discovery without ever serving it (a launched node then stays unconfigured). Returns the
    names of the nodes destroyed."""
    names = []
    for node in nodes:
        try:
            names.append(node.get_fully_qualified_name())
            node.destroy_node()
        except Exception:
            pass
    return names


_MODULES = itertools.count()


@pytest.fixture(autouse=True, scope='module')
def environment_restored():
    """Each test module on its own DDS domain, and with its own environment:

    * a node of an earlier module can stay on the graph after it was destroyed (rclpy finalizes
      it, and its context's participant, only once nothing refers to it any more), and a stale
      ``/control`` or ``/driver`` answers a later module's ``change_state`` discovery without
      ever serving it: the launched node then never configures;
    * a module that sets a variable for the processes it starts (e.g. the nodes' cache directory)
      does not leak it into the next modules' nodes;
    * a suite run at the same time on this machine (another clone, the other distro) never has
      the module's domain: it is claimed with a lock (tests/domains.py)."""
    saved = dict(os.environ)
    base = int(saved['ROS_DOMAIN_ID'])
    # claimed (tests/domains.py): another suite on this machine never shares it
    domain = domains.claim(base + next(_MODULES))
    os.environ['ROS_DOMAIN_ID'] = str(domain)
    yield
    os.environ.clear()
    os.environ.update(saved)
    domains.release(domain)


@pytest.fixture(autouse=True, scope='module')
def no_nodes_left_behind():
    """Nodes a test module left alive in this process are destroyed when the module ends (and
    named on stderr): each module starts on a graph without the previous module's nodes."""
    before = {id(n) for n in live_nodes()} if 'rclpy' in sys.modules else set()
    yield
    if 'rclpy' not in sys.modules:
        return
    names = destroy_nodes(n for n in live_nodes() if id(n) not in before)
    if names:
        print(f'\n[conftest] destroyed nodes the module left alive: {", ".join(names)}',
              file=sys.stderr)


def _ros_children() -> dict:
    """The ROS processes (``--ros-args`` on their command line) below this one: pid -> name."""
    import psutil
    out = {}
    for p in psutil.Process().children(recursive=True):
        try:
            cmd = p.cmdline()
            if '--ros-args' in cmd and p.status() != psutil.STATUS_ZOMBIE:
                out[p.pid] = ' '.join(cmd)[-160:]
        except psutil.Error:
            pass
    return out


@pytest.fixture(autouse=True, scope='module')
def no_processes_left_behind():
    """ROS processes a module started and left running (a node that did not stop on SIGINT, a
    test that failed before its clean-up) are killed when the module ends, and named on stderr:
    a stray node would otherwise stay in the graph of every later module on its DDS domain (a
    test's rerun, a module whose domain a private one repeats) and count as a subscriber or
    answer for a node of the same name."""
    before = set(_ros_children())
    yield
    import psutil
    deadline = time.monotonic() + 5.0   # those stopping already get a moment
    left = {}
    while time.monotonic() < deadline:
        left = {pid: c for pid, c in _ros_children().items() if pid not in before}
        if not left:
            return
        time.sleep(0.2)
    for pid in left:
        try:
            psutil.Process(pid).kill()
        except psutil.Error:
            pass
    print('\n[conftest] killed ROS processes the module left running: '
          + '; '.join(left.values()), file=sys.stderr)


sys.path.insert(0, str(ROOT / 'tests'))
import domains  # noqa: E402  (tests/domains.py)


# scripts/run-tests.sh reruns a few failed tests once, alone (a loaded machine's DDS timing), and
# names them: the failed tests' ids are written to KP_FAILED_FILE when it is set.
_FAILED = []


def pytest_runtest_logreport(report):
    if report.failed and report.nodeid not in _FAILED:
        _FAILED.append(report.nodeid)


def pytest_sessionfinish(session, exitstatus):
    path = os.environ.get('KP_FAILED_FILE')
    if path:
        Path(path).write_text(''.join(f'{n}\n' for n in _FAILED))
