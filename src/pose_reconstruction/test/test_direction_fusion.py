"""direction_fusion of the segment output (issue 34): a reliable segment's observed direction
weighted by the expected errors of the sensor (joint-centre offsets across the segment) and of the
database, so that a long segment the sensor sees follows it and a short one takes the database's."""
import numpy as np

from pose_reconstruction.segment_output import (_SEG_CHAIN, SEG_DIFF, SegmentOutput,
                                                SegmentOutputConfig)
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS, NUM_SEGMENTS, TRACKED


def _unit(rng, n):
    u = rng.normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _run(L, sigma, **kw):
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
    out = so.output(f, solution, np.ones(NUM_JOINTS), 0.0)
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
