"""Simulation.set_targets (a decoded message's users at once, the physics node's input path) gives
every character exactly the targets set_target gives it one user at a time."""
import numpy as np
import pytest

from skeleton_core.model import NUM_JOINTS, standard_body
from skeleton_core.tf import Transform

from physics_sim.posture import segment_quats_from_positions, segment_quats_to_joints
from physics_sim.simulation import SimConfig, Simulation


def _message(k: int, users: int, rng) -> list:
    """(user_id, positions, orientations, stamp) of ``users`` users (sensor frame) at frame ``k``:
    user 1 without orientations, user 2 with identities, the others with noisy unit ones."""
    body = standard_body()
    out = []
    for u in range(users):
        pos = (body.rest_positions() + np.array([2.5, 0.8 * (u - 2.5), -0.8])
               + 0.05 * np.sin(0.2 * k + u + np.arange(NUM_JOINTS)[:, None])
               + rng.normal(0.0, 0.01, (NUM_JOINTS, 3)))
        if u == 0:
            q = None
        elif u == 1:
            q = np.tile([0.0, 0.0, 0.0, 1.0], (NUM_JOINTS, 1))
        else:
            q = segment_quats_to_joints(segment_quats_from_positions(pos, body.rest_offsets))
            q = q + rng.normal(0.0, 0.02, q.shape)
            q /= np.linalg.norm(q, axis=1)[:, None]
        out.append((u + 1, pos, q, k * 33_333_333))
    return out


def _same_targets(a: Simulation, b: Simulation) -> None:
    assert sorted(a.characters) == sorted(b.characters)
    for uid, ca in a.characters.items():
        cb = b.characters[uid]
        for x, y in ((ca.cur.positions, cb.cur.positions), (ca.cur.seg_quats, cb.cur.seg_quats),
                     (ca.prev.positions, cb.prev.positions), (ca.velocity, cb.velocity),
                     (ca.prev.seg_quats, cb.prev.seg_quats)):
            assert np.array_equal(x, y), uid
        assert ca.cur.stamp_ns == cb.cur.stamp_ns and ca.period == cb.period


@pytest.mark.parametrize('pitch', [0.0, 0.35])
def test_set_targets_is_set_target_bit_for_bit(pitch):
    """Level and tilted sensor; users with, without and with identity orientations; a user
    arriving in a later message; the states after steps agree too."""
    pose = Transform.from_xyz_ypr(0.0, 0.0, 0.8, 0.0, pitch, 0.0, degrees=False)
    one = Simulation(SimConfig(), sensor_pose=pose)
    batch = Simulation(SimConfig(), sensor_pose=pose)
    rng = np.random.default_rng(4)
    for k in range(12):
        msg = _message(k, 4 if k < 6 else 5, rng)   # user 5 arrives at frame 6
        for uid, p, q, stamp in msg:
            one.set_target(uid, p, q, stamp)
        assert batch.set_targets(msg) == []
        _same_targets(one, batch)
        one.advance(1 / 30)
        batch.advance(1 / 30)
    sa, sb = one.states(), batch.states()
    assert len(sa) == 5
    for uid in sa:
        assert np.array_equal(sa[uid].positions, sb[uid].positions)
        assert np.array_equal(sa[uid].orientations, sb[uid].orientations)


def test_set_targets_refuses_like_set_target():
    """A NaN skeleton or one user too many is refused with set_target's error; the other users'
    targets are taken."""
    sim = Simulation(SimConfig(max_characters=2))
    rng = np.random.default_rng(5)
    assert sim.set_targets(_message(0, 2, rng)) == []
    msg = _message(1, 2, rng)
    bad = msg[1][1].copy()
    bad[3] = np.nan
    before = sim.characters[2].cur.positions.copy()
    refused = sim.set_targets([msg[0], (2, bad, None, msg[1][3])])
    assert [u for u, _ in refused] == [2] and 'non-finite' in str(refused[0][1])
    assert np.array_equal(sim.characters[2].cur.positions, before)
    assert sim.characters[1].cur.stamp_ns == msg[0][3]
    refused = sim.set_targets(_message(2, 3, rng))
    assert [u for u, _ in refused] == [3] and 'max_characters' in str(refused[0][1])
    assert sorted(sim.characters) == [1, 2]
