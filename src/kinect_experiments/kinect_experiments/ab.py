"""``bench --against REF``: the same benchmark case run on this tree (B) and on commit ``REF``
(A) built beside it, alternated in one invocation (A B A B ...), with the ratio B / A per output
(p50, p95, dropped) and per process (CPU), and a load guard: a run starts only on a quiet
machine, else the comparison is refused (or, with ``--ignore-load``, printed as NOT VALID);
likewise a speed guard: the machine speed gauge (``speed_gauge``) is read before and after
every run, and a run starts only while the machine is within ``MAX_SPEED_CHANGE`` of the
fastest reading of the comparison.

    ros2 run kinect_experiments bench --against 819729f --users 6 --sensors 1
    ros2 run kinect_experiments bench --against            # HEAD^ (the previous landed commit)
    ros2 run kinect_experiments bench --against HEAD^ --users 2 --alternations 3 --fail-ratio 1.5

The reference is built with colcon into ``cache/ab/<commit>/tree`` (the commit's files from
``git archive``: no worktree is registered in the repository) over this tree's venv, never
with its own ``setup.sh`` (which could reinstall the shared venv);
each run is that tree's own ``bench`` (its probe, its graph) in a fresh process with that tree's
environment. Nothing in this module imports rclpy.
"""
from __future__ import annotations

import json
import os
import shlex
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from . import speed_gauge

# The load guard: the share of the machine's CPU (all cores) busy in the seconds before a run,
# measured from /proc/stat (not the 1-minute load average, which still remembers the previous
# run of this very comparison for a minute). Above it, other jobs would move the figures more
# than the change being compared: the run waits for the machine to quiet, then is refused.
MAX_BUSY = 0.25          # a quarter of the machine: half a core of a 2-core machine
LOAD_SAMPLE_S = 3.0
LOAD_WAIT_S = 120.0
OUTPUTS = ('input', 'reconstructed', 'character')
# the output whose frames a process makes (cpu_ms_per_frame); other processes: the captures
PROCESS_OUTPUT = {'reconstruction': 'reconstructed', 'optimizer': 'reconstructed',
                  'physics': 'character', 'fusion': 'input'}   # input: the fused frames with 2 sensors
METRICS = ('p50_ms', 'p95_ms', 'dropped')
# the CI guard: a regression is a ratio above this on every alternation AND at least this many
# ms (or CPU points) worse on every alternation; small figures double on noise alone
FAIL_RATIO = 1.5
FAIL_MIN_MS = 5.0
FAIL_MIN_CPU = 10.0
# The speed guard: the machine speed gauge (speed_gauge) read before and after every run. A run
# starts only while the machine is at most this much slower than the fastest reading of this
# comparison so far: B / A compares two runs, and is honest only when both ran at about the same
# speed (this VM's speed swings up to 2x from one minute to the next, unseen by the load guard).
# Relative, not against the nominal: a steadily slower machine compares its A and B fairly, and
# an absolute threshold (``--max-slow``, off by default) would refuse it for being itself.
MAX_SPEED_CHANGE = 1.25


# ---------------------------------------------------------------------------- the load guard
def cpu_times() -> Tuple[float, float]:
    """(busy, total) jiffies of all cores from /proc/stat."""
    with open('/proc/stat') as f:
        vals = [float(v) for v in f.readline().split()[1:]]
    idle = vals[3] + (vals[4] if len(vals) > 4 else 0.0)   # idle + iowait
    return sum(vals) - idle, sum(vals)


def machine_busy(seconds: float = LOAD_SAMPLE_S, sampler: Callable = cpu_times,
                 sleep: Callable = time.sleep) -> float:
    """Share (0-1) of all cores busy over ``seconds``."""
    b0, t0 = sampler()
    sleep(seconds)
    b1, t1 = sampler()
    return (b1 - b0) / (t1 - t0) if t1 > t0 else 0.0


@dataclass
class LoadCheck:
    busy: float          # share of the machine busy just before the run
    loadavg: float       # 1-minute load average then (reported, not judged)
    waited_s: float
    ok: bool


def wait_for_quiet(max_busy: float = MAX_BUSY, wait_s: float = LOAD_WAIT_S,
                   busy: Callable[[], float] = machine_busy,
                   clock: Callable[[], float] = time.monotonic,
                   loadavg: Callable[[], float] = lambda: os.getloadavg()[0]) -> LoadCheck:
    """Sample the machine until it is quiet (busy <= ``max_busy``) or ``wait_s`` has passed."""
    t0 = clock()
    while True:
        b = busy()
        if b <= max_busy or clock() - t0 >= wait_s:
            return LoadCheck(b, loadavg(), clock() - t0, b <= max_busy)


# ---------------------------------------------------------------------------- figures of a run
def run_figures(bench_json: Dict) -> Dict[str, Dict[str, float]]:
    """One bench run's figures, keyed by case label then ``output.metric`` / ``cpu.process``:
    p50, p95, dropped per output, CPU % per process and of the whole graph, and CPU ms per frame
    per process (CPU % / the frames it output per second -- the captures for the driver and the
    graph: the figure least moved by other jobs on the machine)."""
    out = {}
    for r in bench_json.get('results', []):
        label = f"{r.get('mode')} {r.get('users')}u {r.get('sensors', 1)}s"
        fig: Dict[str, float] = {}
        for key in OUTPUTS:
            o = r.get(key) or {}
            if key == 'input' and r.get('sensors', 1) <= 1:
                continue
            for m in METRICS:
                if m in o:
                    fig[f'{key}.{m}'] = float(o[m])
        procs = r.get('processes', {})
        # captured frames per second: the distinct capture stamps of the input (sensor 1's with
        # several sensors), counted the same way by every version of the bench
        src = (r.get('sensor1') if r.get('sensors', 1) > 1 else r.get('input')) or {}
        secs, users = float(r.get('seconds') or 0.0), max(1, int(r.get('users') or 1))
        rate = src.get('skeletons', 0) / users / secs if secs > 0 else 0.0
        total = 0.0
        for name, s in procs.items():
            c = float(s.get('cpu_percent', float('nan')))
            fig[f'cpu.{name}'] = c
            total += c
            # per frame the process handled: a node that dropped frames on a loaded machine
            # did less work, which the captured frames would count as a saving
            out_key = PROCESS_OUTPUT.get(name)
            o = (r.get(out_key) or {}) if out_key else {}
            done = o.get('skeletons', 0) / users / secs if out_key and secs > 0 else rate
            if done > 0:
                fig[f'cpu_ms_per_frame.{name}'] = c * 10.0 / done
        if procs:
            fig['cpu.graph'] = total
            if rate > 0:
                fig['cpu_ms_per_frame.graph'] = total * 10.0 / rate
        out[label] = fig
    return out


def at_nominal_speed(figures: Dict[str, Dict[str, float]], factor: float
                     ) -> Dict[str, Dict[str, float]]:
    """``figures`` with every ``cpu_ms_per_frame.*`` also divided by the machine speed factor of
    its run (the mean of the gauge before and after it), as ``cpu_ms_per_frame_x1.*``: the CPU
    time per frame the machine would have spent at its nominal speed. A run in a slow minute
    then does not read as a regression (the physics' CPU per frame varied with the host's speed
    by a coefficient of variation of 19 %, 8 % once divided; speed_gauge --beside-physics)."""
    if not (factor > 0 and factor < float('inf')):
        return figures
    return {case: {**fig, **{k.replace('cpu_ms_per_frame.', 'cpu_ms_per_frame_x1.', 1): v / factor
                             for k, v in fig.items() if k.startswith('cpu_ms_per_frame.')}}
            for case, fig in figures.items()}


@dataclass
class Comparison:
    """Per case and figure: A's and B's values in run order, and B / A per alternation."""
    a: Dict[str, Dict[str, List[float]]] = field(default_factory=dict)
    b: Dict[str, Dict[str, List[float]]] = field(default_factory=dict)

    def add(self, side: str, figures: Dict[str, Dict[str, float]]) -> None:
        dst = self.a if side == 'a' else self.b
        for case, fig in figures.items():
            for k, v in fig.items():
                dst.setdefault(case, {}).setdefault(k, []).append(v)

    def rows(self) -> List[Dict]:
        out = []
        for case in self.b:
            for k in sorted(self.b[case]):
                av, bv = self.a.get(case, {}).get(k, []), self.b[case][k]
                n = min(len(av), len(bv))
                ratios = [ratio(bv[i], av[i]) for i in range(n)]
                out.append({'case': case, 'figure': k, 'a': av, 'b': bv, 'ratios': ratios,
                            'ratio': ratio(statistics.median(bv), statistics.median(av))
                            if av and bv else float('nan')})
        return out


def ratio(b: float, a: float) -> float:
    if a == b:
        return 1.0
    return b / a if a > 0 else float('inf')


def regressions(rows: List[Dict], fail_ratio: float = FAIL_RATIO, min_ms: float = FAIL_MIN_MS,
                min_cpu: float = FAIL_MIN_CPU, min_alternations: int = 3) -> List[Dict]:
    """The rows the CI guard fails on: an output's p95 or the graph's CPU worse by more than
    ``fail_ratio`` AND by more than ``min_ms`` / ``min_cpu`` points on EVERY alternation (at
    least ``min_alternations`` of them), or frames dropped on every alternation where A dropped
    none. One slow run of the shared machine cannot fail it; a change that makes every run
    half as slow again does."""
    bad = []
    for r in rows:
        k, a, b = r['figure'], r['a'], r['b']
        n = min(len(a), len(b))
        if n < min_alternations:
            continue
        if k.endswith('.p95_ms') or k == 'cpu.graph':
            margin = min_cpu if k.startswith('cpu') else min_ms
            if all(b[i] > fail_ratio * a[i] and b[i] - a[i] > margin for i in range(n)):
                bad.append(r)
        elif k.endswith('.dropped'):
            if all(a[i] == 0 and b[i] > 0 for i in range(n)):
                bad.append(r)
    return bad


def uneven(loads: List[Dict], max_change: float = MAX_SPEED_CHANGE) -> List[Tuple[int, float]]:
    """The alternations (1-based) whose A and B runs saw machine speeds (before and after each)
    more than ``max_change`` apart, with that spread: their ratios compare different speeds."""
    out = []
    for i in range(0, len(loads) - 1, 2):
        f = [ld[k] for ld in loads[i:i + 2] for k in ('speed_before', 'speed_after')
             if ld.get(k)]
        if len(f) >= 2 and max(f) / min(f) > max_change:
            out.append((i // 2 + 1, max(f) / min(f)))
    return out


def to_markdown(cmp: Comparison, ref: str, ref_sha: str, head: str, loads: List[Dict],
                valid: bool, max_busy: float, args_line: str,
                max_speed_change: float = MAX_SPEED_CHANGE) -> str:
    lines = [f'# A/B benchmark: B = this tree ({head}) against A = {ref} ({ref_sha})', '',
             f'Command: `bench {args_line}`. Runs alternated A B A B ...; each figure lists the '
             'runs in order; ratio = B / A of the medians, and per alternation. CPU in % of one '
             'core over the measured seconds; cpu_ms_per_frame = CPU time per frame the process '
             'output (the captures for the driver and the graph): the figure least moved by '
             'other jobs.', '']
    if not valid:
        lines += [f'**NOT VALID**: the machine was busier than {100 * max_busy:.0f} % before '
                  'a run, or its speed had changed (`--ignore-load`): other jobs or the host '
                  'moved these figures; compare CPU time per frame only.', '']
    lines += ['| run | side | machine busy before | load average | waited s | machine speed '
              'before / after |', '|---:|---|---:|---:|---:|---|']
    for i, ld in enumerate(loads):
        def x(k, ld=ld):
            return f'x{ld[k]:.2f}' if ld.get(k) else '-'
        lines.append(f"| {i + 1} | {ld['side'].upper()} | {100 * ld['busy']:.0f} % | "
                     f"{ld['loadavg']:.2f} | {ld['waited_s']:.0f} | {x('speed_before')} / "
                     f"{x('speed_after')} |")
    if any(ld.get('speed_before') for ld in loads):
        lines += ['', 'Machine speed: `kinect_experiments.speed_gauge` (CPU time of a fixed '
                  'workload; x1.00 = nominal, x1.30 = 30 % slower), read right before and after '
                  'each run, outside it.'
                  + ''.join(f' Alternation {n}: A and B ran at speeds {spread:.2f}x apart, its '
                            'ratios compare different machine speeds.'
                            for n, spread in uneven(loads, max_speed_change or MAX_SPEED_CHANGE))]
    lines += ['', '| case | figure | A runs | B runs | B / A (medians) | B / A per alternation |',
              '|---|---|---|---|---:|---|']
    for r in cmp.rows():
        def vals(v):
            return ' · '.join(f'{x:.1f}' for x in v) or '-'
        lines.append(f"| {r['case']} | {r['figure']} | {vals(r['a'])} | {vals(r['b'])} | "
                     f"{r['ratio']:.2f} | {' · '.join(f'{x:.2f}' for x in r['ratios'])} |")
    return '\n'.join(lines) + '\n'


# ---------------------------------------------------------------------------- the side tree
def git(root: Path, *args: str) -> str:
    return subprocess.run(['git', *args], cwd=root, text=True, capture_output=True,
                          check=True).stdout.strip()


def resolve(root: Path, ref: str) -> str:
    """Full sha of ``ref``; a clear error when the clone does not have it (a shallow clone has
    no HEAD^: fetch with depth >= 2)."""
    try:
        return git(root, 'rev-parse', '--verify', f'{ref}^{{commit}}')
    except subprocess.CalledProcessError:
        raise ValueError(f'--against {ref}: no such commit in this clone (a shallow clone has '
                         'no history: git fetch --deepen=1, or name a commit it has)') from None


def _clean_env(root: Path) -> Dict[str, str]:
    """This process's environment without this tree's workspace (the other tree sources its own)."""
    env = dict(os.environ)
    for k in ('AMENT_PREFIX_PATH', 'CMAKE_PREFIX_PATH', 'COLCON_PREFIX_PATH', 'PYTHONPATH',
              'VIRTUAL_ENV', 'KINECT_POSTURE_ROOT', 'KINECT_POSTURE_ROS',
              'KINECT_POSTURE_LAUNCH_TOOLING',
              # the pip wheels' bootstrap sets the library path once per process tree: the
              # other tree's python redoes it (its own install on the path, not this one's)
              '_ROS_WHEELS_BOOTSTRAP_COMPLETE'):
        env.pop(k, None)
    for var in ('PATH', 'LD_LIBRARY_PATH'):
        keep = [p for p in env.get(var, '').split(os.pathsep)
                if p and not p.startswith(str(root)) and '.venv' not in p]
        env[var] = os.pathsep.join(keep)
    return env


def _venv() -> Path:
    return Path(os.environ.get('VIRTUAL_ENV') or Path(sys.executable).parent.parent)


def prepare(root: Path, sha: str, log=print) -> Path:
    """The reference tree at ``sha`` under ``cache/ab/``, built (colcon, over this tree's venv)
    once; later comparisons reuse it."""
    base = root / 'cache' / 'ab' / sha[:12]
    tree = base / 'tree'
    if not (tree / '.ab-source').exists():
        # the commit's files (git archive): no worktree registered in the repository
        tree.mkdir(parents=True, exist_ok=True)
        arch = subprocess.run(['git', 'archive', '--format=tar', sha], cwd=root,
                              capture_output=True, check=True).stdout
        subprocess.run(['tar', '-x', '-C', str(tree)], input=arch, check=True)
        (tree / '.ab-source').write_text(sha + '\n')
    shared = (root / '..' / 'shared').resolve()
    if shared.is_dir() and not (base / 'shared').exists():
        (base / 'shared').symlink_to(shared)   # the tree's ../shared: the same CMU clips
    venv = _venv()
    distro = os.environ.get('ROS_DISTRO', '')
    for name in ('.venv', f'.venv-{distro}' if distro else ''):
        if name and not (tree / name).exists():
            (tree / name).symlink_to(venv)
    stamp = tree / '.ab-built'
    if stamp.exists():
        return warm(root, tree, log)
    log(f'[ab] building {sha[:12]} in {tree} (colcon, once)')
    install, build = _bases(tree)
    # this tree's environment without its own packages: the venv and launch tooling (inside
    # the tree too: .venv-<distro>) and the vendored hri_msgs stay, the tree's install of its
    # own packages goes
    env = dict(os.environ)
    env.pop('COLCON_PREFIX_PATH', None)
    own = str(root / 'install') + os.sep
    env['AMENT_PREFIX_PATH'] = os.pathsep.join(
        p for p in env.get('AMENT_PREFIX_PATH', '').split(os.pathsep)
        if p and (not p.startswith(own) or os.path.basename(p.rstrip(os.sep)) == 'hri_msgs'))
    env['CMAKE_PREFIX_PATH'] = env['AMENT_PREFIX_PATH']
    res = subprocess.run(
        ['colcon', '--log-base', str(tree / 'log'), 'build', '--symlink-install', '--base-paths',
         'src', '--build-base', str(build), '--install-base', str(install), '--event-handlers',
         'console_direct-', 'console_cohesion-', 'status-', 'summary+', '--cmake-args',
         '-DBUILD_TESTING=OFF', f'-DPython3_EXECUTABLE={sys.executable}'],
        cwd=tree, env=env, text=True, capture_output=True)
    if res.returncode != 0:
        raise RuntimeError(f'building {sha[:12]} failed: {(res.stderr or res.stdout)[-400:]}')
    stamp.write_text(sha + '\n')
    return warm(root, tree, log)


def warm(root: Path, tree: Path, log=print) -> Path:
    """The reference's compiled kernels in its own numba cache, once: otherwise its first run
    compiles them inside the graph (its reconstruction busy compiling, every frame of that run
    lost) while this tree's come from the cache ``make setup`` filled. Its own warm_kernels
    where it has one, else one short discarded run of its bench."""
    stamp = tree / '.ab-warm'
    if stamp.exists():
        return tree
    log(f'[ab] compiling the kernels of {tree.parent.name} (once)')
    if (tree / 'src' / 'kinect_bringup' / 'kinect_bringup' / 'warm_kernels.py').is_file():
        run = 'python -m kinect_bringup.warm_kernels'
    else:
        scratch = shlex.quote(str(tree / 'log' / 'ab-warm'))
        run = (f'python -m {bench_module(tree)} --users 1 --seconds 3 --skip-bag '
               f'--out {scratch}')
    res = subprocess.run(['bash', '-c', f'cd {shlex.quote(str(tree))} && source scripts/env.sh '
                          f'>/dev/null && {run}'], env=_clean_env(root), text=True,
                         capture_output=True)
    if res.returncode != 0:
        raise RuntimeError(f'compiling the kernels of {tree} failed: '
                           f'{(res.stderr or res.stdout)[-400:]}')
    stamp.write_text('warm\n')
    return tree


def _bases(tree: Path) -> Tuple[Path, Path]:
    """(install, build) where the tree's own env.sh looks: install/<distro> since the distro
    split (scripts/distro.sh), install/ before."""
    if (tree / 'scripts' / 'distro.sh').is_file():
        out = subprocess.run(['bash', '-c', 'source scripts/distro.sh >/dev/null 2>&1; '
                              'echo "$_kp_install"; echo "$_kp_build"'], cwd=tree, text=True,
                             capture_output=True).stdout.split()
        if len(out) == 2:
            return Path(out[0]), Path(out[1])
    return tree / 'install', tree / 'build'


def bench_module(tree: Path) -> str:
    for mod in ('kinect_experiments', 'kinect_bringup'):
        if (tree / 'src' / mod / mod / 'bench.py').is_file():
            return f'{mod}.bench'
    raise ValueError(f'{tree}: no bench module (kinect_experiments or kinect_bringup)')


# options that change what is measured: an older bench without one is refused, not run without it
MEASURED_ALIKE = ('--drivers-elsewhere',)


def bench_command(tree: Path, case_args: Sequence[str], out: Path) -> List[str]:
    """Run ``tree``'s own bench with its own environment (its env.sh) on ``case_args``; options
    its bench does not know are left out (an older bench)."""
    known = _known_options(tree)
    args, i = [], 0
    case_args = list(case_args)
    for a in MEASURED_ALIKE:
        if a in case_args and a not in known:
            raise ValueError(f'the bench of {tree} has no {a}: without it that side would '
                             'measure another graph, and the ratios would not compare')
    while i < len(case_args):
        a = case_args[i]
        takes = i + 1 < len(case_args) and not case_args[i + 1].startswith('--')
        if a in known:
            args += case_args[i:i + 1 + takes]
        i += 1 + takes
    cmd = (f'cd {shlex.quote(str(tree))} && source scripts/env.sh >/dev/null && '
           f'exec python -m {bench_module(tree)} {" ".join(map(shlex.quote, args))} '
           f'--out {shlex.quote(str(out))}')
    return ['bash', '-c', cmd]


def _known_options(tree: Path) -> set:
    import re
    text = (tree / 'src' / bench_module(tree).split('.')[0] / bench_module(tree).split('.')[0]
            / 'bench.py').read_text()
    return set(re.findall(r"add_argument\('(--[a-z-]+)'", text))


def _guard_overridden(msg: str, ignore_load: bool, log) -> bool:
    """Log a load or speed guard's refusal; True when the run goes on anyway (--ignore-load: the
    report is then marked NOT VALID), False when the comparison must stop."""
    if not ignore_load:
        log(msg + '; refusing to compare (--ignore-load runs anyway, marked NOT VALID)')
        return False
    log(msg + '; --ignore-load: running, the report is marked NOT VALID')
    return True


def run_ab(root: Path, ref: str, case_args: Sequence[str], alternations: int, out: Path,
           max_busy: float = MAX_BUSY, wait_s: float = LOAD_WAIT_S, ignore_load: bool = False,
           fail_ratio: Optional[float] = None, args_line: str = '', log=print,
           max_slow: Optional[float] = None, max_speed_change: Optional[float] = MAX_SPEED_CHANGE,
           speed_wait_s: float = LOAD_WAIT_S, gauge: Callable = None) -> int:
    """The comparison; exit code 0 (printed), 1 (the guard found a regression), 3 (refused:
    the machine was not quiet)."""
    out = Path(out).resolve()
    sha = resolve(root, ref)
    head = git(root, 'rev-parse', '--short', 'HEAD')
    dirty = bool(git(root, 'status', '--porcelain', '--untracked-files=no'))
    tree_a = prepare(root, sha, log)
    bench_command(tree_a, case_args, out)   # a reference that cannot run the case: refused now
    out.mkdir(parents=True, exist_ok=True)
    cmp = Comparison()
    loads: List[Dict] = []
    valid = True
    gauge = gauge or speed_gauge.measure
    fastest = float('inf')
    for i in range(alternations):
        for side, tree in (('a', tree_a), ('b', root)):
            chk = wait_for_quiet(max_busy, wait_s)
            # the speed guard after the load guard: within max_speed_change of the fastest
            # reading of this comparison (and under max_slow, when given)
            limit = min(max_slow or float('inf'),
                        max_speed_change * fastest if max_speed_change else float('inf'))
            sp = speed_gauge.wait_for_speed(limit, speed_wait_s, gauge)
            fastest = min(fastest, sp.reading.factor)
            loads.append({'side': side, 'busy': chk.busy, 'loadavg': chk.loadavg,
                          'waited_s': chk.waited_s + sp.waited_s,
                          'speed_before': sp.reading.factor, 'gauge_before': sp.reading.as_dict()})
            if chk.ok and not sp.ok:
                msg = (f'[ab] the machine speed reads x{sp.reading.factor:.2f} (limit '
                       f'x{limit:.2f}: ' + (f'{max_speed_change:g} x the fastest reading of '
                                            f'this comparison, x{fastest:.2f}'
                                            if limit < (max_slow or float('inf')) else
                                            '--max-slow') + f') after waiting '
                       f'{sp.waited_s:.0f} s: the host is in a slower minute than the runs '
                       'already taken, whose ratios would compare different speeds')
                if not _guard_overridden(msg, ignore_load, log):
                    return 3
                valid = False
            if not chk.ok:
                msg = (f'[ab] the machine is {100 * chk.busy:.0f} % busy (threshold '
                       f'{100 * max_busy:.0f} %, load average {chk.loadavg:.2f}) after waiting '
                       f'{chk.waited_s:.0f} s: other jobs would move the figures more than the '
                       'change being compared')
                if not _guard_overridden(msg, ignore_load, log):
                    return 3
                valid = False
            run_out = out / f'{i + 1}{side}'
            cmd = bench_command(tree, case_args, run_out) if side == 'a' else \
                [sys.executable, '-m', 'kinect_experiments.bench', *case_args, '--out',
                 str(run_out)]
            log(f'[ab] alternation {i + 1}/{alternations}: '
                f'{"A " + sha[:12] if side == "a" else "B " + head + (" + changes" if dirty else "")}')
            env = _clean_env(root) if side == 'a' else None
            res = subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL,
                                 stderr=open(out / f'{i + 1}{side}.log', 'w'))
            after = gauge()
            fastest = min(fastest, after.factor)
            loads[-1].update(speed_after=after.factor, gauge_after=after.as_dict())
            speed = (sp.reading.factor + after.factor) / 2
            path = run_out / 'bench.json'
            if res.returncode != 0 or not path.is_file():
                raise RuntimeError(f'the {"reference" if side == "a" else "new"} bench failed '
                                   f'(exit {res.returncode}): {out / f"{i + 1}{side}.log"}')
            cmp.add(side, at_nominal_speed(run_figures(json.loads(path.read_text())), speed))
    md = to_markdown(cmp, ref, sha[:12], head + (' + uncommitted changes' if dirty else ''),
                     loads, valid, max_busy, args_line, max_speed_change)
    bad = regressions(cmp.rows(), fail_ratio) if fail_ratio else []
    if fail_ratio:
        md += (f'\nGuard (ratio > {fail_ratio:g} and > {FAIL_MIN_MS:g} ms / {FAIL_MIN_CPU:g} CPU '
               f'points worse on every one of {alternations} alternations, or drops where A had '
               f'none): ' + ('**FAILED** on ' + ', '.join(f"{r['case']} {r['figure']}"
                                                          for r in bad) if bad else 'passed')
               + (' (not valid: loaded machine)' if not valid else '') + '\n')
    (out / 'ab.md').write_text(md)
    (out / 'ab.json').write_text(json.dumps({'reference': sha, 'head': head, 'dirty': dirty,
                                             'valid': valid, 'loads': loads,
                                             'rows': cmp.rows()}, indent=2))
    log(md)
    log(f'[ab] wrote {out / "ab.md"} and {out / "ab.json"}')
    return 1 if bad else 0
