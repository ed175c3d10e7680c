"""Memory stays flat while users come and go: the physics library churned with visitors
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


def test_soak_judges_slopes_not_percentages():
    """The soak's verdict per node: a steady 0.1 MB/s after warm-up fails even where it is only a
    few per cent of the process; a flat RSS that follows the load (visitors in the physics world)
    passes; open files and log volume that grow fail too."""
    from kinect_experiments.soak import MAX_RSS_SLOPE, judge_process
    t = np.arange(0.0, 600.0, 2.0)
    load = 20.0 * ((t // 40) % 2)                       # a visitor in, out, in, ...

    def rows(rss, fds=None, log=None):
        fds = np.full(t.size, 18) if fds is None else fds
        log = 100.0 * t if log is None else log        # 6 kB/min
        return [(a, b, 7, int(c), 0.2 * a, int(d)) for a, b, c, d in zip(t, rss, fds, log)]

    leak = judge_process(rows(3000.0 + 0.1 * t), 120)
    assert leak['judged'] and not leak['flat'] and leak['growth_percent'] < 2.0
    assert abs(leak['rss_slope_mb_per_s'] - 0.1) < 1e-3
    flat = judge_process(rows(250.0 + load + np.where(t < 60, t, 60.0)), 120)
    assert flat['flat'] and abs(flat['rss_slope_mb_per_s']) < MAX_RSS_SLOPE / 5
    assert not judge_process(rows(250.0 + 0 * t, fds=18 + t // 60), 120)['flat']
    assert not judge_process(rows(250.0 + 0 * t, log=2000.0 * t), 120)['flat']
    # a process too short to tell warm-up from a leak is reported, not judged
    assert not judge_process(rows(3000.0 + 0.1 * t)[:40], 120)['judged']


def test_lab_day_people_come_and_go():
    """The lab-day profile: people every 10-60 s, 0-5 besides the driver's user, each a new id,
    occluded limbs now and then, the sensor unplugged every 7-13 minutes."""
    import random
    from kinect_experiments.soak import LabDay
    from skeleton_core.cdr import frames_from_cdr  # noqa: F401 (the message package is built)
    lab = LabDay(random.Random(1))
    counts, ids, states, unplugs = [], set(), set(), []
    for i in range(0, 30 * 60 * 15, 3):             # 15 minutes, every third frame
        t = i / 30.0
        if lab.unplug_due(t):
            unplugs.append(t)
        msg = lab.frame(t, 10 ** 18 + i * 33_333_333)
        n = 0 if msg is None else len(msg.skeletons)
        counts.append(n)
        if msg is not None and i % 9 == 0:
            for sk in msg.skeletons:
                ids.add(sk.user_id)
                states |= set(sk.tracking_state)
    s = lab.summary()
    changes = s['arrivals'] + s['departures']
    assert 15 <= changes <= 90 and max(counts) <= 5 and s['most_people'] >= 3
    assert len(ids) == s['arrivals']                     # every visit a new user id
    assert states == {0, 1, 2} and s['occlusions'] > 5
    assert 1 <= len(unplugs) <= 3 and unplugs[0] >= 420
