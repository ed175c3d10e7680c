"""kinect_experiments.reconstruction_cost: the reconstruction node's per-message work on the fused
two-sensor stream beside sensor 1's own, in lockstep: CPU per stage and digests of the outputs
that stay the same for the same frames."""
import pytest

pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

from kinect_experiments import fusion_cost, reconstruction_cost  # noqa: E402


@pytest.fixture(scope='module')
def inputs():
    data = fusion_cost.load_streams(users=2, sensors=2, seconds=3.0)
    return reconstruction_cost.input_messages(data, 60)


@pytest.fixture(scope='module')
def db():
    from pose_reconstruction.posture_space import as_database_arrays
    from pose_reconstruction.synthetic import scenario
    return as_database_arrays(scenario(frames=30, n_random=500)[0])


def test_both_streams_are_reconstructed_and_the_same_frames_give_the_same_bytes(inputs, db):
    from skeleton_core.cdr import frames_from_cdr
    assert set(inputs) == set(reconstruction_cost.INPUTS)
    assert len(inputs['fused']) == len(inputs['one sensor']) == 60
    _, fid_one, one = frames_from_cdr(inputs['one sensor'][0], [])
    _, fid_fused, fused = frames_from_cdr(inputs['fused'][0], [])
    assert fid_fused == 'world' and fid_one != 'world'
    assert len(one) == len(fused) == 2          # the same two people, fused
    a = reconstruction_cost.run(inputs, db, warm=10)
    b = reconstruction_cost.run(inputs, db, warm=10)
    for name in reconstruction_cost.INPUTS:
        assert a[name]['messages'] == 60
        assert a[name]['digest'] == b[name]['digest']
        assert set(a[name]['cpu_ms_per_frame']) == set(reconstruction_cost.STAGES)
        assert a[name]['cpu_ms_per_frame']['reconstruct'] > 0
        assert a[name]['p95_ms'] >= a[name]['total_ms_per_frame'] * 0.5
    assert a['fused']['digest'] != a['one sensor']['digest']
