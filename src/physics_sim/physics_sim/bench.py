"""``bench_physics``: figures of the physics character (no ROS).

    ros2 run physics_sim bench_physics [--quick] [--long] [--solver pgs] [--out out/bench_physics.json]

Prints, for every controller (``actuator_pd`` = Eq. 1-2 as MuJoCo actuators, the default, with
explicit Euler integration as the paper and with implicitfast (``actuator_pd_implicit``);
``explicit_pd`` = the papers' external PD forces computed in Python at every step;
``mocap_constraints`` = soft connect constraints to mocap targets):

* real-time factor with 1, 2 and 6 characters at the 2 ms step, by wall clock (depends on the machine's
  load: quote it) and by this process's CPU time (what an idle core would give), as simulated
  seconds (whole 2 ms steps: 34 ms per 1/30 s frame) per second; all runs are stepped
  interleaved in chunks of 10 frames and each figure is the median over its chunks,
* steady-state tracking error on a static T-pose and on the built-in motion clips
  (``skeleton_data.motions.builtin_clips``, 30 fps), segment length preservation, pinned foot drift,
* output jitter against the raw input with Kinect-like noise (mean joint acceleration, m/s^2, as
  ``skeleton_eval.metrics.jitter``),
* the stability limits (largest stable Ke at 2 ms with the damping ratio kept, largest stable Kd)
  of explicit_pd and of actuator_pd with either integrator, and the constraint option's stiffest
  setting,
* a push (300 N for 0.1 s on the chest): peak joint displacement and recovery time,
* a long noisy run with outliers and pushes (60 s; ``--long``: 10 min) counting NaN resets.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Dict

import numpy as np
from skeleton_core.model import NUM_JOINTS, segment_lengths, standard_body
from skeleton_eval import metrics

from .controller import Gains
from .simulation import SimConfig, Simulation
from .controllers import explicit_pd as mod

SENSOR_SHIFT = np.array([2.5, 0.0, -0.8])  # world -> sensor frame: person 2.5 m ahead, sensor 0.8 m up
# (name, controller, integrator): every controller, actuator_pd (the default: Euler, explicit as the
# paper) also with the implicit integration of its damping
VARIANTS = (('actuator_pd', 'actuator_pd', 'euler'),
            ('actuator_pd_implicit', 'actuator_pd', 'implicitfast'),
            ('explicit_pd', 'explicit_pd', 'implicitfast'),
            ('mocap_constraints', 'mocap_constraints', 'implicitfast'))


def clips(quick: bool):
    try:
        from skeleton_data.motions import builtin_clips
        cs = builtin_clips(0)
        names = ('builtin_walk', 'builtin_punch', 'builtin_squat_lift', 'builtin_wave',
                 'builtin_kick', 'builtin_sword_swing')
        cs = [c for c in cs if c.name in names] or cs
        out = [(c.name, c.positions + SENSOR_SHIFT, c.orientations) for c in cs]
    except ImportError:
        out = [('synthetic_wave', synthetic(180), None)]
    return out[:2] if quick else out


def synthetic(n: int) -> np.ndarray:
    """Fallback clip: the standard T-pose with waving forearms, sensor frame."""
    base = standard_body().rest_positions() + SENSOR_SHIFT
    seq = np.repeat(base[None], n, axis=0)
    t = np.arange(n) / 30.0
    seq[:, [6, 7, 10, 11], 2] += 0.15 * np.sin(2 * np.pi * 0.5 * t)[:, None]
    return seq


# real-time factor only: the alternatives side by side with the defaults. *_split = characters that
# cannot touch each other in separate MuJoCo models (world_split contact; the default is one model);
# explicit_pd_numpy = explicit_pd with the numpy formulation of its per-step Eq. 1 instead of the
# numba kernel; auto = the node's default (controller auto, Euler)
RTF_VARIANTS = {'actuator_pd_split': ('actuator_pd', dict(world_split='contact')),
                'actuator_pd_implicit_split': ('actuator_pd', dict(integrator='implicitfast',
                                                                   world_split='contact')),
                'explicit_pd_split': ('explicit_pd', dict(world_split='contact')),
                'explicit_pd_numpy': ('explicit_pd', {}),
                'auto': ('auto', dict(integrator='euler')),
                'auto_split': ('auto', dict(integrator='euler', world_split='contact'))}
# SimConfig.solver of every run (--solver; auto = the node's default, newton)
SOLVER = 'auto'


def config(variant: str, **kw) -> SimConfig:
    """The SimConfig of a VARIANTS or RTF_VARIANTS name (or a plain controller name)."""
    if variant in RTF_VARIANTS:
        variant, extra = RTF_VARIANTS[variant]
        kw = {**extra, **kw}
    ctrl, integ = next(((c, i) for n, c, i in VARIANTS if n == variant), (variant, 'implicitfast'))
    kw.setdefault('integrator', integ)
    kw.setdefault('solver', SOLVER)
    return SimConfig(controller=ctrl, body_height=1.75, **kw)


class _numpy_kernel:
    """Within: explicit_pd steps with the numpy twin of its compiled Eq. 1 kernel."""

    def __init__(self, on: bool):
        self.on = on

    def __enter__(self):
        self.saved = mod.explicit_pd_wrenches
        if self.on:
            from .controller import _explicit_pd_numpy
            mod.explicit_pd_wrenches = _explicit_pd_numpy

    def __exit__(self, *exc):
        mod.explicit_pd_wrenches = self.saved


def run_clip(controller: str, seq: np.ndarray, ori=None, noise: float = 0.0, seed: int = 0,
             cfg: SimConfig = None) -> Dict:
    rng = np.random.default_rng(seed)
    sim = Simulation(cfg or config(controller))
    out_s, out_w, tgt, raw, drift = [], [], [], [], []
    for i in range(len(seq)):
        p = seq[i] + (rng.normal(0.0, noise, seq[i].shape) if noise > 0 else 0.0)
        raw.append(p)
        st = sim.step({0: (p, None if ori is None else ori[i])})[0]
        out_s.append(st.positions_sensor)
        out_w.append(st.positions)
        tgt.append(st.target_world)
        for j, pin in sim.characters[0].pins.items():
            if pin.active:  # distance of the pinned foot from its pin point
                drift.append(float(np.linalg.norm(st.positions[j] - pin.point)))
    return dict(sensor=np.array(out_s), world=np.array(out_w), target=np.array(tgt),
                raw=np.array(raw), drift=np.array(drift) if drift else np.zeros(1),
                counters=dict(sim.counters))


def jitter(seq: np.ndarray) -> float:
    """Mean joint acceleration magnitude (m/s^2) of a 30 fps sequence (skeleton_eval.metrics)."""
    return metrics.jitter(seq, fps=30.0)[1]


def tracking(quick: bool) -> Dict:
    res = {}
    body = standard_body()
    for ctrl, _, _ in VARIANTS:
        r = {}
        static = run_clip(ctrl, np.repeat((body.rest_positions() + SENSOR_SHIFT)[None], 45, 0))
        e = np.linalg.norm(static['world'] - static['target'], axis=-1)[30:]
        r['static_tpose_err_mean_cm'] = 100 * float(e.mean())
        r['static_tpose_err_max_cm'] = 100 * float(e.max())
        errs, lens, drift = [], [], []
        per_clip = {}
        for name, seq, ori in clips(quick):
            rr = run_clip(ctrl, seq, ori)
            e = np.linalg.norm(rr['world'] - rr['target'], axis=-1)[30:]
            errs.append(e)
            per_clip[name] = round(100 * float(e.mean()), 2)
            lens.append(np.abs(segment_lengths(rr['world']) - body.segment_lengths).max())
            drift.append(rr['drift'].max())
        e = np.concatenate([x.ravel() for x in errs])
        r['clip_err_mean_cm'] = 100 * float(e.mean())
        r['clip_err_p95_cm'] = 100 * float(np.percentile(e, 95))
        r['clip_err_by_clip_cm'] = per_clip
        r['segment_length_err_max_mm'] = 1000 * float(max(lens))
        r['pinned_foot_drift_max_cm'] = 100 * float(max(drift))
        # jitter on a noisy version of the first clip (Kinect-like 1.5 cm i.i.d. noise)
        name, seq, ori = clips(quick)[0]
        rr = run_clip(ctrl, seq, ori, noise=0.015, seed=1)
        jr, jo = jitter(rr['raw'][30:]), jitter(rr['sensor'][30:])
        r['jitter_raw_m_s2'] = jr
        r['jitter_out_m_s2'] = jo
        r['jitter_reduction_pct'] = 100 * (1 - jo / jr)
        res[ctrl] = r
    return res


def stable_run(cfg: SimConfig, seconds: float = 1.5) -> bool:
    body = standard_body()
    tp = body.rest_positions() + SENSOR_SHIFT
    sim = Simulation(cfg)
    try:
        for i in range(int(seconds * 30)):
            if i == 6:
                sim.apply_push(0, 'ShoulderCenter', (300.0, 0.0, 0.0), 0.1)
            st = sim.step({0: tp})[0]
            v = sim.world_of(0).data.qvel[sim.characters[0].dofs[:3]]
            if sim.counters['nan_reset'] or not np.all(np.isfinite(st.positions)) \
                    or np.linalg.norm(v) > 20.0:
                return False
    except Exception:  # noqa: BLE001 -- a blown-up simulation is the measurement
        return False
    e = np.linalg.norm(st.positions - st.target_world, axis=-1)
    return bool(e.mean() < 0.1)


def gain_sweeps(variant: str, quick: bool) -> Dict:
    """Largest stable Ke (damping ratio kept) and Kd (Ke default) of a PD variant at 2 ms."""
    g0 = Gains()
    kes = [4e3, 1e4, 2e4, 4e4, 7e4, 1e5, 3e5, 1e6] if not quick else [4e3, 2e4, 1e5, 1e6]
    rows = []
    limit = None
    for ke in kes:
        kd = g0.kd * np.sqrt(ke / g0.ke)
        g = replace(g0, ke=ke, kd=kd, max_force=1e9)
        ok = stable_run(config(variant, gains=g))
        rows.append(dict(ke=ke, kd=round(kd, 1), stable=ok))
        if ok:
            limit = ke
        else:
            break
    kd_rows = []
    kd_limit = None
    for kd in ([100, 200, 300, 400, 600, 1200, 5000] if not quick else [100, 300, 600, 5000]):
        ok = stable_run(config(variant, gains=replace(g0, kd=float(kd), max_force=1e9)))
        kd_rows.append(dict(ke=g0.ke, kd=kd, stable=ok))
        if ok:
            kd_limit = kd
        else:
            break
    return dict(ke_sweep=rows, max_stable_ke=limit, kd_sweep=kd_rows, max_stable_kd=kd_limit)


def stability(quick: bool) -> Dict:
    out = {v: gain_sweeps(v, quick) for v in ('explicit_pd', 'actuator_pd', 'actuator_pd_implicit')}
    mc = []
    for tc in ([0.1, 0.03, 0.01, 0.004] if not quick else [0.03, 0.004]):
        ok = stable_run(config('mocap_constraints', track_timeconst=tc))
        mc.append(dict(timeconst=tc, spring_per_kg=round(1.0 / tc ** 2, 1), stable=ok))
    out['mocap_timeconst_sweep'] = mc
    return out


def push_test() -> Dict:
    body = standard_body()
    tp = body.rest_positions() + SENSOR_SHIFT
    out = {}
    for ctrl, _, _ in VARIANTS:
        sim = Simulation(config(ctrl))
        for _ in range(30):
            st = sim.step({0: tp})[0]
        before = st.positions.copy()
        base_err = np.linalg.norm(st.positions - st.target_world, axis=-1).max()
        sim.apply_push(0, 'ShoulderCenter', (300.0, 0.0, 0.0), 0.1)
        peak, rec = 0.0, None
        for i in range(90):
            st = sim.step({0: tp})[0]
            disp = np.linalg.norm(st.positions - before, axis=-1).max()
            peak = max(peak, disp)
            if rec is None and i > 3 and disp < 0.02:
                rec = (i + 1) / 30.0
            elif disp >= 0.02:
                rec = None
        if peak < 0.02:
            rec = 0.0  # never left the 2 cm band
        out[ctrl] = dict(impulse_Ns=30.0, peak_displacement_cm=100 * peak,
                         recovery_time_s=rec, pre_push_err_cm=100 * float(base_err))
    return out


def rtf(quick: bool, variants=None, counts=(1, 2, 6), chunk: int = 10,
        frames: int = 0) -> Dict:
    """Real-time factors. For each number of characters, the variants are stepped in chunks of
    ``chunk`` frames, interleaved round-robin, so a change in the machine's load hits them alike;
    each figure is the median over its chunks (the VM's timing varies +-25 % run to run). Worlds
    with other numbers of characters are not alive meanwhile (a 6-character world between chunks
    would evict a 1-character one from the caches). ``frames``: frames per run (default 60 quick,
    else 90), at least one chunk."""
    seq = clips(True)[0][1]
    n_chunks = max(1, (frames or (60 if quick else 90)) // chunk)
    out = {}
    for n in counts:
        runs = {}
        for ctrl in (variants or [v for v, _, _ in VARIANTS]):
            sim = Simulation(config(ctrl, max_characters=n))
            offs = [np.array([0.0, 1.6 * (k - (n - 1) / 2), 0.0]) for k in range(n)]
            sim.step({k: seq[0] + offs[k] for k in range(n)})
            runs[f'{ctrl}_{n}char'] = [sim, offs, 1, [], [], [], ctrl]
        for _ in range(n_chunks):
            for r in runs.values():
                sim, offs, i = r[0], r[1], r[2]
                s0 = sim.time
                with _numpy_kernel(r[6].endswith('_numpy')):
                    t0, c0 = time.perf_counter(), time.process_time()
                    for _ in range(chunk):
                        sim.step({k: seq[i % len(seq)] + offs[k] for k in range(len(offs))})
                        i += 1
                    r[3].append(time.perf_counter() - t0)
                    r[4].append(time.process_time() - c0)
                r[5].append(sim.time - s0)   # simulated: whole 2 ms steps (34 ms a 1/30 s frame)
                r[2] = i
        for key, r in runs.items():
            out[key] = float(np.median(np.array(r[5]) / np.array(r[3])))
            out[key + '_cpu'] = float(np.median(np.array(r[5]) / np.array(r[4])))
    return {f'{v}_{n}char{s}': out[f'{v}_{n}char{s}'] for v in (variants or [v for v, _, _ in VARIANTS])
            for n in counts for s in ('', '_cpu')}


def long_run(seconds: float) -> Dict:
    cs = clips(False)
    rng = np.random.default_rng(7)
    sim = Simulation(config('actuator_pd'))   # the default
    n = int(seconds * 30)
    nan_out = 0
    t0 = time.perf_counter()
    for i in range(n):
        name, seq, ori = cs[(i // 180) % len(cs)]
        p = seq[i % len(seq)] + rng.normal(0.0, 0.03, (NUM_JOINTS, 3))
        if rng.random() < 0.02:
            p[rng.integers(NUM_JOINTS)] += rng.normal(0.0, 0.5, 3)  # tracking glitch
        if i % 60 == 30:
            sim.apply_push(0, ['Spine', 'Head', 'ElbowLeft', 'KneeRight'][(i // 60) % 4],
                           rng.normal(0.0, 250.0, 3), 0.1)
        st = sim.step({0: p})[0]
        nan_out += int(not np.all(np.isfinite(st.positions)))
    return dict(seconds=seconds, wall_s=time.perf_counter() - t0, nan_outputs=nan_out,
                nan_resets=sim.counters['nan_reset'], conflicts=sim.counters['constraint_conflict'],
                released=sim.counters['virtual_joint_released'])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='bench_physics', description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--quick', action='store_true', help='fewer clips and sweep points')
    ap.add_argument('--long', action='store_true', help='10 min noisy run instead of 60 s')
    ap.add_argument('--rtf-only', action='store_true',
                    help='only the real-time factors (every controller, and the alternatives beside '
                         'the defaults: one model per group that can touch, the numpy Eq. 1)')
    ap.add_argument('--frames', type=int, default=0,
                    help='real-time factors: frames per variant and number of characters '
                         '(default 60 with --quick, else 90; fewer: a quick check, noisier figures)')
    ap.add_argument('--solver', default='auto',
                    help='MuJoCo constraint solver of every run (SimConfig.solver: auto = newton, '
                         'the default; pgs, cg to compare)')
    ap.add_argument('--out', default='out/bench_physics.json')
    args = ap.parse_args(argv if argv is not None else sys.argv[1:])
    global SOLVER
    try:
        SimConfig(solver=args.solver).validate()
    except ValueError as e:
        ap.error(str(e))
    SOLVER = args.solver
    load = os.getloadavg()[0] if hasattr(os, 'getloadavg') else float('nan')
    res = {'cpu_count': os.cpu_count(), 'load_avg_1min': load, 'solver': args.solver}
    t0 = time.perf_counter()
    print(f'bench_physics (2 ms step; solver {args.solver}; load average {load:.1f} on '
          f'{os.cpu_count()} cores)', flush=True)
    if args.frames < 0:
        ap.error('--frames must be >= 0')
    res['real_time_factor'] = rtf(args.quick, [v for v, _, _ in VARIANTS] + list(RTF_VARIANTS),
                                  frames=args.frames)
    r = res['real_time_factor']
    for k in [k for k in r if not k.endswith('_cpu')]:
        print(f'  RTF {k:28s} wall {r[k]:6.2f}   CPU-time {r[k + "_cpu"]:6.2f} '
              '(sim s per s of this process\'s CPU: the figure on an idle core)', flush=True)
    if args.rtf_only:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(res, indent=1, default=float))
        return 0
    res['tracking'] = tracking(args.quick)
    for ctrl, r in res['tracking'].items():
        print(f'  [{ctrl}] static T-pose error mean {r["static_tpose_err_mean_cm"]:.2f} cm '
              f'(max {r["static_tpose_err_max_cm"]:.2f}); clips mean {r["clip_err_mean_cm"]:.2f} cm '
              f'p95 {r["clip_err_p95_cm"]:.2f} cm {r["clip_err_by_clip_cm"]}', flush=True)
        print(f'  [{ctrl}] segment length error max {r["segment_length_err_max_mm"]:.4f} mm; '
              f'pinned foot drift max {r["pinned_foot_drift_max_cm"]:.2f} cm; jitter raw '
              f'{r["jitter_raw_m_s2"]:.2f} m/s2 -> out {r["jitter_out_m_s2"]:.2f} m/s2 '
              f'({r["jitter_reduction_pct"]:.0f} % lower)', flush=True)
    res['stability'] = stability(args.quick)
    s = res['stability']
    for v in ('explicit_pd', 'actuator_pd', 'actuator_pd_implicit'):
        r = s[v]
        print(f'  stability {v}: Ke sweep {[(x["ke"], x["stable"]) for x in r["ke_sweep"]]} -> max '
              f'stable Ke {r["max_stable_ke"]}; Kd sweep '
              f'{[(x["kd"], x["stable"]) for x in r["kd_sweep"]]} -> max stable Kd '
              f'{r["max_stable_kd"]}', flush=True)
    print(f'  stability mocap_constraints: {[(r["timeconst"], r["stable"]) for r in s["mocap_timeconst_sweep"]]}',
          flush=True)
    res['push'] = push_test()
    for ctrl, r in res['push'].items():
        rec = r['recovery_time_s']
        rec_txt = 'never settled' if rec is None else f'{rec:.2f} s'
        print(f'  push [{ctrl}] 300 N x 0.1 s on ShoulderCenter: peak displacement '
              f'{r["peak_displacement_cm"]:.1f} cm, recovery (< 2 cm) {rec_txt}', flush=True)
    res['long_run'] = long_run(600.0 if args.long else 60.0)
    r = res['long_run']
    print(f'  long noisy run {r["seconds"]:.0f} s (3 cm noise, glitches, pushes): NaN outputs '
          f'{r["nan_outputs"]}, NaN resets {r["nan_resets"]}, conflicts {r["conflicts"]}, '
          f'released {r["released"]} (wall {r["wall_s"]:.0f} s)', flush=True)
    res['bench_wall_s'] = time.perf_counter() - t0
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1, default=float))
    print(f'wrote {out} ({res["bench_wall_s"]:.0f} s)')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
