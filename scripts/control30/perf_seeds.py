"""Continuous performance with the rope over performers: phases, release speeds, landings."""

import json
import os
import sys
import time

import numpy as np

from performance_control import controller, dynamics
from performance_control.controller import ControlParams, PerformanceController
from performance_control.features import load_world
from performance_control.performances import SENSOR_HEIGHT, watched_performance

WORLD = load_world("playground")


def W_kind(f):
    return WORLD.features[f].kind

if os.environ.get("BASE"):
    dynamics.SWING_STRENGTH = float("inf")
    if hasattr(controller, "RELEASE_SPEED"):
        controller.RELEASE_SPEED = float("inf")


def run(seed):
    ctl = PerformanceController(WORLD, ControlParams(sensor_height=SENSOR_HEIGHT))
    phase, com, vel, hands, cpu = [], [], [], [], []
    ft_, vz_, foot, vz2 = [], [], [], []

    def step(s, st, t):
        c0 = time.thread_time()
        o = ctl.step(s, t, st)
        cpu.append(time.thread_time() - c0)
        h = {f for e, f in o.contacts.items() if e.startswith("Hand")}
        phase.append(
            "bars"
            if "monkey_bars" in h
            else "rope"
            if "rope" in h
            else "water"
            if ctl.dp.in_water
            else "walk"
            if ctl.walking
            else ""
        )
        com.append(o.com.copy())
        vel.append(ctl.dp.com_velocity.copy())
        hands.append(sorted(h))
        foot.append(
            any(e.startswith("Foot") and W_kind(f) == "floor" for e, f in o.contacts.items())
            or ctl.walking
        )
        dp = ctl.dp
        f = dp.forces(dp.time)
        eff = dp.effectors()
        c = dp.com
        w = dp.total_mass * 9.81
        ftr, vzr = [0.0, 0.0], [0.0, 0.0]
        for k, e in enumerate(("HandLeft", "HandRight")):
            if e in dp.contacts:
                u = (eff[k] - c) / np.linalg.norm(eff[k] - c)
                fr = f[k] @ u
                ftr[k] = float(np.linalg.norm(f[k] - fr * u)) / w
                vzr[k] = ctl._hand_vz[e]
        ft_.append(max(ftr))
        vz_.append(min(vzr))
        vz2.append(max(vzr) if all(e in dp.contacts for e in ("HandLeft", "HandRight")) else 0.0)
        return o

    sched, rope_at = watched_performance(WORLD, seed, step)
    seq = [
        x for k, x in enumerate(phase) if x and x != next((y for y in reversed(phase[:k]) if y), "")
    ]
    com, vel = np.array(com), np.array(vel)
    stand = com[0, 2]
    ev = []
    # releases: last frame with hands on bars/rope followed by no hands held
    for k in range(1, len(phase)):
        if phase[k - 1] in ("bars", "rope") and phase[k] != phase[k - 1]:
            feat = phase[k - 1]
            # speed max over the 1 s before release (while held) and at release
            a = max(0, k - 30)
            vmax_before = float(np.linalg.norm(vel[a:k], axis=1).max())
            v_rel = float(np.linalg.norm(vel[k]))
            # landing: first frame after k where COM z < stand + 0.15 and vz >= -0.2 (or next phase walk)
            land = next((j for j in range(k, min(len(com), k + 150)) if foot[j]), None)
            d = float(np.linalg.norm(com[land, :2] - com[k, :2])) if land else float("nan")
            dx = float(com[land, 0] - com[k, 0]) if land else float("nan")
            rise = float(com[k : k + 45, 2].max() - com[k, 2])
            ev.append(
                dict(
                    feat=feat,
                    t=k / 30,
                    vmax_before=round(vmax_before, 2),
                    v_release=round(v_rel, 2),
                    land_t=None if land is None else round(land / 30, 2),
                    land_dist=round(d, 2),
                    land_dx=round(dx, 2),
                    rise=round(rise, 2),
                    hmax=round(float(com[:k, 2].max() - stand), 2),
                )
            )
    ph = np.array(phase)
    ft_ = np.array(ft_)
    vz_ = np.array(vz_)
    # holds, without the last 0.5 s before each release
    last = np.zeros(len(ph), bool)
    for k in range(1, len(ph)):
        if ph[k - 1] in ("bars", "rope") and ph[k] != ph[k - 1]:
            last[max(0, k - 15) : k] = True
    stats = {}
    for fe in ("bars", "rope"):
        m = (ph == fe) & ~last
        if m.any():
            stats[fe] = dict(
                vz_both=round(float(np.array(vz2)[m].min()), 2),
                ft_max=round(float(ft_[m].max()), 2),
                ft_p99=round(float(np.percentile(ft_[m], 99)), 2),
                vz_min=round(float(vz_[m].min()), 2),
            )
    np.savez(
        f"out/run_{os.environ.get('TAG', 'x')}_{seed}.npz",
        phase=ph,
        com=com,
        vel=vel,
        foot=np.array(foot),
        vz2=np.array(vz2),
        ft=ft_,
        vz=vz_,
    )
    ok = seq == ["walk", "bars", "walk", "rope", "walk", "water"]
    return dict(
        seed=seed,
        ok=ok,
        seq=seq,
        rope_at=rope_at,
        swim_at=next((round(a, 2) for a, w in reversed(sched) if w == "swim"), None),
        unstable=ctl.dp.unstable_steps,
        releases=ev,
        holds=stats,
        cpu_ms_median=round(1e3 * float(np.median(cpu)), 2),
        final=[round(float(x), 2) for x in com[-1]],
    )


if __name__ == "__main__":
    for s in map(int, sys.argv[1:]):
        r = run(s)
        print(json.dumps(r), flush=True)
