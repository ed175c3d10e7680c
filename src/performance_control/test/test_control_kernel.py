"""The dynamics kernel (Eq. 2-4 and Eq. 1): numba and the numpy twin give the same forces, and
KINECT_NUMBA=0 selects the numpy twin (the package runs without numba)."""
import os
import subprocess
import sys

import numpy as np
import pytest

from performance_control import dynamics


def _inputs(rng):
    x = rng.normal(0, 0.3, 3) + [0, 0, 1.0]
    v = rng.normal(0, 0.5, 3)
    pe = x + rng.normal(0, 0.6, (4, 3))
    ve = rng.normal(0, 1.0, (4, 3))
    rh = rng.normal(0, 0.6, (4, 3))
    rhd = rng.normal(0, 1.0, (4, 3))
    g = rng.uniform(0, 9000, (4, 6))
    return x, v, pe, ve, rh, rhd, g, float(rng.uniform(-np.pi, np.pi))


def test_numpy_twin_equals_numba_contact_forces():
    pytest.importorskip('numba')
    rng = np.random.default_rng(3)
    for _ in range(50):
        args = _inputs(rng)
        a = dynamics._contact_forces_jit(*args)
        b = dynamics._contact_forces_np(*args)
        assert np.abs(b).max() > 1.0            # not trivially zero
        np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-7)


def test_numpy_twin_equals_numba_applied_forces():
    pytest.importorskip('numba')
    rng = np.random.default_rng(4)
    nb = 7
    xpos = rng.normal(0, 1, (nb, 3))
    qvel = rng.normal(0, 1, 15)
    eff_body = np.array([2, 3, 4, 5])
    eff_dof = np.array([3, 6, 9, 12])
    r0, r1 = rng.normal(0, 0.5, (4, 3)), rng.normal(0, 0.5, (4, 3))
    g = rng.uniform(0, 9000, (4, 6))
    # along / across r: the first clamped both ways, the third across only
    fmax = np.array([[1.0, 1.0], [np.inf, np.inf], [1e6, 1.0], [np.inf, np.inf]])
    for t in (0.0, 0.01, 0.05):           # inside and after the interpolation period
        outs = []
        for fn in (dynamics._apply_forces_jit, dynamics._apply_forces_np):
            xfrc = np.zeros((nb, 6))
            fn(xpos, qvel, xfrc, 1, 0, eff_body, eff_dof, r0, r1, t, 0.0, 1 / 30, g, 0.7, 123.0,
               fmax)
            outs.append(xfrc)
        np.testing.assert_allclose(outs[1], outs[0], rtol=1e-9, atol=1e-7)
        # each effector's force along r (effector - COM) and across it at most fmax (the arms'
        # strength: pull, swing), the unbounded ones untouched
        f = outs[1][eff_body, :3]
        r = xpos[eff_body] - xpos[1]
        u = r / np.linalg.norm(r, axis=1)[:, None]
        fr = np.sum(f * u, axis=1)
        ft = np.linalg.norm(f - fr[:, None] * u, axis=1)
        assert np.all(np.abs(fr) <= fmax[:, 0] + 1e-6) and np.all(ft <= fmax[:, 1] + 1e-6)
        assert np.isclose(abs(fr[0]), 1.0) and np.isclose(ft[0], 1.0) and np.isclose(ft[2], 1.0)
        assert abs(fr[2]) > 1.0                              # the third's pull is not clamped
        rh = r0 + min(t * 30, 1.0) * (r1 - r0)
        rhd = (r1 - r0) * 30 if t * 30 < 1 else np.zeros((4, 3))
        free = dynamics._contact_forces_np(xpos[1], qvel[0:3], xpos[eff_body],
                                           qvel[eff_dof[:, None] + np.arange(3)], rh, rhd, g, 0.7)
        np.testing.assert_allclose(f[[1, 3]], free[[1, 3]], rtol=1e-9)
        # Eq. 1: the COM gets the effectors' sum reversed plus the buoyancy
        np.testing.assert_allclose(outs[1][1, :3] + outs[1][eff_body, :3].sum(axis=0),
                                   [0, 0, 123.0], atol=1e-6)


def test_kinect_numba_0_selects_numpy_twin():
    code = ('from performance_control import composition as c, dynamics as d; '
            'print(d._apply_forces is d._apply_forces_np, d._contact_forces is d._contact_forces_np,'
            ' c._capsule_d is c._capsule_d_np)')
    env = dict(os.environ, KINECT_NUMBA='0')
    out = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ['True', 'True', 'True']


def test_numpy_twin_equals_numba_capsule_distances():
    """The capsule-axis distances of the pose constraints (composition.Obstacles._d): the
    compiled kernel and its numpy twin, on points before, along and past the segments and a
    degenerate (zero-length) axis."""
    pytest.importorskip('numba')
    from performance_control import composition
    rng = np.random.default_rng(5)
    a = rng.normal(0, 1, (6, 3))
    b = a + rng.normal(0, 1, (6, 3))
    b[3] = a[3]                                        # a point-like capsule
    ab = b - a
    den = np.maximum((ab * ab).sum(axis=1), 1e-12)
    pts = rng.normal(0, 2, (40, 3))
    pts[0] = a[0] + 0.5 * ab[0]                        # on an axis: distance 0
    d1, c1 = composition._capsule_d_jit(pts, a, ab, den)
    d2, c2 = composition._capsule_d_np(pts, a, ab, den)
    np.testing.assert_allclose(d1, d2, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(c1, c2, rtol=1e-12, atol=1e-15)
    assert d1[0, 0] < 1e-12
    # by hand: the distance to a segment clips to its ends
    d, cp = composition._capsule_d_jit(np.array([[2.0, 1.0, 0.0]]), np.zeros((1, 3)),
                                       np.array([[1.0, 0.0, 0.0]]), np.array([1.0]))
    assert d[0, 0] == pytest.approx(np.sqrt(2.0)) and np.allclose(cp[0, 0], [1.0, 0.0, 0.0])
    # no capsule: empty results
    d, cp = composition._capsule_d_jit(pts, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    assert d.shape == (40, 0) and cp.shape == (40, 0, 3)


def test_warm_up_compiles_the_capsule_kernel_for_the_real_calls():
    """The control node calls composition.warm_up() on configure: afterwards a real distance
    query compiles nothing more (no stall on a user's first control step)."""
    pytest.importorskip('numba')
    code = (
        'import numpy as np\n'
        'from performance_control import composition as c\n'
        'assert c.warm_up() > 0 and c.warm_up() == 0\n'
        'n = len(c._capsule_d_jit.signatures)\n'
        'o = c.Obstacles()\n'
        'o.capsules.append((np.array([0., 0, 2]), np.array([1., 0, 2]), 0.03, "bars"))\n'
        'd, _ = o.freeze()._d(np.array([[0.5, 0.0, 1.0], [0.2, 0.1, 1.5]]))\n'
        'assert abs(d[0, 0] - 1.0) < 1e-12, d\n'
        'assert len(c._capsule_d_jit.signatures) == n, c._capsule_d_jit.signatures\n')
    env = {k: v for k, v in os.environ.items() if k != 'KINECT_NUMBA'}
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, env=env,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
