"""What the sensor model produces and how a clip is timed for it: :class:`KinectStream` (a
corrupted clip, offline), :func:`resample` to the sensor rate and :func:`loop_blend` (a clip
played in a loop without a teleport)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List

import numpy as np

from skeleton_core.model import HIP_CENTER, NUM_JOINTS, forward_kinematics, parent_relative


@dataclass
class KinectStream:
    """A corrupted clip in the sensor frame."""

    positions: np.ndarray       # (T, 20, 3) what the Kinect reports
    tracking_state: np.ndarray  # (T, 20) uint8
    truth: np.ndarray           # (T, 20, 3) the true joints, same frame
    stamps_ns: np.ndarray       # (T,) int64
    events: List[Dict]          # onset records: type, cause, frame, joints, duration
    scenario: str
    seed: int
    clean: np.ndarray = field(default=None)  # (T, 20) bool: joint unaffected by any event
    clip_name: str = ''
    fps: float = 30.0

    def __len__(self) -> int:
        return len(self.positions)


def resample(positions: np.ndarray, fps_in: float, fps_out: float) -> np.ndarray:
    """Linear resampling of (T, 20, 3) positions from ``fps_in`` to ``fps_out``."""
    p = np.asarray(positions, float)
    if abs(fps_in - fps_out) < 1e-9 or len(p) < 2:
        return p.copy()
    t_in = np.arange(len(p)) / fps_in
    t_out = np.arange(0.0, t_in[-1] + 1e-9, 1.0 / fps_out)
    flat = p.reshape(len(p), -1)
    out = np.empty((len(t_out), flat.shape[1]))
    for k in range(flat.shape[1]):
        out[:, k] = np.interp(t_out, t_in, flat[:, k])
    return out.reshape(len(t_out), NUM_JOINTS, 3)

LOOP_BLEND_FRAMES = 15  # 0.5 s at 30 Hz: a looping clip ends in its first posture (stream())


def loop_blend(pos: np.ndarray, frames: int = LOOP_BLEND_FRAMES) -> np.ndarray:
    """(T, 20, 3) ``pos`` whose last ``frames`` (at most a third of the clip) turn smoothly
    into its first posture: the root moves linearly, every segment's direction is blended
    (normalised) with the same smooth-step weight at its own length, so a clip played in a loop
    has no teleport at the loop point and keeps its bone lengths."""
    p = np.array(pos, float)
    T = len(p)
    B = min(int(frames), T // 3)
    if B < 2:
        return p
    rel = parent_relative(p)
    u0 = rel[0, 1:] / np.maximum(np.linalg.norm(rel[0, 1:], axis=-1, keepdims=True), 1e-9)
    for k in range(B):
        i = T - B + k
        x = (k + 1) / (B + 1)
        w = x * x * (3 - 2 * x)
        seg = rel[i, 1:]
        L = np.linalg.norm(seg, axis=-1, keepdims=True)
        u = (1 - w) * seg / np.maximum(L, 1e-9) + w * u0
        u *= L / np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-9)
        root = (1 - w) * p[i, HIP_CENTER] + w * p[0, HIP_CENTER]
        r = rel[i].copy()
        r[1:] = u
        p[i] = forward_kinematics(r, root)
    return p
