"""kinect_experiments.fusion_cost: the fusion node's decode -> fuse -> encode replayed on the bench's
two-sensor frames, its CPU per stage and a digest of the fused bytes that stays the same for the
same frames (the one-pass decode of a message's skeletons against the one-by-one one)."""
import pytest

pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built (run scripts/setup.sh)')

from kinect_experiments import fusion_cost  # noqa: E402


@pytest.fixture(scope='module')
def frames():
    return fusion_cost.load_streams(users=2, sensors=2, seconds=4.0)


def test_every_capture_is_fused_once_and_the_same_frames_give_the_same_bytes(frames):
    a = fusion_cost.replay(frames, 90, warm=10)
    b = fusion_cost.replay(frames, 90, warm=10)
    assert a['published'] == 90 and a['measured'] == 80
    assert a['forced'] == 0            # sensor 2 3 ms late: waited for, every frame
    assert a['digest'] == b['digest']
    assert set(a['cpu_ms_per_frame']) == set(fusion_cost.STAGES)
    assert all(v > 0 for v in a['cpu_ms_per_frame'].values())


def test_the_fused_bytes_do_not_depend_on_how_the_skeletons_are_checked(frames, monkeypatch):
    import skeleton_core.cdr as cdr
    together = fusion_cost.replay(frames, 60, warm=10)['digest']
    monkeypatch.setattr(cdr, '_checked_together', lambda parsed: None)
    assert fusion_cost.replay(frames, 60, warm=10)['digest'] == together


def test_one_sensor_is_refused():
    with pytest.raises(ValueError, match='two or more sensors'):
        fusion_cost.replay({'streams': [{'topic': '/kinect/skeletons', 'messages': []}],
                            'rate_hz': 30.0}, 60)


def test_a_sensor_half_a_frame_late_is_not_waited_for(frames):
    """Sensor 2 16.7 ms after sensor 1, beyond the 5 ms wait: its frames are held, the fused
    frames leave on sensor 1's (counted as published without the late sensor)."""
    r = fusion_cost.replay(frames, 90, phase_ms=16.7, warm=10)
    assert r['published'] == 90 and r['forced'] >= 80
