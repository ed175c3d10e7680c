"""pose_reconstruction.fused: what the one-node reconstruction computes per user (no rclpy)."""
import numpy as np
import pytest

from pose_reconstruction.fused import FusedProcessor, section
from pose_reconstruction.reconstructor import Reconstructor


@pytest.fixture(scope='module')
def case():
    from pose_reconstruction.synthetic import scenario
    return scenario(frames=40)


def _values(**over):
    v = {'optimizer.method': 'C', 'optimizer.k': 12, 'completion.pca_dims': 7,
         'reliability.f_total': 6}
    v.update(over)
    return v


def test_section_strips_one_prefix_only():
    v = {'optimizer.k': 3, 'optimizer.x.y': 1, 'completion.k': 4, 'k': 5}
    assert section(v, 'optimizer') == {'k': 3, 'x.y': 1}
    assert section(v, 'reliability') == {}


def test_fused_outputs_equal_the_split_methods(case):
    """Reconstructed = method C on the raw frame; the reliability output is the one C
    estimated; the completion (built only once wanted) = method A fed with that reliability."""
    from skeleton_core.conversions import SkeletonFrame
    db, truth, obs, ts = case
    fused = FusedProcessor(db, _values())
    c = Reconstructor(db, method='C', k=12, f_total=6, use_input_reliability=False)
    a = None
    for i in range(len(obs)):
        f = SkeletonFrame(positions=obs[i], tracking_state=ts[i], user_id=1,
                          stamp_ns=i * 33_333_333)
        want_comp = i >= 20
        out, rel, comp = fused.process(f, (True, i % 2 == 0, want_comp))
        ref = c.process(f)
        assert np.array_equal(out.positions, ref.positions)
        assert (rel is None) == (i % 2 == 1)
        if rel is not None:
            assert np.array_equal(rel.reliability, ref.reliability)
            assert np.array_equal(rel.positions, f.positions)  # raw positions, reliability filled
        if not want_comp:
            assert comp is None and fused.comp is None
            continue
        if a is None:
            a = Reconstructor(db, method='A', pca_dims=7, f_total=6, use_input_reliability=True)
        ref_a = a.process(f.copy(reliability=ref.reliability))
        assert np.array_equal(comp.positions, ref_a.positions)


def test_fused_refuses_what_the_library_refuses(case):
    with pytest.raises(ValueError):
        FusedProcessor(case[0], _values(**{'optimizer.method': 'Z'}))
