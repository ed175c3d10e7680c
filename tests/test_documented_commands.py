"""Every `ros2 launch` and `ros2 run` line of README.md and docs/*.md works verbatim on the built
tree, as a user types it after `make setup` and `source scripts/env.sh`: the launch files load and
describe their arguments (`--show-args`), every documented executable answers `--help` with its
usage and exit code 0, without a traceback and without starting ROS.

(tests/test_docs.py checks statically that the packages, files, options and launch arguments
named exist; this runs them through the real `ros2` command line.) REAL_RUNS below names, for every
documented executable, the tests that run it for real (tests/test_documented_runs.py for those no
other test runs; tests/test_documented_launches.py starts every launch line), and fails for one
without.
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


# Every documented executable -> the tests that run it for real (its main() or the installed
# executable, with real arguments, checking its real output; `--help` above is not one). A
# command added to a page without a test here fails test_every_documented_executable_is_run_for_real.
RUNS = 'tests/test_documented_runs.py::test_documented_command_runs'
NODES = 'tests/test_documented_runs.py::test_documented_nodes_run_over_dds_and_stop_on_ctrl_c'
REAL_RUNS = {
    ('kinect_bringup', 'calibrate_extrinsics'): [f'{RUNS}[calibrate_extrinsics]',
                                                f'{RUNS}[calibrate_extrinsics_bags]'],
    ('kinect_bringup', 'pipeline'): [
        'tests/test_launch_cli.py::test_ros2_launch_and_pipeline_run_the_same_configuration',
        'tests/test_launch_cli.py::test_pipeline_on_the_single_threaded_executor_flows_and_stops_on_sigint'],
    ('kinect_bringup', 'process_bag'): [f'{RUNS}[process_bag]', f'{RUNS}[process_bag_report]'],
    ('kinect_bringup', 'recorder'): [
        'tests/test_recovery.py::test_a_recorder_killed_with_sigkill_keeps_what_it_received',
        'tests/test_bag_split.py::test_recorder_node_rotates_and_process_bag_takes_the_folder'],
    ('kinect_bringup', 'recover_bag'): ['tests/test_recovery.py::test_recover_bag_command'],
    ('kinect_experiments', 'bench'): [f'{RUNS}[bench]'],
    ('kinect_experiments', 'evaluate'): [
        'src/kinect_experiments/test/test_evaluation.py::test_evaluate_cli_writes_markdown_and_json'],
    ('kinect_experiments', 'soak'): ['tests/test_soak.py::test_short_soak_passes'],
    ('performance_control', 'bench_control'): [f'{RUNS}[bench_control]'],
    ('performance_control', 'control'): [NODES],
    ('performance_control', 'demo_control'): [f'{RUNS}[demo_control]'],
    ('physics_sim', 'bench_physics'): [f'{RUNS}[bench_physics]'],
    ('physics_sim', 'physics'): [NODES],
    ('pose_reconstruction', 'bench_reconstruction'): [f'{RUNS}[bench_reconstruction]'],
    ('pose_reconstruction', 'build_correction'): [
        'tests/test_correction_pairs.py::test_build_correction_from_pairs_learns_the_tracker_error_with_a_loso_report',
        'tests/test_correction_azure.py::test_build_correction_learns_an_azure_kinect_correction_found_by_auto'],
    ('skeleton_data', 'build_db'): ['src/skeleton_data/test/test_database.py::test_build_db_cli'],
    ('skeleton_data', 'import_azure_json'): [f'{RUNS}[import_azure_json]'],
    ('skeleton_eval', 'import_uiprmd'): [
        'tests/test_uiprmd.py::test_cli_skips_bad_files_and_writes_the_rest'],
    ('viz', 'bench_hri'): [f'{RUNS}[bench_hri]'],
    ('viz', 'report'): ['src/viz/test/test_report.py::test_report_cli_on_a_small_bag'],
}


def _entry_modules():
    """(pkg, exe) -> the module its console script runs, from the packages' setup.py."""
    found = {}
    for setup in ROOT.glob('src/*/setup.py'):
        for exe, module in re.findall(r"'(\w+) = ([\w.]+):main'", setup.read_text()):
            found[(setup.parent.name, exe)] = module
    return found


def _test_function(node_id):
    """The source of the module-level test function a node id names (None if there is none), its
    parametrize id and its file's text."""
    import ast
    path, _, name = node_id.partition('::')
    name, _, param = name.partition('[')
    file = ROOT / path
    if not file.is_file() or not file.name.startswith('test_'):
        return None, None, None
    text = file.read_text()
    for node in ast.parse(text).body:
        if isinstance(node, ast.FunctionDef) and node.name == name and name.startswith('test_'):
            return ast.get_source_segment(text, node), param.rstrip(']') or None, text
    return None, None, None


def _runs(src, text, exe, module):
    """Whether a test's source starts the executable (its name as a string: a node of a graph),
    runs its module (`-m module`), or calls main()/run() of the module as its file imports it."""
    pkg, _, last = module.rpartition('.')
    names = {last} if re.search(rf'from {re.escape(pkg)} import [^\n]*\b{last}\b', text) else set()
    names |= set(re.findall(rf'(?:from {re.escape(pkg)} import {last}|import {re.escape(module)}) '
                            rf'as (\w+)', text))
    names |= set(re.findall(rf"(\w+) = pytest\.importorskip\('{re.escape(module)}'\)", src))
    return bool(re.search(rf"['\"]{exe}['\"]", src) or module in src
                or any(re.search(rf'\b{n}\.(main|run)\(', src) for n in names))


def test_every_documented_executable_is_run_for_real():
    """Every documented executable has a test that runs it for real, and each test named exists
    (a module-level test in a file pytest collects) and runs that executable (:func:`_runs`, or
    for tests/test_documented_runs.py its command table)."""
    import importlib.util
    missing = sorted(set(EXECUTABLES) - set(REAL_RUNS))
    assert not missing, (f'documented executables no test runs for real: {missing} (add a run to '
                         'tests/test_documented_runs.py COMMANDS and name it in REAL_RUNS)')
    stale = sorted(set(REAL_RUNS) - set(EXECUTABLES))
    assert not stale, f'REAL_RUNS names executables no page documents any more: {stale}'
    spec = importlib.util.spec_from_file_location('_documented_runs', Path(__file__).parent /
                                                  'test_documented_runs.py')
    runs = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(runs)
    modules = _entry_modules()
    bad = []
    for (pkg, exe), ids in sorted(REAL_RUNS.items()):
        assert ids, (pkg, exe)
        module = modules[(pkg, exe)]
        for node_id in ids:
            src, param, text = _test_function(node_id)
            if src is None:
                bad.append(f'{pkg} {exe}: no test {node_id}')
            elif param is not None:
                if runs.COMMANDS.get(param, (None, None))[:2] != (pkg, exe):
                    bad.append(f'{pkg} {exe}: {node_id} runs {runs.COMMANDS.get(param)}')
            elif node_id == NODES:
                if (pkg, exe) not in {v[:2] for v in runs.NODES.values()}:
                    bad.append(f'{pkg} {exe}: {node_id} does not start it')
            elif not _runs(src, text, exe, module):
                bad.append(f'{pkg} {exe}: {node_id} neither starts {exe} nor calls {module}')
    assert not bad, '\n'.join(bad)


MAKE = re.compile(r'^make ([a-z][\w-]*)')
# Every documented `make TARGET` whose recipe is not a documented `ros2 run` (those are REAL_RUNS')
# -> what runs it for real: a test (node id), or a script that runs it (file, the line it holds)
MAKE_RUNS = {
    'demo': ['tests/test_demo.py::test_demo_writes_bag_animation_and_plots'],
    'docs': [('.ci/run', 'make docs')],
    'bench-guard': [('.ci/run', 'make bench-guard')],
    'help': ['tests/test_documented_commands.py::test_make_help_lists_every_documented_target'],
    'lint': ['tests/test_lint.py::test_the_tree_passes_ruff'],
    'params': ['tests/test_param_docs.py::test_check_command_fails_on_a_stale_file'],
    'setup': [('scripts/run-tests.sh', 'scripts/setup.sh'),
              'tests/test_warm_kernels.py::test_warm_kernels_runs',
              'tests/test_bytecode.py::test_workspace_has_no_uncompiled_module_after_compile'],
    'test': [('.ci/run', 'make test')],
    'warm-kernels': ['tests/test_warm_kernels.py::test_warm_kernels_runs'],
}


def _make_targets():
    """The `make TARGET`s of the pages' code blocks and spans (as _command_lines finds commands)."""
    found = set()
    for page in PAGES:
        text = page.read_text()
        chunks = [b.replace('\\\n', ' ') for b in FENCE.findall(text)] + SPAN.findall(FENCE.sub('', text))
        for chunk in chunks:
            for line in chunk.splitlines():
                m = MAKE.match(re.sub(r'(^|\s)#.*', '', line).strip())
                if m:
                    found.add(m.group(1))
    return found


def _makefile_recipes():
    """target -> its recipe's lines, from the Makefile."""
    recipes, target = {}, None
    for line in (ROOT / 'Makefile').read_text().splitlines():
        m = re.match(r'^([a-z][\w-]*):', line)
        if m:
            target = m.group(1)
            recipes[target] = []
        elif line.startswith('\t') and target:
            recipes[target].append(line.strip().lstrip('@'))
    return recipes


MAKE_TARGETS = sorted(_make_targets())


def test_every_documented_make_target_is_run_for_real():
    """Every documented `make TARGET` is a Makefile target, run for real: its recipe's `ros2 run`
    is a documented executable REAL_RUNS covers, or MAKE_RUNS names an existing test or a script
    that runs it."""
    assert {'setup', 'test', 'demo'} <= set(MAKE_TARGETS), MAKE_TARGETS
    recipes = _makefile_recipes()
    bad = []
    for target in MAKE_TARGETS:
        if target not in recipes:
            bad.append(f'make {target}: no such target in the Makefile')
            continue
        runs = [re.search(r'ros2 run (\w+) (\w+)', ln) for ln in recipes[target]]
        if any(r and r.groups() in REAL_RUNS for r in runs) and target not in MAKE_RUNS:
            continue
        if not MAKE_RUNS.get(target):
            bad.append(f'make {target}: no test runs it (add it to MAKE_RUNS)')
        for run in MAKE_RUNS.get(target, []):
            if isinstance(run, tuple):
                if run[1] not in (ROOT / run[0]).read_text():
                    bad.append(f'make {target}: {run[0]} does not hold {run[1]!r}')
            elif _test_function(run)[0] is None:
                bad.append(f'make {target}: no test {run}')
    assert not bad, '\n'.join(bad)
    stale = sorted(set(MAKE_RUNS) - set(MAKE_TARGETS))
    assert not stale, f'MAKE_RUNS names targets no page documents any more: {stale}'


def test_make_help_lists_every_documented_target():
    """`make help` runs and describes every documented target."""
    make = shutil.which('make')
    if make is None:
        pytest.skip('no make on this machine')
    rc, out = _run([make, '--no-print-directory', 'help'], timeout=60)
    assert rc == 0, out[-2000:]
    listed = set(re.findall(r'^make ([a-z][\w-]*)', out, re.M))
    assert set(MAKE_TARGETS) - {'help'} <= listed, sorted(set(MAKE_TARGETS) - listed)
