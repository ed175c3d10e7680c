"""Memory stays flat while users come and go (issue 32): the physics library churned with visitors
(every arrival and departure recompiles the MuJoCo world), judged as memory per user that came and
went after warm-up; and the slope estimator the soak and the diagnostics use."""
import gc
import weakref

import numpy as np

from skeleton_core.memory import open_files, rss_mb, slope
from skeleton_core.model import standard_body

from physics_sim import world as world_mod
from physics_sim.simulation import SimConfig, Simulation

BODY = standard_body()


def _target(k, rng):
    """User ``k``'s T-pose 3 m ahead, side by side 0.7 m apart, with a little noise."""
    p = BODY.rest_positions() - np.array([0.0, 0.0, 0.8]) + np.array([3.0, 0.7 * (k % 5) - 1.4, 0])
    return p + rng.normal(0.0, 0.01, p.shape)


def test_slope_is_theil_sen_after_warmup():
    t = np.arange(0.0, 100.0, 1.0)
    y = 200.0 + 0.5 * t
    assert abs(slope(t, y) - 0.5) < 1e-9
    # a warm-up ramp is ignored; load steps (a few outliers) barely move the median
    y2 = np.where(t < 20, 100.0 + 5.0 * t, 200.0 + 0.01 * t)
    y2[[50, 51, 70]] += 40.0
    assert abs(slope(t, y2, warmup=0.25) - 0.01) < 0.005
    assert np.isnan(slope([0.0, 1.0], [1.0, 2.0]))
    assert rss_mb() > 1.0 and open_files() > 0


def test_visitors_coming_and_going_keep_memory_flat():
    """A steady user and 3 visitors at a time, 70 visitors in all, each staying a few ticks (two
    world recompiles per visitor). Before the fix every recompile left the old world -- a MuJoCo
    model and data of several MB -- in a reference cycle that Python's collector only freed at a
    rare full collection: ~1.8 MB per visitor. Judged as MB per visitor after 15 warm-up
    visitors, with the collector left as it runs in a node (no gc.collect())."""
    rng = np.random.default_rng(3)
    sim = Simulation(SimConfig())
    created = []
    orig_init = world_mod.World.__init__

    def tracking_init(self, *a, **k):
        created.append(weakref.ref(self))
        orig_init(self, *a, **k)

    world_mod.World.__init__ = tracking_init
    try:
        gc.collect()
        sim.set_target(1, _target(0, rng))
        present = {}
        samples = []
        uid = 200
        for v in range(70):
            uid += 1
            present[uid] = 2 + v % 4           # ticks it stays
            while len(present) > 3:             # the one that leaves first
                gone = min(present, key=present.get)
                present.pop(gone)
                sim.remove_character(gone)
            for _ in range(2):
                for u in [1, *present]:
                    sim.set_target(u, _target(u, rng))
                sim.advance(1 / 30)
            for u in list(present):
                present[u] -= 1
                if present[u] <= 0:
                    present.pop(u)
                    sim.remove_character(u)
            samples.append((v, rss_mb()))
        per_visitor = slope([s[0] for s in samples], [s[1] for s in samples], warmup=15 / 70)
        alive = sum(r() is not None for r in created)
    finally:
        world_mod.World.__init__ = orig_init
    print(f'RSS {samples[15][1]:.1f} -> {samples[-1][1]:.1f} MB, {per_visitor:.3f} MB per visitor, '
          f'{sim.counters["rebuilds"]} rebuilds, {alive} worlds alive')
    assert sim.counters['rebuilds'] >= 100
    assert per_visitor < 0.2, f'{per_visitor:.2f} MB per visitor that came and went'
    # the worlds alive: the current ones and the cache (bounded), not one per recompile
    assert alive <= len(sim.worlds) + Simulation.CACHE_SIZE
