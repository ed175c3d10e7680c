"""``demo`` (the README's ``make demo``): run the full graph on the default input for ~20 s, record
``out/demo.mcap`` and write a report a person can look at (animation, plots, summary).

The graph runs through ``ros2 launch kinect_bringup pipeline.launch.py`` where the launch tooling is
installed, else through the one-process ``pipeline``. The default input is the synthetic source:
CMU clips through the Kinect sensor model when ``../shared`` exists, the built-in motions otherwise.
"""
from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Optional

from skeleton_core.bagio import recover, truncation

from .dds_profile import use_startup_profile
from .graph import repo_root
from skeleton_data.database import build_default
from viz.report import main as report_main


def launch_available() -> bool:
    if shutil.which('ros2') is None:
        return False
    try:
        import launch  # noqa: F401
        import launch_ros  # noqa: F401
    except ImportError:
        return False
    return True


class OutputWatch:
    """A subscription to ``topic`` (the last stage of the graph), made before the graph starts:
    its rclpy import and DDS participant are not part of the start it times, and do not take
    CPU from the graph's processes while they come up."""

    def __init__(self, topic: str = '/character/skeletons'):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from skeleton_msgs.msg import SkeletonArray
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        self.node = Node('demo_watch', context=self.ctx)
        self.got = []
        self.node.create_subscription(SkeletonArray, topic, self.got.append, 10)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)

    def wait(self, proc, timeout: float, since: float) -> Optional[float]:
        """Seconds from ``since`` (monotonic) to the first message, or None (``timeout``, or
        ``proc`` ended)."""
        while not self.got and time.monotonic() - since < timeout and proc.poll() is None:
            self.executor.spin_once(timeout_sec=0.2)
        return (time.monotonic() - since) if self.got else None

    def close(self) -> None:
        import rclpy
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.ctx)


def run_graph(bag: Path, duration: float, args, use_launch: bool,
              startup_timeout: float = 180.0) -> int:
    """Start the graph, let it run ``duration`` s, stop it with SIGINT (as Ctrl-C does)."""
    opts = {'scenario': args.scenario, 'num_users': str(args.num_users), 'method': args.method,
            'seed': str(args.seed)}
    if use_launch:
        # pipeline.launch.py that a SIGUSR1 stops without the Ctrl-C notice in the graph log
        cmd = ['ros2', 'launch', 'kinect_bringup', 'demo.launch.py', f'record:={bag}'] + \
            [f'{k}:={v}' for k, v in opts.items()]
    else:
        cmd = [sys.executable, '-m', 'kinect_bringup.pipeline', '--record', str(bag),
               '--scenario', args.scenario, '--num-users', str(args.num_users),
               '--method', args.method, '--seed', str(args.seed)]
    print(f'[demo] running for {duration:.0f} s: {" ".join(cmd)}', flush=True)
    log_path = bag.with_suffix('.log')
    # the start's Fast DDS profile (unless the user has one) for the watch and the graph
    use_startup_profile()
    watch = OutputWatch()
    with open(log_path, 'w') as log:
        t0 = time.monotonic()
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            try:
                started = watch.wait(proc, startup_timeout, t0)
            finally:
                watch.close()
            if started is None:
                print(f'[demo] the graph produced no /character/skeletons within '
                      f'{startup_timeout:.0f} s; stopping it', file=sys.stderr)
            else:
                print(f'[demo] graph up after {started:.1f} s; recording {duration:.0f} s', flush=True)
                deadline = time.monotonic() + duration
                while time.monotonic() < deadline and proc.poll() is None:
                    time.sleep(0.2)
            if proc.poll() is None:
                if use_launch:   # the launch stops its nodes (SIGINT each) and ends
                    os.kill(proc.pid, signal.SIGUSR1)
                else:
                    os.killpg(proc.pid, signal.SIGINT)
                try:
                    proc.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait()
        except KeyboardInterrupt:
            os.killpg(proc.pid, signal.SIGINT)
            proc.wait(timeout=30)
            raise
    rc = proc.returncode
    if rc not in (0, -signal.SIGINT, 130) and not bag.exists():
        print(f'[demo] the graph failed (exit {rc}); its log: {log_path}', file=sys.stderr)
        print(log_path.read_text()[-3000:], file=sys.stderr)
        return 1
    print(f'[demo] graph log: {log_path}', flush=True)
    return 0


def main(argv=None) -> int:
    root = repo_root() or Path.cwd()
    p = argparse.ArgumentParser(prog='demo', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--out', default=str(root / 'out'), help='output directory')
    p.add_argument('--duration', type=float, default=20.0, help='seconds of running graph')
    p.add_argument('--scenario', default='b', choices=['a', 'b', 'c', 'd', 'e'])
    p.add_argument('--num-users', type=int, default=1)
    p.add_argument('--method', default='C', choices=['A', 'B', 'C'])
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--no-launch', action='store_true', help='use the one-process pipeline')
    args = p.parse_args(argv)

    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    bag = out / 'demo.mcap'
    if bag.exists():
        bag.unlink()

    # The nodes load the default database file, never build it: its producer (make build-db)
    # first, from the cache when its inputs have not changed.
    t0 = time.monotonic()
    db = build_default()
    print(f'[demo] motion database: {len(db)} postures ({db.meta.get("source", "?")}), '
          f'{time.monotonic() - t0:.1f} s', flush=True)

    use_launch = launch_available() and not args.no_launch
    print(f'[demo] runner: {"ros2 launch" if use_launch else "one-process pipeline"}', flush=True)
    if run_graph(bag, args.duration, args, use_launch) != 0:
        return 1
    if not bag.exists():
        print(f'[demo] no bag was written at {bag}', file=sys.stderr)
        return 1
    if truncation(bag) is not None:
        # the recorder was stopped before it finished the file (launch escalates to SIGTERM and
        # SIGKILL when a node takes longer than a few seconds to stop, e.g. on a loaded machine):
        # every complete message is kept, as recover_bag does
        fixed = bag.with_name('demo.recovered.mcap')
        n, cut = recover(bag, fixed)
        fixed.replace(bag)
        print(f'[demo] the recording was not finished ({cut}); recovered {n} messages', flush=True)

    rc = report_main(['--bag', str(bag), '--out', str(out)])
    print(f'[demo] done. Outputs in {out}:')
    for f in sorted(out.iterdir()):
        if f.is_file():
            print(f'  {f}  ({f.stat().st_size / 1024:.0f} kB)')
    return int(rc or 0)


if __name__ == '__main__':
    sys.exit(main())
