"""The segment output's compiled per-user arithmetic (segment_output_kernels.output_core) against
its numpy twin (SegmentOutput.output_rows with numba off): the same rows, directions, smoothing
arguments and filled-memory state, within float rounding (1e-12), on every option it branches on."""
import numpy as np
import pytest

from pose_reconstruction import segment_output_kernels as K
from pose_reconstruction.segment_output import (_SEG_CHAIN, SegmentOutput, SegmentOutputConfig,
                                                smooth_many)
from skeleton_core import jit
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import (ELBOW_LEFT, NUM_JOINTS, NUM_SEGMENTS, TRACKED, WRIST_LEFT,
                                 WRIST_RIGHT)

FPS = 30.0
TOL = 1e-12


def _user(compiled, u, **cfg):
    so = SegmentOutput(None, np.full(NUM_SEGMENTS, 0.3), lambda: True, 0.5, 'user',
                       SegmentOutputConfig(**cfg))
    so.profile_lengths = np.linspace(0.1, 0.45, NUM_SEGMENTS) * (1.0 + 0.05 * u)
    so.compiled = compiled
    return so


def _frame(u, k, few=False, zero=False):
    """User ``u``'s frame ``k``: (frame, solution, reliabilities, trust), some joints unreliable
    (``few``: only the wrists reliable), now and then a reliable segment seen with zero length
    (``zero``) and a joint missing (NaN)."""
    rng = np.random.default_rng(1000 * u + k)
    t = k / FPS
    a = 0.5 * np.sin(2 * np.pi * 0.7 * t + np.linspace(0, np.pi, NUM_SEGMENTS) + u)
    dirs = np.stack([np.sin(a), -np.cos(a), 0.2 * np.cos(a)], axis=1)
    root = np.array([0.6 * u - 1.0, 0.1, 2.4])
    obs = root + _SEG_CHAIN @ (dirs * 0.3) + rng.normal(scale=0.01, size=(NUM_JOINTS, 3))
    solution = root + _SEG_CHAIN @ (np.roll(dirs, u, axis=0) * 0.3)
    w = np.ones(NUM_JOINTS)
    if few:
        w[:] = rng.uniform(0.0, 0.3, NUM_JOINTS)
        w[[WRIST_LEFT, WRIST_RIGHT]] = 1.0
    else:
        # every fifth frame a gap: the filled memory's segments
        n = 3 + u + (6 if k % 5 == 0 else 0)
        w[rng.choice(NUM_JOINTS, n, replace=False)] = rng.uniform(0.0, 0.4, n)
    if zero and k % 3 == 0:
        obs[WRIST_LEFT] = obs[ELBOW_LEFT]
        w[[WRIST_LEFT, ELBOW_LEFT]] = 1.0
    if zero and k % 7 == 0:
        obs[3] = np.nan
    f = SkeletonFrame(positions=obs, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                      stamp_ns=int(k * 1e9 / FPS))
    return f, solution, w, [0.0, 0.3, 1.0][u % 3] if not few else 0.6


CASES = {
    'defaults': {},
    'no fusion, observation weight': dict(direction_fusion=False),
    'no fusion, no weight': dict(direction_fusion=False, observation_weight=0.0),
    'no memory': dict(filled_memory_s=0.0),
    'no position fit': dict(position_fit=0.0),
    'no smoothing': dict(smooth_min_cutoff=0.0),
    'plain scales': dict(smooth_filled_scale=1.0, smooth_trusted_scale=1.0, smooth_lead=0.0),
    'trusted scale only': dict(smooth_filled_scale=1.0),
}


def _compare(a, b):
    assert (a.filter is None) == (b.filter is None)
    assert a.stamp_ns == b.stamp_ns
    assert a.lengths is b.lengths or np.array_equal(a.lengths, b.lengths)
    np.testing.assert_allclose(a.rows, b.rows, rtol=0, atol=TOL)
    np.testing.assert_allclose(a.directions, b.directions, rtol=0, atol=TOL)
    for name in ('cutoff_scale', 'speed_scale', 'lead'):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            np.testing.assert_allclose(x, y, rtol=0, atol=TOL, err_msg=name)


def _run(cfg, kernel, few=False, zero=False, extras=False, frames=40):
    users = range(3)
    twin = [_user(False, u, **cfg) for u in users]
    comp = [_user(True, u, **cfg) for u in users]
    seen_speed = False
    for k in range(frames):
        for u in users:
            f, sol, w, trust = _frame(u, k, few, zero)
            kw = {}
            if extras:
                rng = np.random.default_rng(k)
                kw = dict(yaw=0.3 * u + 0.01 * k, root=f.positions[0] + 0.01,
                          db_spread=rng.uniform(0, 0.2, NUM_SEGMENTS), db_distance=0.05 + 0.01 * k)
            a = twin[u].output_rows(f, sol, w, trust, **kw)
            b = comp[u].output_rows(f, sol, w, trust, **kw)
            _compare(a, b)
            seen_speed |= b.speed_scale is not None
            np.testing.assert_allclose(twin[u]._seen_u, comp[u]._seen_u, rtol=0, atol=TOL)
            np.testing.assert_allclose(twin[u]._seen_age, comp[u]._seen_age, rtol=0, atol=1e-15)
            # and the output from the smoothing on: within the same rounding
            pa, pb = smooth_many([a]), smooth_many([b])
            np.testing.assert_allclose(SegmentOutput.output_positions(a, pa[0]),
                                       SegmentOutput.output_positions(b, pb[0]),
                                       rtol=0, atol=1e-9)
    return seen_speed


@pytest.fixture(params=['compiled', 'python'])
def kernel(request, monkeypatch):
    """The kernel compiled by numba, and its source run as plain Python (the same numbers)."""
    if request.param == 'compiled':
        if not jit.enabled():
            pytest.skip('numba not installed or switched off')
    else:
        monkeypatch.setattr(K, 'output_core', K._output_core)
    return request.param


@pytest.mark.parametrize('case', list(CASES))
def test_kernel_matches_numpy_twin(case, kernel):
    _run(CASES[case], kernel)


def test_kernel_matches_with_yaw_root_spread_zero_lengths_and_missing_joints(kernel):
    _run({}, kernel, zero=True, extras=True)


def test_kernel_matches_with_few_reliable_joints_the_anchored_speed(kernel):
    assert _run({}, kernel, few=True)   # the anchored speed term was taken
    _run(dict(smooth_anchored_speed=False), kernel, few=True, frames=10)


def test_kernel_changes_the_output_when_an_option_does():
    """The comparison can fail: the kernel with another option than the twin differs."""
    f, sol, w, trust = _frame(1, 5)
    a = _user(False, 1).output_rows(f, sol, w, trust)
    b = _user(True, 1, position_fit=0.0).output_rows(f, sol, w, trust)
    assert np.abs(a.rows - b.rows).max() > 1e-4
