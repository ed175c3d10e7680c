"""Characters in separate MuJoCo worlds while they cannot touch each other, merged while they can;
controllers behind one interface (a test-defined controller through the registry alone)."""
import numpy as np
import pytest

from skeleton_core.model import standard_body

from physics_sim import controllers
from physics_sim.controllers.base import Controller
from physics_sim.simulation import SimConfig, Simulation

BODY = standard_body()


def tpose(y, x=2.5):
    return BODY.rest_positions() + np.array([x, y, -0.8])


def _wave(n):
    from skeleton_data.motions import builtin_clips
    clip = next(c for c in builtin_clips(0) if c.name == 'builtin_wave')
    return clip.positions[:n] + np.array([2.5, 0.0, -0.8])


def test_a_character_alone_in_its_world_moves_as_if_it_were_the_only_one():
    """Two characters 3 m apart: two worlds; each moves exactly (bit for bit) as it does alone,
    where the shared world couples them through the constraint solver."""
    seq = _wave(30)
    alone = Simulation(SimConfig(body_height=1.75))
    pair = Simulation(SimConfig(body_height=1.75, world_split='contact'))
    a = [alone.step({1: p + [0.0, -1.5, 0.0]})[1].positions for p in seq]
    b = [pair.step({1: p + [0.0, -1.5, 0.0], 2: p + [0.0, 1.5, 0.0]})[1].positions for p in seq]
    assert len(pair.worlds) == 2 and pair.world_of(1) is not pair.world_of(2)
    assert pair.counters['regroups'] == 0
    np.testing.assert_array_equal(np.array(a), np.array(b))


def test_characters_share_a_world_while_they_can_touch():
    """Walking towards each other, two characters are merged into one world (and collide there),
    keep their motion across the recompile, and part when they move apart again."""
    sim = Simulation(SimConfig(body_height=1.75, world_split='contact', contact_margin=0.2))
    for _ in range(10):
        sim.step({1: tpose(-2.0), 2: tpose(2.0)})
    assert len(sim.worlds) == 2
    before = sim.states()
    sim.step({1: tpose(-1.9), 2: tpose(1.9)})
    for y in np.linspace(1.9, 0.9, 10):   # T-poses 1.8 m apart: the hands (+-0.9 m) meet
        st = sim.step({1: tpose(-y), 2: tpose(y)})
    assert len(sim.worlds) == 1 and sim.counters['regroups'] >= 1
    assert sim.world.model.nbody > 2 * 19        # both characters in one model
    assert np.abs(st[1].positions - before[1].positions).max() < 1.2   # no jump on regrouping
    for _ in range(15):   # apart for half a second: still together (PART_AFTER)
        st = sim.step({1: tpose(-2.5), 2: tpose(2.5)})
    assert len(sim.worlds) == 1
    for _ in range(25):
        st = sim.step({1: tpose(-2.5), 2: tpose(2.5)})
    assert len(sim.worlds) == 2
    rebuilds = sim.counters['rebuilds']
    for y in np.linspace(2.5, 0.9, 10):   # meeting again: the pair's compiled model is reused
        sim.step({1: tpose(-y), 2: tpose(y)})
    assert len(sim.worlds) == 1
    assert sim.counters['rebuilds'] == rebuilds and sim.counters['reused_models'] >= 1
    for s in st.values():
        assert np.linalg.norm(s.positions - s.target_world, axis=1).mean() < 0.05
    assert sim.counters['nan_reset'] == 0


def test_shared_world_and_objects_keep_one_model():
    sim = Simulation(SimConfig(body_height=1.75, world_split='shared'))
    sim.step({1: tpose(-3.0), 2: tpose(3.0)})
    assert len(sim.worlds) == 1
    assert SimConfig().world_split == 'shared'   # the default
    sim = Simulation(SimConfig(body_height=1.75, world_split='contact'))
    sim.step({1: tpose(-3.0), 2: tpose(3.0)})
    assert len(sim.worlds) == 2
    sim.throw_ball((2.5, 0.0, 1.0), (0.0, 0.0, 0.0))
    assert len(sim.worlds) == 1 and len(sim.states()) == 2
    sim.remove_object('thrown1')
    for _ in range(40):   # split again after PART_AFTER
        sim.step({1: tpose(-3.0), 2: tpose(3.0)})
    assert len(sim.worlds) == 2
    with pytest.raises(ValueError):
        SimConfig(world_split='nowhere').validate()


class _Hold(Controller):
    """A controller defined outside the package: no forces at all, the characters fall."""

    name = 'test_limp'
    bound = 0

    def bind(self, world):
        type(self).bound += 1

    def advance(self, world, nsteps):
        import mujoco
        world.data.xfrc_applied[:] = 0.0
        world.apply_pushes(world.time)
        mujoco.mj_step(world.model, world.data, nstep=nsteps)
        world.time = float(world.data.time)


def test_a_controller_added_through_the_registry_alone():
    controllers.register(_Hold)
    try:
        sim = Simulation(SimConfig(controller='test_limp', body_height=1.75))
        for _ in range(30):
            st = sim.step({1: tpose(0.0)})
        assert _Hold.bound >= 1 and sim.controller == 'test_limp'
        assert st[1].positions[3, 2] < 1.0          # the head fell: nothing drives the body
        assert sim.counters['nan_reset'] == 0
    finally:
        controllers.unregister('test_limp')
    with pytest.raises(ValueError):
        Simulation(SimConfig(controller='test_limp'))
    with pytest.raises(ValueError):
        controllers.register(type('Auto', (Controller,), {'name': 'auto'}))
