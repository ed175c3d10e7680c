"""Constraint islands are disabled in every world (mjcf_world): the characters move as they do with
MuJoCo's islands -- bit for bit while all touching characters form one island, to rounding when
several islands are solved as one problem."""
import copy

import mujoco
import numpy as np

from skeleton_core.model import NUM_JOINTS, standard_body

from physics_sim.simulation import SimConfig, Simulation

ISLAND = int(mujoco.mjtDisableBit.mjDSBL_ISLAND)
REST = standard_body().rest_positions() - np.array([0.0, 0.0, 0.8])
SWAY = np.arange(NUM_JOINTS)[:, None] * 0.3


def _frame(sim, k, users, spacing):
    """The step_cost scene: T-posed characters side by side, swaying, hands up and down."""
    for u in range(users):
        pos = REST + np.array([0.0, spacing * (u - (users - 1) / 2), 0.0])
        pos = pos + 0.05 * np.sin(0.2 * k + u + SWAY)
        pos[[7, 11], 2] += 0.2 * np.sin(0.1 * k + u)
        sim.set_target(u + 1, pos, None, k * 33_333_333)
    sim.advance(1 / 30)
    st = sim.states()
    return np.array([st[u].positions for u in sorted(st)])


def test_six_touching_characters_move_as_with_islands():
    """Six characters 0.8 m apart (arms overlapping: one island): 60 frames with MuJoCo's islands
    switched back on give the same joint positions."""
    new, old = Simulation(SimConfig()), Simulation(SimConfig())
    _frame(new, 0, 6, 0.8)
    _frame(old, 0, 6, 0.8)
    assert new.model.opt.disableflags & ISLAND and len(new.worlds) == 1
    old.model.opt.disableflags &= ~ISLAND
    rebuilds = old.counters['rebuilds']
    diff = max(np.abs(_frame(new, k, 6, 0.8) - _frame(old, k, 6, 0.8)).max()
               for k in range(1, 60))
    assert old.counters['rebuilds'] == rebuilds   # the flag stayed on the model compared
    assert diff < 1e-6


def test_several_islands_solved_as_one_problem_agree_to_rounding():
    """Three characters 1.2 m apart (touching now and then: two or three islands): one frame from
    the same state, with and without islands, ends within a micrometre -- the same Newton solve,
    stopped when the worst island has converged instead of per island."""
    sim = Simulation(SimConfig())
    worst, several = 0.0, 0
    for k in range(60):
        _frame(sim, k, 3, 1.2)
        if k >= 10 and k % 5 == 0:
            m, d = sim.model, sim.data
            m_old = copy.deepcopy(m)
            m_old.opt.disableflags &= ~ISLAND
            a, b = copy.copy(d), copy.copy(d)
            for _ in range(17):
                mujoco.mj_step(m, a)
                mujoco.mj_step(m_old, b)
            several += b.nisland > 1
            worst = max(worst, np.abs(a.xpos - b.xpos).max())
    assert several > 0   # the comparison covered states with several islands
    assert worst < 1e-6
