"""The physics node's per-frame shortcuts give the same numbers as the general code they skip:
explicit_pd's one-share-for-all and contiguous-rows paths (World.share_at, a slice of
xfrc_applied) against the per-character arrays and index lists, and the published frames checked
all at once (physics_sim.output) against validate_arrays frame by frame -- bit for bit."""
import numpy as np
import pytest
from skeleton_core.cdr import frames_to_cdr
from skeleton_core.conversions import SkeletonFormatError, SkeletonFrame
from skeleton_core.model import NUM_JOINTS, TRACKED, standard_body
from skeleton_core.tf import Transform

from physics_sim.controllers.explicit_pd import ExplicitPD
from physics_sim.output import output_frames
from physics_sim.simulation import SimConfig, Simulation
from physics_sim.world import World


def _run(users: int, frames: int, sensor=None):
    """States of ``users`` swaying characters after each of ``frames`` frames (explicit_pd)."""
    body = standard_body()
    rest = body.rest_positions() - np.array([0.0, 0.0, 0.8])
    sim = Simulation(SimConfig(controller='explicit_pd'), sensor_pose=sensor)
    out = []
    for k in range(frames):
        for u in range(users):
            p = rest + np.array([0.0, 1.2 * u - 1.2, 0.0])
            p = p + 0.05 * np.sin(0.3 * k + u + np.arange(NUM_JOINTS)[:, None] * 0.3)
            p[[7, 11], 2] += 0.2 * np.sin(0.2 * k + u)
            sim.set_target(u + 1, p, None, k * 33_333_333)
        sim.advance(1 / 30)
        out.append(sim.states())
    return sim, out


def _same_states(a, b):
    for sa, sb in zip(a, b):
        assert sorted(sa) == sorted(sb)
        for uid in sa:
            assert sa[uid].positions.tobytes() == sb[uid].positions.tobytes()
            assert sa[uid].orientations.tobytes() == sb[uid].orientations.tobytes()


def test_one_share_and_slice_paths_match_the_general_ones(monkeypatch):
    _, fast = _run(3, 12)
    # the general paths: a share per character (an array), the segment rows as an index list
    monkeypatch.setattr(World, 'share_at', lambda self, t: self.frame_shares((t,))[0])
    bind = ExplicitPD.bind

    def bind_indexed(self, world):
        bind(self, world)
        self._sb = None

    monkeypatch.setattr(ExplicitPD, 'bind', bind_indexed)
    _, general = _run(3, 12)
    _same_states(fast, general)


def test_share_at_is_frame_shares():
    sim, _ = _run(2, 3)
    w = sim.worlds[0]
    u = w.tg['uniform']
    assert u is not None
    for t in (u[0] - 0.01, u[0], u[0] + 0.3 * u[1], u[0] + u[1], u[0] + 2 * u[1]):
        s = w.share_at(t)
        assert isinstance(s, float)
        assert np.array_equal(np.full(2, s), w.frame_shares((t,))[0])
    w.tg['uniform'] = None   # characters on different frame times: one share each
    assert np.array_equal(w.share_at(u[0] + 0.5 * u[1]), w.frame_shares((u[0] + 0.5 * u[1],))[0])


def _old_frames(states, lift):
    """The frames as the node built them before (validated one by one in frames_to_cdr)."""
    return [SkeletonFrame(positions=st.positions - lift,
                          tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                          reliability=np.ones(NUM_JOINTS, np.float32),
                          orientations=st.orientations, user_id=uid, stamp_ns=st.stamp_ns,
                          frame_id='world') for uid, st in states.items()]


def test_output_frames_write_the_same_bytes():
    tilted = Transform.from_xyz_ypr(0.3, -0.2, 1.1, 20.0, 15.0, 0.0)
    _, runs = _run(3, 4, sensor=tilted)
    lift = np.array([0.0, 0.0, 0.057])
    for states in runs:
        frames, latest, validated = output_frames(states, lift, 'world')
        assert validated and latest == max(st.stamp_ns for st in states.values())
        assert [f.user_id for f in frames] == list(states)
        assert (frames_to_cdr(frames, latest, 'world', validated=True)
                == frames_to_cdr(_old_frames(states, lift), latest, 'world'))
    assert output_frames({}, lift, 'world') == ([], 0, True)


def test_output_frames_of_a_bad_state_leave_the_error_to_the_frame_check():
    _, runs = _run(2, 1)
    states = runs[-1]
    uid = next(iter(states))
    states[uid].positions[3] = np.nan
    frames, latest, validated = output_frames(states, np.zeros(3), 'world')
    assert not validated
    with pytest.raises(SkeletonFormatError, match='non-finite position'):
        frames_to_cdr(frames, latest, 'world', validated=validated)
    # a zero quaternion (identity, as validate_arrays reads it) takes the frame-by-frame path too
    _, runs = _run(2, 1)
    states = runs[-1]
    states[uid].orientations[0] = 0.0
    frames, latest, validated = output_frames(states, np.zeros(3), 'world')
    assert not validated
    assert (frames_to_cdr(frames, latest, 'world', validated=validated)
            == frames_to_cdr(_old_frames(states, np.zeros(3)), latest, 'world'))


def test_step_cost_prints_the_cost_and_a_digest_of_the_same_outputs(capsys):
    from physics_sim import step_cost
    assert step_cost.main(['--users', '2', '--frames', '2']) == 0
    assert step_cost.main(['--users', '2', '--frames', '2']) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 2 and 'ms per frame' in lines[0] and 'medians: input' in lines[0]
    assert lines[0].split('digest ')[1] == lines[1].split('digest ')[1]   # deterministic
    assert step_cost.main(['--users', '7']) == 2
    assert step_cost.main(['--solver', 'dantzig']) == 2
    assert step_cost.main(['--spacing', '0.1']) == 2
    capsys.readouterr()
    # touching neighbours with either solver: other contacts, other numbers
    assert step_cost.main(['--users', '2', '--frames', '2', '--spacing', '0.8']) == 0
    assert step_cost.main(['--users', '2', '--frames', '2', '--spacing', '0.8',
                           '--solver', 'pgs']) == 0
    near, pgs = capsys.readouterr().out.strip().splitlines()
    assert '0.8 m apart' in near and 'solver pgs' in pgs
    assert near.split('digest ')[1] != pgs.split('digest ')[1]
