"""A Kinect v1 skeleton sensor model: turns clean mocap into Kinect-like skeleton streams.

The model (parameters and the published values behind them: ``config/sensor_model.yaml``; the same
numbers are embedded here as :data:`DEFAULT_PARAMS` so it runs without the file):

1. *Placement* — the clip is resampled to 30 Hz, centred ``distance_m`` in front of the sensor and
   turned to face it; output is in the sensor frame (REP-103: x forward out of the sensor, y left,
   z up; the floor at ``z = -sensor_height_m``).
2. *Noise* — per joint: a fast AR(1) jitter (lateral ``base_mm`` + depth term ``k Z^2`` after
   Khoshelham & Elberink 2012), a slow AR(1) drift (frame-to-frame bone-length changes) and a
   per-session systematic joint-centre offset carried in the body frame.
3. *Occlusion* — geometric: a joint whose line of sight is blocked by a body capsule or the
   scenario's object is INFERRED at its last reported position; random episodes: the distal joints
   of a limb are INFERRED (frozen or collapsed onto the body) or NOT_TRACKED.
4. *False positives* — a joint latches onto a nearby external point and vibrates there while the
   SDK still reports it TRACKED (random onsets; in class c also when a hand comes near the object).
5. *Turning away* — smooth yaw excursions of the user; past ``degrade_deg`` the far limbs are
   INFERRED and jitter grows, past ``confusion_deg`` left and right are swapped.

Offline: :meth:`SensorModel.corrupt` -> :class:`~.sensor_stream.KinectStream`; live:
:meth:`SensorModel.stream` yields ``(positions, tracking_state, truth)`` frame by frame. Both run the
same per-frame state machine, so they have the same statistics. A clip is any object with ``name``,
``fps`` and ``positions`` (T, 20, 3) in a world frame (REP-103, floor at z = 0), e.g.
``skeleton_data.mocap.MotionClip``.

The parts: the parameters (:mod:`.sensor_params`), the per-frame state machine
(:mod:`.sensor_corrupter`, with the failure modes of classes d and e in :mod:`.sensor_failures`
and its geometry in :mod:`.sensor_geometry`), the streams (:mod:`.sensor_stream`) and their
statistics (:mod:`.sensor_statistics`).
"""
from __future__ import annotations

import zlib
from pathlib import Path
from typing import Dict, Iterator, Optional, Tuple, Union

import numpy as np

from skeleton_core.geometry import facing_yaw, yaw_matrix
from skeleton_core.model import HIP_CENTER, NUM_JOINTS
from .sensor_corrupter import _Corrupter
from .sensor_params import _group_array, load_params
from .sensor_stream import KinectStream, loop_blend, resample


class SensorModel:
    """Kinect v1 skeleton sensor model. ``params``: None (config/sensor_model.yaml or built-in
    defaults), a YAML path, or a dict of overrides. ``seed``: base seed of every stream."""

    def __init__(self, params: Union[None, str, Path, Dict] = None, seed: int = 0):
        self.params = load_params(params)
        self.seed = int(seed)
        self.fps = float(self.params['fps'])

    # ------------------------------------------------------------------------------------
    def place(self, clip) -> np.ndarray:
        """The clip's joints resampled to the sensor rate and put in front of the sensor (T,20,3)."""
        pos = np.asarray(clip.positions, float)
        pos = resample(pos, float(getattr(clip, 'fps', self.fps)), self.fps)
        pl = self.params['placement']
        ok = np.isfinite(pos).all(axis=(1, 2))
        if not ok.all():  # fill gaps in the input by holding the previous valid frame
            idx = np.maximum.accumulate(np.where(ok, np.arange(len(pos)), 0))
            pos = pos[idx]
        if pl.get('keep_facing', True) and len(pos) > 1:
            # the user keeps facing the screen: remove the slow part of the heading (moving average
            # of the unwrapped yaw over travel_window_s), turning each frame about its own root;
            # turning away is then modelled by the turn episodes at their configured rate
            w = max(1, int(round(float(pl.get('travel_window_s', 2.0)) * self.fps)))
            yaw = np.unwrap(facing_yaw(pos))
            padded = np.pad(yaw, (w // 2, w - 1 - w // 2), mode='edge')
            slow = np.convolve(padded, np.ones(w) / w, mode='valid')
            corr = -(slow - slow[0])
            c, sn = np.cos(corr), np.sin(corr)
            rot = np.zeros((len(pos), 3, 3))
            rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1] = c, -sn, sn, c
            rot[:, 2, 2] = 1.0
            r0 = pos[:, HIP_CENTER:HIP_CENTER + 1, :]
            pos = np.einsum('tij,tkj->tki', rot, pos - r0) + r0
        root = pos[:, HIP_CENTER, :2]
        travel = float(np.max(np.ptp(root, axis=0))) if len(root) else 0.0
        if travel > float(pl.get('max_travel_m', np.inf)):
            # treadmill: remove the slow part of the horizontal root path (moving average over
            # travel_window_s) so locomotion stays inside the play space
            w = max(1, int(round(float(pl.get('travel_window_s', 2.0)) * self.fps)))
            kernel = np.ones(w) / w
            padded = np.pad(root, ((w // 2, w - 1 - w // 2), (0, 0)), mode='edge')
            slow = np.stack([np.convolve(padded[:, k], kernel, mode='valid') for k in range(2)], 1)
            pos = pos.copy()
            pos[..., :2] -= (slow - slow.mean(axis=0))[:, None, :]
        centre = np.array([*np.mean(pos[:, HIP_CENTER, :2], axis=0), 0.0])
        pos = pos - centre
        if pl.get('face_sensor', True):
            yaws = facing_yaw(pos)
            mean_yaw = float(np.arctan2(np.mean(np.sin(yaws)), np.mean(np.cos(yaws))))
            # face -x (towards the sensor)
            pos = pos @ yaw_matrix(np.pi - mean_yaw).T
        pos = pos + np.array([float(pl['distance_m']), float(pl['lateral_offset_m']),
                              -float(pl['sensor_height_m'])])
        return pos

    def stream_seed(self, clip, scenario: str, seed: Optional[int] = None) -> int:
        base = self.seed if seed is None else int(seed)
        tag = f'{getattr(clip, "name", "")}/{scenario}'.encode()
        return (base * 1_000_003 + zlib.crc32(tag)) % (2 ** 31)

    def corrupt(self, clip, scenario: str = 'a', seed: Optional[int] = None,
                max_frames: Optional[int] = None, start_ns: int = 0,
                seed_tag: Optional[str] = None,
                sys_offset: Optional[np.ndarray] = None, view=None,
                time_shift_s: float = 0.0) -> KinectStream:
        """The whole clip through the sensor model (offline). ``seed_tag``: the stream's random
        seed from this tag instead of the scenario's name (another recording of the same user);
        ``sys_offset`` (20, 3): the systematic joint-centre offsets to use (e.g. those of
        :meth:`session_offsets`: the same sensor session) instead of drawing new ones; ``view``:
        see :meth:`stream`; ``time_shift_s`` (with a ``view``): this sensor captures that much
        later in the motion than the reference (an unsynchronised sensor's phase)."""
        s = self.stream_seed(clip, scenario if seed_tag is None else seed_tag, seed)
        if time_shift_s and view is None:
            raise ValueError('time_shift_s needs a view')
        c = _Corrupter(self, clip, scenario, s, view, time_shift_s)
        if sys_offset is not None:
            c.sys_offset = np.array(sys_offset, float).reshape(NUM_JOINTS, 3)
        n = c.T if max_frames is None else min(c.T, int(max_frames))
        pos = np.empty((n, NUM_JOINTS, 3))
        st = np.empty((n, NUM_JOINTS), np.uint8)
        tr = np.empty((n, NUM_JOINTS, 3))
        cl = np.empty((n, NUM_JOINTS), bool)
        for i in range(n):
            pos[i], st[i], tr[i], cl[i] = c.step(i)
        stamps = start_ns + np.round(np.arange(n) * 1e9 / self.fps).astype(np.int64)
        return KinectStream(positions=pos, tracking_state=st, truth=tr, stamps_ns=stamps,
                            events=c.events, scenario=scenario, seed=s, clean=cl,
                            clip_name=str(getattr(clip, 'name', '')), fps=self.fps)

    def session_offsets(self, clip, scenario: str = 'a', seed: Optional[int] = None) -> np.ndarray:
        """(20, 3) the systematic joint-centre offsets of ``corrupt(clip, scenario, seed)``."""
        return _Corrupter(self, clip, scenario,
                          self.stream_seed(clip, scenario, seed)).sys_offset.copy()

    def stream(self, clip, scenario: str = 'a', loop: bool = True, seed: Optional[int] = None,
               view=None) -> Iterator[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Live: yields ``(positions, tracking_state, truth)`` per frame (forever if ``loop``;
        then the clip's last :data:`~.sensor_stream.LOOP_BLEND_FRAMES` turn into its first posture,
        :func:`loop_blend`: no teleport at the loop point).

        ``view`` (a :class:`skeleton_core.tf.Transform`, None = the one sensor): several sensors
        watching the same people. The clip is placed for the *reference* sensor (``placement``)
        and ``view`` is this sensor's pose in the reference sensor's frame; the output is in this
        sensor's frame. Every view of one clip, scenario and seed shares the motion and the
        user's turns; noise, offsets, occlusion (line of sight from this sensor; the scenario's
        object between the user and this sensor) and failures are drawn per view. The sensors
        are assumed level (the floor at ``-(sensor_height_m + view z)``)."""
        c = _Corrupter(self, clip, scenario, self.stream_seed(clip, scenario, seed), view)
        if loop:
            c.truth_all = loop_blend(c.truth_all)
        while True:
            for i in range(c.T):
                pos, st, tr, _ = c.step(i)
                yield pos, st, tr
            if not loop:
                return

    # ------------------------------------------------------------------------------------
    def expected_jitter_mm(self, depth_m: Union[float, np.ndarray]) -> np.ndarray:
        """Model std (mm, RMS over the 3 axes) of the random error (fast + slow) per joint at a depth."""
        base = _group_array(self.params['jitter']['base_mm'])
        slow = _group_array(self.params['slow_drift']['sigma_mm'])
        dz = float(self.params['jitter']['depth_coeff_mm']) * np.asarray(depth_m, float) ** 2
        var = (3 * base ** 2 + dz ** 2) / 3 + slow ** 2
        return np.sqrt(var)
