"""Synthetic source (the default): ground-truth motion through the Kinect sensor model.

Motion (``clip``): ``''`` = the built-in motions (``skeleton_data.motions.builtin_clips``; user k
gets motion k), the name of a built-in clip (e.g. ``builtin_wave``), or a path to a CMU BVH file
(``skeleton_data.mocap.load_cmu_clip``, e.g. one under ``/work/shared/mocap/cmu``). When every user
plays the same clip, user k starts k/num_users of the way into it.

Each of ``num_users`` (1-6) users gets its own sensor-model stream (``SensorModel.stream``,
scenario a-e, seed ``seed + user``; a clip's last 0.5 s turn into its first posture, so the loop
has no teleport: ``sensor_stream.loop_blend``), placed side by side ``user_spacing`` metres apart across the
field of view (the model's ``placement.lateral_offset_m``). User ids are 1..num_users.

Several sensors (``driver.launch.py sensors:=N``): one driver per sensor, each with ``view_pose``
= its pose in the first sensor's frame; every driver simulates the same people (placed for the
first sensor, facing it) seen from its own place, with its own noise and occlusion
(``SensorModel.stream(view=...)``), and shows the motion's frame of the wall clock (frame k at
k / rate_hz s since the epoch): drivers started at different times see the same instant together,
their frames apart by their timers' phase.

Timing: a simulated sensor captures frames on a fixed, drift-free schedule ``A + k / rate_hz``,
anchored at the first poll. Each frame is stamped with its scheduled capture time; a poll returns
every frame due by then, so a late poll (a loaded machine) catches up instead of losing frames.
A poll that comes less than half a period before the next capture (the first poll was late, the
timer is back on its grid) moves the schedule back to it, so frames leave at the moment they
are stamped and the latency measured downstream is the graph's own. When more than
``MAX_CATCHUP`` frames are overdue the backlog is skipped (counted in ``skipped``).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from pathlib import Path
from typing import List, Optional

import numpy as np

from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS, TRACKED
from skeleton_core.params import check, param
from skeleton_core.tf import parse_pose

from .base import Source, SourceError, SourceOutput
from skeleton_data.motions import builtin_clips
from skeleton_data.mocap import load_cmu_clip
from skeleton_eval.sensor_model import SensorModel
from skeleton_eval.sensor_params import load_params
from skeleton_eval.sensor_stream import resample

MAX_USERS = 6
MAX_CATCHUP = 15  # frames (0.5 s at 30 Hz)


def _load_motion(clip: str, seed: int):
    """The list of clips users cycle through."""
    if not clip:
        return builtin_clips(seed)
    builtins = {c.name: c for c in builtin_clips(seed)}
    for name in (clip, f'builtin_{clip}'):
        if name in builtins:
            return [builtins[name]]
    p = Path(clip).expanduser()
    if not p.is_file():
        raise SourceError(f'clip {clip!r} is neither a file nor a built-in motion '
                          f'({", ".join(sorted(builtins))})')
    try:
        return [load_cmu_clip(p)]
    except Exception as e:  # BvhError / MocapError / OSError: one line naming the file
        raise SourceError(f'cannot load motion clip {p}: {e}') from None


def _pose_error(text: str):
    if not text:
        return None
    try:
        parse_pose(text)
    except ValueError as e:
        return str(e)
    return None


@dataclass
class SyntheticConfig:
    """Parameters of :class:`SyntheticSource`."""

    scenario: str = param('b', 'sensor-model scenario class a | b | c | d | e (d: confident '
                          'failures; e: small persistent errors of TRACKED joints; clean: noise '
                          'only)', choices=('a', 'b', 'c', 'd', 'e', 'clean'))
    seed: int = param(0, 'random seed of the sensor model and motions', range=(0, 2 ** 31 - 1))
    num_users: int = param(1, 'number of users side by side', range=(1, MAX_USERS))
    clip: str = param('', "motion ('' = built-in motions, a built-in name such as builtin_wave, "
                      'or a CMU BVH path)')
    user_spacing: float = param(0.8, 'lateral distance between users (m)', range=(0.3, 2.0),
                                public=False)
    sensor_params: str = param('', "sensor model YAML ('' = config/sensor_model.yaml or the "
                               'built-in defaults)')
    rate_hz: float = param(30.0, 'frame rate (Hz)', range=(1.0, 120.0))
    view_pose: str = param('', "several sensors: this sensor's pose in the first sensor's frame, "
                           '"x y z yaw pitch roll" (m, deg; the people face the first sensor; '
                           "set by driver.launch.py sensors:=N); '' = the only sensor",
                           validator=lambda v: _pose_error(v))


class SyntheticSource(Source):
    name = 'synthetic'
    tracker = 'sensor_model'
    config_class = SyntheticConfig
    has_truth = True

    def __init__(self, config: Optional[SyntheticConfig] = None, frame_id: str = 'kinect_link',
                 with_truth: bool = True, **params):
        cfg = replace(config or SyntheticConfig(), **params)
        try:
            check(cfg)
        except ValueError as e:
            raise SourceError(str(e)) from None
        self.config = cfg
        self.scenario = cfg.scenario
        self.seed = int(cfg.seed)
        self.num_users = int(cfg.num_users)
        self.clip = cfg.clip
        rate_hz = cfg.rate_hz
        self.period_s = 1.0 / float(rate_hz)
        self.frame_id = frame_id
        self.user_spacing = float(cfg.user_spacing)
        self.sensor_params = cfg.sensor_params
        self.view = parse_pose(cfg.view_pose) if cfg.view_pose else None
        self.with_truth = with_truth
        self._streams: List = []
        self._lengths: List[int] = []
        self.frames_out = 0
        self.skipped = 0
        self.clip_names: List[str] = []
        self._period_ns = int(round(1e9 / float(rate_hz)))
        self._next_ns = None
        self._ready = None  # the next frame's simulated data, computed ahead by prepare()

    def open(self) -> None:
        if self.sensor_params and not Path(self.sensor_params).is_file():
            raise SourceError(f'sensor model parameter file {self.sensor_params} not found')
        try:
            base = load_params(self.sensor_params or None)
        except Exception as e:
            raise SourceError(f'cannot load sensor model parameters '
                              f'{self.sensor_params or "(default)"}: {e}') from None
        # the tracker the model stands for (a tracker's variant declares its own, e.g. the
        # Azure Kinect body tracking's), published on /kinect/tracker like a real source's
        self.tracker = str(base.get('tracker') or 'sensor_model')
        clips = _load_motion(self.clip, self.seed)
        self._streams = []
        self._lengths = []
        self._ready = None
        self.clip_names = []
        n = self.num_users
        for k in range(n):
            clip = clips[k % len(clips)]
            if len(clips) == 1 and n > 1:  # same motion for everybody: stagger the start
                shift = (k * len(clip)) // n
                clip = replace(clip, name=f'{clip.name}+{shift}',
                               positions=np.roll(clip.positions, -shift, axis=0),
                               orientations=np.roll(clip.orientations, -shift, axis=0))
            params = copy.deepcopy(base)
            params['placement']['lateral_offset_m'] = (
                float(base['placement'].get('lateral_offset_m', 0.0))
                + (k - (n - 1) / 2.0) * self.user_spacing)
            model = SensorModel(params=params, seed=self.seed + k)
            self._streams.append(model.stream(clip, self.scenario, loop=True, view=self.view))
            self.clip_names.append(clip.name)
            self._lengths.append(len(resample(
                np.asarray(clip.positions, float)[:, :1], float(clip.fps), model.fps)))

    def poll(self, now_ns: int) -> List[SourceOutput]:
        period = self._period_ns
        if self._next_ns is None and self.view is not None:
            # several sensors: every driver shows the motion frame of the wall clock (frame k at
            # k / rate s since the epoch), so sensors started at different times see the same
            # instant at the same time, as real ones do
            k = int(now_ns // period)
            self._ready = None
            for stream, length in zip(self._streams, self._lengths):
                for _ in range(k % max(length, 1)):
                    next(stream)
        if self._next_ns is None or 0 < self._next_ns - now_ns < period // 2:
            self._next_ns = now_ns   # first poll, or the timer ticks earlier than the schedule
        due = (now_ns - self._next_ns) // period + 1
        if due > MAX_CATCHUP:
            skip = due - 1
            self._next_ns += skip * period
            self.skipped += skip
        outs = []
        while self._next_ns <= now_ns:
            outs.append(self._capture(self._next_ns))
            self._next_ns += period
        return outs

    def prepare(self) -> None:
        """Simulate the next frame now (after the current one went out): a real sensor has its
        frame ready when it is captured; the simulation's cost must not count as latency."""
        if self._ready is None and self._streams:
            self._ready = [next(stream) for stream in self._streams]

    def _capture(self, stamp_ns: int) -> SourceOutput:
        frames, truth = [], []
        data, self._ready = self._ready, None
        if data is None:
            data = [next(stream) for stream in self._streams]
        for k, (pos, state, true_pos) in enumerate(data):
            uid = k + 1
            frames.append(SkeletonFrame(positions=np.asarray(pos, float),
                                        tracking_state=np.asarray(state, np.uint8), user_id=uid,
                                        stamp_ns=stamp_ns, frame_id=self.frame_id))
            if self.with_truth:
                truth.append(SkeletonFrame(positions=np.asarray(true_pos, float),
                                           tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                                           user_id=uid, stamp_ns=stamp_ns, frame_id=self.frame_id))
        self.frames_out += 1
        return SourceOutput(stamp_ns=stamp_ns, frames=frames,
                            truth=truth if self.with_truth else None, frame_id=self.frame_id)

    def close(self) -> None:
        self._streams = []

    def describe(self) -> str:
        return (f'scenario {self.scenario}, {self.num_users} user(s): '
                + ','.join(self.clip_names))

    def status(self) -> dict:
        return {'scenario': self.scenario, 'users': self.num_users,
                'clips': ','.join(self.clip_names), 'frames_skipped': self.skipped}

