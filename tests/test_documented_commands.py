"""Every `ros2 launch` and `ros2 run` line of README.md and docs/*.md works verbatim on the built
tree, as a user types it after `make setup` and `source scripts/env.sh`: the launch files load and
describe their arguments (`--show-args`), every documented executable answers `--help` with its
usage and exit code 0, without a traceback and without starting ROS.

(tests/test_docs.py checks statically that the packages, files, options and launch arguments
named exist; this runs them through the real `ros2` command line.)
"""
import os
import re
import shutil
import subprocess
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# the pages written by hand (the generated reference, docs/commands.md and
# docs/launch_arguments.md, is written from the commands and launch files themselves)
GENERATED = {'parameters.md', 'launch_arguments.md', 'commands.md'}
PAGES = [ROOT / 'README.md'] + sorted(p for p in (ROOT / 'docs').glob('*.md') if p.name not in GENERATED)
FENCE = re.compile(r'```[^\n]*\n(.*?)```', re.S)
SPAN = re.compile(r'`([^`\n]+)`')
LAUNCH = re.compile(r'^ros2 launch ([a-z_]+) ([\w.]+\.launch\.py)')
RUN = re.compile(r'^ros2 run ([a-z_]+) ([a-z_]+)')


def _command_lines():
    """Shell lines starting with `ros2 launch` / `ros2 run` in the pages' code blocks and spans
    (continuations joined, comments dropped), with the page each was found on."""
    found = {}
    for page in PAGES:
        text = page.read_text()
        chunks = [b.replace('\\\n', ' ') for b in FENCE.findall(text)]
        chunks += SPAN.findall(FENCE.sub('', text))
        for chunk in chunks:
            for line in chunk.splitlines():
                line = re.sub(r'(^|\s)#.*', '', line).strip()
                if LAUNCH.match(line) or RUN.match(line):
                    found.setdefault(line, page.name)
    return found


COMMANDS = _command_lines()
LAUNCH_FILES = sorted({LAUNCH.match(c).groups() for c in COMMANDS if LAUNCH.match(c)})
EXECUTABLES = sorted({RUN.match(c).groups() for c in COMMANDS if RUN.match(c)})


def test_the_pages_document_launch_files_and_executables():
    """The extraction finds the README's first commands (a parser that found nothing would let
    every test below pass vacuously)."""
    assert ('kinect_bringup', 'pipeline.launch.py') in LAUNCH_FILES
    assert ('kinect_bringup', 'pipeline') in EXECUTABLES
    assert len(EXECUTABLES) >= 10, EXECUTABLES


def _ros2():
    exe = shutil.which('ros2')
    if exe is None:
        pytest.fail('the ros2 command line is not on the PATH: run `make setup` and '
                    '`source scripts/env.sh` (the wheels venv builds it from third_party/ros2)')
    return exe


def _run(cmd, timeout=120):
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    res = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout)
    return res.returncode, res.stdout + res.stderr


@pytest.mark.parametrize('pkg,launch_file', LAUNCH_FILES, ids=[f'{p}/{f}' for p, f in LAUNCH_FILES])
def test_documented_launch_file_shows_its_arguments(pkg, launch_file):
    rc, out = _run([_ros2(), 'launch', pkg, launch_file, '--show-args'])
    assert rc == 0 and 'Traceback' not in out, out[-3000:]
    assert 'Arguments (pass arguments as' in out, out[-3000:]
    shown = set(re.findall(r"^\s+'(\w+)':", out, re.M))
    assert shown, out[-2000:]
    # every name:= a page gives this launch file is one it describes
    for line in (c for c in COMMANDS if LAUNCH.match(c) and LAUNCH.match(c).groups() == (pkg, launch_file)):
        for name in re.findall(r'(?:^|\s)([\w.]+):=', line):
            assert name in shown, f'{line}: {name} is not an argument of {launch_file}'


def test_documented_executables_answer_help():
    """Every documented executable is one `ros2 run` finds (`ros2 pkg executables`, once) and
    answers `--help`, started from where `ros2 run` starts it (in parallel: each start imports its
    package, a few seconds on a loaded machine; through `ros2 run` itself for one of them, the
    command line's own start-up, a second each, is the same for all)."""
    from ament_index_python.packages import get_package_prefix
    ros2 = _ros2()
    rc, out = _run([ros2, 'pkg', 'executables'])
    listed = {tuple(ln.split()[:2]) for ln in out.splitlines() if len(ln.split()) == 2}
    assert rc == 0 and set(EXECUTABLES) <= listed, \
        f'not found by ros2 run: {sorted(set(EXECUTABLES) - listed)}\n{out[-1500:]}'

    def one(pe):
        pkg, exe = pe
        if pe == EXECUTABLES[0]:
            return pe, _run([ros2, 'run', pkg, exe, '--help'])
        return pe, _run([os.path.join(get_package_prefix(pkg), 'lib', pkg, exe), '--help'])

    bad = []
    with ThreadPoolExecutor(max_workers=4) as pool:
        for (pkg, exe), (rc, out) in pool.map(one, EXECUTABLES):
            if rc != 0 or 'Traceback' in out or 'usage:' not in out.lower():
                bad.append(f'ros2 run {pkg} {exe} --help: exit {rc}\n{out[-1500:]}')
    assert not bad, '\n\n'.join(bad)
