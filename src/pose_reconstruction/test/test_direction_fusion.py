"""direction_fusion of the segment output: a reliable segment's observed direction
weighted by the expected errors of the sensor (joint-centre offsets across the segment) and of the
database, so that a long segment the sensor sees follows it and a short one takes the database's."""
import numpy as np
import pytest

from pose_reconstruction.segment_output import (_SEG_CHAIN, SEG_DIFF, SegmentOutput,
                                                SegmentOutputConfig, neighbour_direction_spread)
from skeleton_core.geometry import yaw_matrix
from pose_reconstruction.reconstructor import Reconstructor
from pose_reconstruction.synthetic import random_database
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS, NUM_SEGMENTS, TRACKED, standard_body


def _unit(rng, n):
    u = rng.normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _run(L, sigma, db_spread=None, db_distance=None, **kw):
    """One untrusted frame (trust 0, every joint reliable): the output's segment directions and
    the observed and database ones."""
    rng = np.random.default_rng(7)
    root = np.array([0.0, 0.1, 2.4])
    uo, ud = _unit(rng, NUM_SEGMENTS), _unit(rng, NUM_SEGMENTS)
    so = SegmentOutput(None, np.full(NUM_SEGMENTS, 0.3), lambda: True, 0.5, 'user',
                       SegmentOutputConfig(smooth_min_cutoff=0.0, symmetric_lengths=False, **kw))
    so.profile_lengths = L
    so.offset_sigma = lambda: sigma
    obs = root + _SEG_CHAIN @ (uo * L[:, None])
    solution = root + _SEG_CHAIN @ (ud * L[:, None])
    f = SkeletonFrame(positions=obs, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8))
    out = so.output(f, solution, np.ones(NUM_JOINTS), 0.0, db_spread=db_spread,
                    db_distance=db_distance)
    d = SEG_DIFF @ out
    return d / np.linalg.norm(d, axis=1, keepdims=True), uo, ud


def _weight(u, uo, ud):
    """The observation's weight of each blended direction (u ~ normalised ud + b (uo - ud))."""
    # u is parallel to ud + b (uo - ud): solve for b by least squares on the cross product
    a, c = uo - ud, ud
    b = np.empty(len(u))
    for i in range(len(u)):
        # cross(u, c + b a) = 0  ->  b = -cross(u, c) . cross(u, a) / |cross(u, a)|^2
        x, y = np.cross(u[i], c[i]), np.cross(u[i], a[i])
        b[i] = -np.dot(x, y) / np.dot(y, y)
    return b


def test_the_observed_weight_is_the_minimum_error_blend_of_sensor_and_database():
    L = np.linspace(0.08, 0.45, NUM_SEGMENTS)
    sigma = 0.03
    u, uo, ud = _run(L, sigma)
    b = _weight(u, uo, ud)
    var_obs = 4 * sigma ** 2 / L ** 2            # two ends, two axes across the segment
    var_db = np.radians(12.0) ** 2
    assert np.allclose(b, var_db / (var_db + var_obs), atol=1e-6)
    # a shank (0.42 m) follows the sensor, a hip segment (0.1 m) the database
    assert b[L > 0.4].min() > 0.6 and b[L < 0.11].max() < 0.25
    # the user's larger offsets: less weight for the sensor everywhere
    b2 = _weight(*_run(L, 2 * sigma))
    assert (b2 < b - 0.05).all()


def test_off_is_the_fixed_observation_weight():
    L = np.linspace(0.08, 0.45, NUM_SEGMENTS)
    b = _weight(*_run(L, 0.03, direction_fusion=False, observation_weight=0.3))
    assert np.allclose(b, 0.3, atol=1e-6)


def test_neighbour_spread_is_the_mean_squared_angle_about_their_mean_direction():
    # K neighbours whose every segment is the same direction turned about a perpendicular axis by
    # +-theta (equal distances): the spread is 1 - cos^2 theta ~ theta^2
    rng = np.random.default_rng(3)
    L = np.linspace(0.1, 0.4, NUM_SEGMENTS)
    base = _unit(rng, NUM_SEGMENTS) * L[:, None]
    theta = np.radians(10.0)
    Y = []
    for sign in (1, -1, 1, -1):
        v = np.empty_like(base)
        for s in range(NUM_SEGMENTS):
            axis = np.cross(base[s], [0.0, 0.0, 1.0])
            axis /= np.linalg.norm(axis)
            k = np.cross(axis, base[s])        # Rodrigues about `axis` (perpendicular to base)
            v[s] = np.cos(theta) * base[s] + sign * np.sin(theta) * k
        Y.append(_SEG_CHAIN @ v)
    Y = np.array(Y)
    sp = neighbour_direction_spread(Y, np.ones(len(Y)))
    assert np.allclose(sp, np.sin(theta) ** 2, atol=1e-9)
    # the directions do not depend on the heading: turning every neighbour changes nothing
    turned = Y @ yaw_matrix(0.7).T
    assert np.allclose(neighbour_direction_spread(turned, np.ones(len(Y))), sp, atol=1e-12)
    # identical neighbours: no spread; a far neighbour (inverse-distance weight) counts little
    assert np.allclose(neighbour_direction_spread(np.repeat(Y[:1], 5, axis=0), np.ones(5)), 0.0,
                       atol=1e-12)
    near_far = neighbour_direction_spread(Y[:2], np.array([1.0, 100.0]))
    assert (near_far < 0.05 * sp).all()


def test_where_the_neighbours_disagree_the_sensor_weighs_more():
    # direction_db_spread: the database's error is the constant plus the neighbours' spread
    L = np.linspace(0.08, 0.45, NUM_SEGMENTS)
    sigma = 0.03
    spread = np.linspace(0.0, np.radians(25.0) ** 2, NUM_SEGMENTS)
    b = _weight(*_run(L, sigma, db_spread=spread))
    var_obs = 4 * sigma ** 2 / L ** 2
    var_db = np.radians(12.0) ** 2 + spread
    assert np.allclose(b, var_db / (var_db + var_obs), atol=1e-6)
    b0 = _weight(*_run(L, sigma))
    assert (b[1:] > b0[1:] + 1e-3).all() and abs(b[0] - b0[0]) < 1e-9


@pytest.mark.parametrize('on', [True, False])
def test_the_reconstructor_gives_the_output_its_neighbours_spread(on, monkeypatch):
    """Method C hands the segment output the spread of the K neighbours it solved with (the
    database's own rows, by the optimizer's indices and distances); off: none."""
    db = random_database(800, seed=5)
    r = Reconstructor(db, method='C', direction_db_spread=on)
    seen, dist = [], []
    orig = r.segment_output.output_rows   # the reconstructor's way into the output

    def spy(*a, **kw):
        seen.append(kw.get('db_spread'))
        dist.append(kw.get('db_distance'))
        return orig(*a, **kw)

    monkeypatch.setattr(r.segment_output, 'output_rows', spy)
    solve = r.core.solve
    results = []

    def spy_solve(*a, **kw):
        res = solve(*a, **kw)
        results.append(res)
        return res

    monkeypatch.setattr(r.core, 'solve', spy_solve)
    rest = standard_body().rest_positions() + np.array([2.5, 0.0, -0.8])
    out = r.process(SkeletonFrame(positions=rest,
                                  tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                                  user_id=1, stamp_ns=0))
    res = results[-1]
    # the nearest posture's RMS distance per reliable joint (every joint reliable here)
    wsum = float(np.asarray(out.reliability, float).sum())
    assert dist[0] > 0.0 and np.isclose(dist[0], np.sqrt(res.distances[0] / wsum), rtol=1e-5)
    if not on:
        assert seen == [None]
        return
    want = neighbour_direction_spread(db.flat[res.neighbours].reshape(-1, NUM_JOINTS, 3),
                                      res.distances)
    assert seen[0].shape == (NUM_SEGMENTS,) and np.allclose(seen[0], want)
    assert (seen[0] > 0).all()   # random postures: the neighbours disagree


def test_far_from_the_database_the_sensor_weighs_more():
    # direction_db_distance: the database's constant error scaled by (distance / reference)^2
    # where the nearest posture is farther than the reference, unchanged nearer
    L = np.linspace(0.08, 0.45, NUM_SEGMENTS)
    sigma = 0.03
    b0 = _weight(*_run(L, sigma))
    near = _weight(*_run(L, sigma, db_distance=0.05))
    assert np.allclose(near, b0, atol=1e-9)
    far = _weight(*_run(L, sigma, db_distance=0.18))
    var_obs = 4 * sigma ** 2 / L ** 2
    var_db = np.radians(12.0) ** 2 * (0.18 / 0.09) ** 2
    assert np.allclose(far, var_db / (var_db + var_obs), atol=1e-6)
    assert (far > b0 + 1e-3).all()
    off = _weight(*_run(L, sigma, db_distance=0.18, direction_db_distance=0.0))
    assert np.allclose(off, b0, atol=1e-9)


def test_the_observed_variance_kept_for_frozen_lengths_follows_a_new_sigma_or_lengths():
    """The observation's direction variance is kept between frames while the lengths are the
    frozen ones (the same array) and the offset scale is the same; another scale or other
    lengths give their own weight, as computed afresh."""
    so = SegmentOutput(None, np.full(NUM_SEGMENTS, 0.3), lambda: True, 0.5, 'user',
                       SegmentOutputConfig(smooth_min_cutoff=0.0))
    L = np.linspace(0.05, 0.45, NUM_SEGMENTS)
    sigma = [0.03]
    so.offset_sigma = lambda: sigma[0]

    def fresh(lengths, s):
        other = SegmentOutput(None, np.full(NUM_SEGMENTS, 0.3), lambda: True, 0.5, 'user',
                              SegmentOutputConfig(smooth_min_cutoff=0.0))
        other.offset_sigma = lambda: s
        return other._fused_weight(lengths)

    w0 = so._fused_weight(L)
    assert np.array_equal(so._fused_weight(L), w0)            # kept: the same numbers
    sigma[0] = 0.05
    w1 = so._fused_weight(L)
    assert np.array_equal(w1, fresh(L, 0.05)) and (w1 < w0).all()
    L2 = L * 1.5
    assert np.array_equal(so._fused_weight(L2), fresh(L2, 0.05))
