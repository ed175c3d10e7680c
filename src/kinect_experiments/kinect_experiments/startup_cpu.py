"""``python -m kinect_experiments.startup_cpu``: the CPU seconds each process of the graph spends to
come up, by CPU time (valid on a loaded machine, unlike the wall clock of ``make demo``'s "graph
up after N s"). Runs ``ros2 launch kinect_bringup demo.launch.py`` (``make demo``'s graph, with a
recording) ``--runs`` times and reads every process of the launch from ``/proc`` at the moment
the launch logs ``/driver active`` (the driver is activated last, once every other node is
active): the launch itself, each node process (with the CPU of any child it ran and waited for
meanwhile), and their total; the median over the runs.

    python -m kinect_experiments.startup_cpu [--runs 3] [--num-users 2] [--out out/startup_cpu]

Linux only (``/proc``). Each run uses a fresh DDS graph of its own launch; stop other graphs on
the same ROS_DOMAIN_ID first.
"""
from __future__ import annotations

import argparse
import os
import re
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, Optional

READY = '/driver active'   # kinect_bringup.launch_nodes logs it once the source is active


def stat_fields(text: str) -> list:
    """The fields of a ``/proc/PID/stat`` line after the command name (which may hold spaces and
    parentheses): index 0 is the state, 2 the process group, 3 the session, 11/12 utime/stime,
    13/14 those of its children that ended."""
    return text[text.rindex(')') + 2:].split()


def cpu_seconds(fields: list, hz: float) -> float:
    """The process's CPU and that of its children that ended (cutime/cstime: a library that
    probes something in a short-lived subprocess at import, which ``/proc`` no longer lists)."""
    return sum(int(f) for f in fields[11:15]) / hz


def process_name(cmdline: list) -> str:
    """'launch' for ``ros2 launch``, the executable for a node (``.../lib/PKG/EXE``)."""
    for a, b in zip(cmdline, cmdline[1:]):
        if Path(a).name == 'ros2' and b == 'launch':
            return 'launch'
    text = ' '.join(cmdline)
    m = re.search(r'/lib/[A-Za-z0-9_]+/([A-Za-z0-9_]+)', text)
    return m.group(1) if m else (Path(cmdline[0]).name if cmdline else '?')


def session_cpu(sid: int, hz: float) -> Dict[str, float]:
    """CPU seconds per process name of the processes of session ``sid``."""
    out: Dict[str, float] = {}
    for d in os.listdir('/proc'):
        if not d.isdigit():
            continue
        try:
            fields = stat_fields(Path(f'/proc/{d}/stat').read_text())
            if int(fields[3]) != sid:
                continue
            cmd = [c.decode(errors='replace') for c in
                   Path(f'/proc/{d}/cmdline').read_bytes().split(b'\0') if c]
        except (OSError, ValueError, IndexError):
            continue   # ended meanwhile
        name = process_name(cmd)
        out[name] = out.get(name, 0.0) + cpu_seconds(fields, hz)
    return out


def one_run(out: Path, k: int, num_users: int, timeout_s: float) -> Optional[Dict[str, float]]:
    log = out / f'launch_{k}.log'
    hz = os.sysconf('SC_CLK_TCK')
    with open(log, 'w') as f:
        proc = subprocess.Popen(['ros2', 'launch', 'kinect_bringup', 'demo.launch.py',
                                 f'record:={out / f"run_{k}.mcap"}', f'num_users:={num_users}'],
                                stdout=f, stderr=subprocess.STDOUT, start_new_session=True)
    snap = None
    try:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end and proc.poll() is None:
            time.sleep(0.05)
            cpu = session_cpu(proc.pid, hz)   # (read before the log: never after READY)
            if READY in log.read_text():
                snap = cpu
                break
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGUSR1)   # demo.launch.py: a clean stop
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    if snap is None:
        print(f'[startup_cpu] run {k}: the graph was not up within {timeout_s:.0f} s ({log})',
              file=sys.stderr)
    return snap


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog='startup_cpu', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--runs', type=int, default=3)
    p.add_argument('--num-users', type=int, default=2)
    p.add_argument('--out', default='out/startup_cpu', help='launch logs and recordings')
    p.add_argument('--timeout', type=float, default=120.0, help='s per run')
    args = p.parse_args(argv)
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    runs = []
    for k in range(args.runs):
        snap = one_run(out, k, args.num_users, args.timeout)
        if snap is None:
            return 1
        runs.append(snap)
        print(f'run {k}: ' + ', '.join(f'{n} {s:.2f}' for n, s in sorted(snap.items()))
              + f' | total {sum(snap.values()):.2f} s CPU', flush=True)
    names = sorted({n for r in runs for n in r})
    med = {n: statistics.median(r.get(n, 0.0) for r in runs) for n in names}
    print(f'median of {len(runs)}: ' + ', '.join(f'{n} {med[n]:.2f}' for n in names)
          + f' | total {statistics.median(sum(r.values()) for r in runs):.2f} s CPU')
    return 0


if __name__ == '__main__':
    sys.exit(main())
