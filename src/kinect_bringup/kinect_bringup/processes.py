"""Start and stop the graph as OS processes (one-process ``pipeline`` or one process per node),
for the benchmark, the soak and the tests. No rclpy here."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional, Sequence

from skeleton_core.tf import DEFAULT_SENSOR_POSE, SENSOR_FRAME

from .graph import NODES, NodeInfo, config_dir, graph_nodes, load_params

# nodes that look their input's frame up on TF: a graph with one of them gets the sensor frame
# on /tf_static, as the launch files' static_tf does
TF_USERS = {'physics', 'viz', 'control'}
STATIC_TF = NodeInfo('static_tf', 'kinect_driver', 'static_tf', 'kinect_driver.static_tf_node')


def executable(node) -> List[str]:
    """Command that runs one node's console script (installed by colcon), or its module
    (``node``: a name of :data:`NODES` or a :class:`NodeInfo`)."""
    info = NODES[node] if isinstance(node, str) else node
    prefix = os.environ.get('COLCON_PREFIX_PATH', '').split(os.pathsep)[0] or None
    candidates = []
    if prefix:
        candidates.append(Path(prefix) / info.package / 'lib' / info.package / info.executable)
    try:
        from ament_index_python.packages import get_package_prefix
        candidates.append(Path(get_package_prefix(info.package)) / 'lib' / info.package / info.executable)
    except Exception:  # noqa: BLE001
        pass
    for c in candidates:
        if c.is_file():
            return [sys.executable, str(c)]
    return [sys.executable, '-c', f'import sys; from {info.module} import main; sys.exit(main())']


def _ros_value(v) -> str:
    if isinstance(v, bool):
        return 'true' if v else 'false'
    if isinstance(v, str):
        return v if v else "''"
    return str(v)


def node_command(node: str, values: Optional[Dict] = None, name: Optional[str] = None,
                 ros_args: Sequence[str] = ()) -> List[str]:
    """The command that runs graph node ``node`` as its own process, with its YAML file (or, for a
    node without one, the values ``load_params`` maps onto it), ``values`` on top, node name
    ``name`` (default: ``node``) and further ``--ros-args`` (``-r __ns:=/kinect_1``, remaps)."""
    cdir = config_dir()
    cmd = executable(node) + ['--ros-args', '-r', f'__node:={name or node}'] + list(ros_args)
    pf = cdir / f'{node}.yaml'
    values = dict(values or {})
    if pf.is_file():
        cmd += ['--params-file', str(pf)]
    else:  # a node without a file of its own (the fused reconstruction)
        values = {**load_params(node, cdir), **values}
    for k, v in values.items():
        cmd += ['-p', f'{k}:={_ros_value(v)}']
    return cmd


class Graph:
    """The node graph as running processes; ``stop()`` sends SIGINT like Ctrl-C."""

    def __init__(self, mode: str = 'pipeline', nodes: Optional[List[str]] = None,
                 overrides: Optional[Dict[str, Dict]] = None, pipeline_args: Optional[List[str]] = None,
                 log_dir: Optional[Path] = None, env: Optional[Dict[str, str]] = None,
                 sensor_pose: str = DEFAULT_SENSOR_POSE):
        self.mode = mode
        self.procs: Dict[str, subprocess.Popen] = {}
        self._logs = []
        self.log_dir = Path(log_dir) if log_dir else None
        self.env = dict(os.environ, **(env or {}))
        self.env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        if mode == 'pipeline':
            cmd = [sys.executable, '-m', 'kinect_bringup.pipeline'] + list(pipeline_args or [])
            self._start('pipeline', cmd)
        elif mode == 'processes':
            names = list(nodes or graph_nodes())
            if TF_USERS & set(names):
                self._start('static_tf', executable(STATIC_TF) + [
                    '--pose', sensor_pose, '--child', SENSOR_FRAME,
                    '--ros-args', '-r', '__node:=static_tf'])
            for name in names:
                self._start(name, node_command(name, (overrides or {}).get(name)))
        else:
            raise ValueError(f'unknown mode {mode!r} (pipeline | processes)')

    def _start(self, name: str, cmd: List[str]):
        if self.log_dir:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            # a restarted node appends to its log: what the killed process wrote is kept
            restart = name in self.procs
            out = open(self.log_dir / f'{name}.log', 'a' if restart else 'w')
            if restart:
                out.write(f'---- {name} restarted ----\n')
                out.flush()
            self._logs.append(out)
        else:
            out = subprocess.DEVNULL
        self.procs[name] = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=self.env,
                                            start_new_session=True)

    def add(self, name: str, cmd: List[str]):
        """Start one more process (e.g. a second driver, a static_tf) as part of the graph."""
        if name in self.procs:
            raise ValueError(f'{name} is already part of the graph')
        self._start(name, cmd)

    def restart(self, name: str):
        """Kill one process and start it again with the same command (robustness tests)."""
        p = self.procs[name]
        cmd = p.args
        self.kill(name)
        self._start(name, cmd)

    def start(self, name: str):
        """Start a process that was killed again, with its command (a sensor replugged)."""
        p = self.procs[name]
        if p.poll() is None:
            raise RuntimeError(f'{name} is running')
        self._start(name, p.args)

    def kill(self, name: str, sig=signal.SIGKILL):
        p = self.procs[name]
        if p.poll() is None:
            os.killpg(p.pid, sig)
            p.wait(timeout=10)

    def alive(self) -> Dict[str, bool]:
        return {n: p.poll() is None for n, p in self.procs.items()}

    def stop(self, timeout: float = 15.0) -> Dict[str, int]:
        for p in self.procs.values():
            if p.poll() is None:
                try:
                    os.killpg(p.pid, signal.SIGINT)
                except ProcessLookupError:
                    pass
        deadline = time.monotonic() + timeout
        codes = {}
        for n, p in self.procs.items():
            try:
                codes[n] = p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                codes[n] = p.wait()
        for f in self._logs:
            f.close()
        return codes

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()
