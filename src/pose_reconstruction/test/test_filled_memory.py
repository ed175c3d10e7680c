"""filled_memory_s of the segment output: a segment the database fills starts from
where the sensor last saw it, in proportion to the trust in the sensor, the memory fading with
its time constant. On the real recordings (trust ~1: the database does not explain the
exercises) a glitch of a few frames kept the last seen shank instead of the database's raised
leg 60-90 cm off."""
import numpy as np
import pytest

from pose_reconstruction.segment_output import SEG_DIFF, SegmentOutput, SegmentOutputConfig
from pose_reconstruction.segment_output import _SEG_CHAIN
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS, NUM_SEGMENTS, TRACKED

SEG = 5          # a segment whose child is a leaf is not needed: any segment, its child unreliable


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _run(trust, memory, frames=30, lost_from=10):
    """Observed and database directions fixed and different; the segment's child unreliable
    from ``lost_from``: the output's direction of that segment per frame."""
    rng = np.random.default_rng(4)
    L = np.full(NUM_SEGMENTS, 0.3)
    uo, ud = _unit(rng.normal(size=(NUM_SEGMENTS, 3))), _unit(rng.normal(size=(NUM_SEGMENTS, 3)))
    # the database's direction of the segment 60 deg from the sensor's
    perp = _unit(np.cross(uo[SEG], [0.0, 0.0, 1.0]))
    ud[SEG] = np.cos(np.radians(60.0)) * uo[SEG] + np.sin(np.radians(60.0)) * perp
    root = np.array([0.0, 0.0, 2.5])
    obs = root + _SEG_CHAIN @ (uo * L[:, None])
    sol = root + _SEG_CHAIN @ (ud * L[:, None])
    so = SegmentOutput(None, L, lambda: True, 0.5, 'user',
                       SegmentOutputConfig(smooth_min_cutoff=0.0, symmetric_lengths=False,
                                           position_fit=0.0, filled_memory_s=memory))
    so.profile_lengths = L
    child = int(np.nonzero(SEG_DIFF[SEG] > 0)[0][0])
    out = []
    for i in range(frames):
        w = np.ones(NUM_JOINTS)
        if i >= lost_from:
            w[child] = 0.0
        f = SkeletonFrame(positions=obs, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                          stamp_ns=i * 33_333_333)
        p = so.output(f, sol, w, trust)
        out.append(_unit(SEG_DIFF[SEG] @ p))
    return np.array(out), uo[SEG], ud[SEG]


def _angle(a, b):
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


def test_a_trusted_sensor_keeps_the_last_seen_direction_then_fades_to_the_database():
    out, uo, ud = _run(trust=1.0, memory=0.5)
    start = _angle(uo, ud)
    assert _angle(out[:10], uo).max() < 1e-6            # seen and trusted: the sensor's
    assert _angle(out[10], uo) < 0.1 * start             # lost: where it was last seen
    # the memory fades with exp(-age / 0.5 s): after 0.5 s (15 frames) the blend is ~37 % memory
    assert _angle(out[10 + 15], ud) < 0.75 * start
    assert _angle(out[10 + 15], ud) > 0.2 * start


@pytest.mark.parametrize('trust, memory', [(0.0, 0.5), (1.0, 0.0)])
def test_without_trust_or_memory_the_database_fills(trust, memory):
    out, uo, ud = _run(trust=trust, memory=memory)
    assert _angle(out[10:], ud).max() < 1e-6
