"""Every `ros2 launch` line of README.md and the hand-written docs/*.md pages starts its nodes for
real: run verbatim (in a scratch directory whose out/ and cache/ hold the files the lines name:
a short recording, a two-sensor extrinsics file, a copy of config/), every lifecycle node it starts
logs "active" (kinect_bringup.launch_nodes), no process dies and nothing raises, and it stops
cleanly on Ctrl-C. (`--show-args`, tests/test_documented_commands.py, never evaluates a launch
file.) Lines for a live sensor run without one: every node but the driver comes up, and the driver
says in one line why it cannot.

Slow (each launch brings a whole graph up; two at a time): `-m "not slow"` leaves it out."""
import importlib.util
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))
import domains  # noqa: E402

# the first test's setup starts every line's graph (two at a time: ~5 min on a loaded 2-core machine)
pytestmark = [pytest.mark.launch_tooling, pytest.mark.slow, pytest.mark.timeout(1800)]

_spec = importlib.util.spec_from_file_location('_documented', Path(__file__).parent /
                                               'test_documented_commands.py')
_documented = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_documented)
LINES = sorted(c for c in _documented.COMMANDS if c.startswith('ros2 launch '))

UP_TIMEOUT_S = 150.0   # a whole graph's processes start on a loaded 2-core machine
HOLD_S = 8.0           # then it runs this long before Ctrl-C
PLAIN = ('static_tf', 'rviz2', 'calibrate_extrinsics')   # nodes without a lifecycle
ACTIVE = re.compile(r'\[kinect_bringup\.lifecycle\]: (\S+) active ([\d.]+) s after its start')
DRIVER_ERROR = re.compile(r'\[ERROR\] \[[\d.]+\] \[[\w/]*driver\]')
STARTED = re.compile(r'\[INFO\] \[([\w]+)-\d+\]: process started with pid')
EXTRINSICS = """transforms:
- parent: world
  child: kinect_1_link
  xyz: [0.0, 0.0, 0.8]
  ypr_deg: [0.0, 0.0, 0.0]
- parent: world
  child: kinect_2_link
  xyz: [2.5, 2.5, 0.8]
  ypr_deg: [-90.0, 0.0, 0.0]
"""


def _workspace(work: Path) -> Path:
    """A scratch directory with the files the documented lines name (never the user's out/)."""
    from test_launch_replay import _write_input
    (work / 'out').mkdir()
    (work / 'cache' / 'uiprmd').mkdir(parents=True)
    _write_input(work / 'out' / 'demo.mcap')
    for name in ('first.mcap',):
        shutil.copy(work / 'out' / 'demo.mcap', work / 'out' / name)
    shutil.copy(work / 'out' / 'demo.mcap', work / 'cache' / 'uiprmd' / 'm01_s02_e01.mcap')
    (work / 'cache' / 'extrinsics.yaml').write_text(EXTRINSICS)
    from azure_fake import write_bag   # an Azure Kinect ROS driver's body_tracking_data bag
    write_bag(work / 'azure.mcap')
    shutil.copytree(ROOT / 'config', work / 'cache' / 'config')
    db = ROOT / 'cache' / 'motion_db.npz'
    if db.is_file():
        shutil.copy(db, work / 'cache' / 'lab_db.npz')
    return work


def _run(line: str, work: Path):
    with domains.claimed(40 + abs(hash(line)) % 50) as domain:
        return _run_on(line, work, domain)


def _run_on(line: str, work: Path, domain: int):
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1',
               KINECT_POSTURE_CACHE=str(ROOT / 'cache'))
    log = work / f'launch_{abs(hash(line))}.log'
    start = time.monotonic()
    with open(log, 'w') as out:
        proc = subprocess.Popen(shlex.split(line), cwd=work, env=env, stdout=out,
                                stderr=subprocess.STDOUT, start_new_session=True)
        up_at = None
        while time.monotonic() - start < UP_TIMEOUT_S and proc.poll() is None:
            text = log.read_text()
            started = [n for n in STARTED.findall(text) if n not in PLAIN]
            active = ACTIVE.findall(text)
            if 'source:=live' in line:   # the driver fails its configure: the rest comes up
                done = DRIVER_ERROR.search(text) and len(active) >= len(started) - 1
            else:
                done = started and len(active) >= len(started)
            if done:
                up_at = time.monotonic() - start
                break
            time.sleep(0.5)
        if proc.poll() is None:
            time.sleep(HOLD_S)
        died = proc.poll()
        if died is None:
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    return up_at, died, log.read_text()


@pytest.fixture(scope='module')
def runs(request, tmp_path_factory):
    """The selected lines (`-k` selects some), two at a time."""
    if shutil.which('ros2') is None:
        pytest.fail('the ros2 command line is not on the PATH: run `make setup`')
    lines = [item.callspec.params['line'] for item in request.session.items
             if item.module is request.module and getattr(item, 'callspec', None)
             and 'line' in item.callspec.params]   # (other modules parametrize a 'line' too)
    work = _workspace(tmp_path_factory.mktemp('documented_launches'))
    with ThreadPoolExecutor(max_workers=2) as pool:
        return dict(zip(lines, pool.map(lambda ln: _run(ln, work), lines)))


def test_the_pages_have_launch_lines():
    assert any('pipeline.launch.py' in ln for ln in LINES) and len(LINES) >= 10, LINES


@pytest.mark.parametrize('line', LINES)
def test_documented_launch_line_brings_its_nodes_up(runs, line):
    up_at, died, text = runs[line]
    tail = '\n'.join(text.splitlines()[-40:])
    assert died is None, f'{line}: the launch ended by itself (exit {died}):\n{tail}'
    running = text.split('user interrupted with ctrl-c')[0]   # a process Ctrl-C ends may say so
    assert 'Traceback' not in text and 'process has died' not in running, f'{line}:\n{tail}'
    # SIGINT, then launch's SIGTERM 5 s later (a loaded machine needs that), then SIGKILL: a hang
    stuck = re.findall(r'\[(\w+)-\d+\]: process\[\S+\] failed to terminate \S+ seconds after '
                       r"receiving 'SIGTERM'", text)
    assert not stuck, f'{line}: {stuck} did not stop on Ctrl-C nor SIGTERM:\n{tail}'
    assert up_at is not None, f'{line}: not every node active within {UP_TIMEOUT_S:.0f} s:\n{tail}'
    if 'source:=live' in line:   # no sensor here: the driver says why in one line
        assert DRIVER_ERROR.search(text), f'{line}:\n{tail}'
