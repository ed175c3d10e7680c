"""``demo_control``: a scripted performance through the feature world, offline, no DDS needed.

    ros2 run performance_control demo_control                 # out/control_demo.{mcap,png}

Five scenes, one simulated user each (user ids 1-5), 8 s apiece (the last ~52 s), performed by a user of another
size and style than the examples and seen through the Kinect sensor model (the performance
placement: 3.5 m away, sensor 1.2 m up): hanging from the monkey bars and swinging (imitation,
then the arms drop at 6 s: the character falls), climbing the rope, jumping on the trampoline,
swimming a breaststroke, and one continuous performance from the floor (Sec. 8.3: the user walks
in place, the character walks under the monkey bars; the user jumps with the arms up, the
character catches a bar, swings and drops; the user walks in place again until the character is
at the rope (:func:`.performances.watched_performance`), climbs hand over hand, lowers the arms
(the character drops), turns 45 degrees and walks in place, the character walks into the water,
then the user swims). Each
frame runs :class:`PerformanceController` and the physics character
(:class:`physics_sim.simulation.Simulation`) tracking the composed pose, as the graph does with
``control:=true``. Writes

* ``out/control_demo.mcap`` -- ``/kinect/skeletons`` (the performance), ``/control/target``,
  ``/control/intention`` and ``/character/skeletons`` (the physics), the graph's topic names;
* ``out/control_demo.png`` -- per scene: a side view of the character in the world at three
  moments, e1/e2 against their thresholds with the imitation flag, COM height and held contacts.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Dict, List

import numpy as np

from .controller import ControlParams, PerformanceController, build_models
from .features import load_world
from .performances import (SENSOR_HEIGHT, imitation_stream, jump_stream, to_sensor,
                           watched_performance)
from skeleton_core.bagio import BagWriter
from skeleton_core.cdr import frames_to_cdr
from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS, TRACKED
from skeleton_core.model import SEGMENTS

FPS = 30.0
SCENES = ('monkey_bars', 'rope', 'trampoline', 'water', 'continuous')


def scene_stream(world, name: str, seed: int, seconds: float = 8.0):
    """(sensor frames (T, 20, 3), tracking states (T, 20) or None)."""
    rng = np.random.default_rng(seed)
    if name == 'continuous':      # floor -> bars -> walk -> rope -> walk -> water (the test's)
        ctl = PerformanceController(world, ControlParams(sensor_height=SENSOR_HEIGHT))
        frames, states = [], []

        def step(s, st, t):       # the performer watches this character to stop at the rope
            frames.append(s)
            states.append(st)
            return ctl.step(s, t, st)
        watched_performance(world, 0, step)
        return np.array(frames), np.array(states)
    if name == 'trampoline':
        p = jump_stream(rng, n_jumps=5)
    else:
        stop = 6.0 if name == 'monkey_bars' else seconds + 1.0
        p, _ = imitation_stream(world.features[name], rng, pattern=((-1.0, stop),),
                                total=seconds, fade=0.25)
    p = p[:int(seconds * FPS)]
    return to_sensor(p, f'demo_{name}', seed), None


def run(world, out_dir: Path, seconds: float = 8.0, physics: bool = True,
        scenes=SCENES) -> Dict:
    cp = ControlParams(sensor_height=SENSOR_HEIGHT)
    models = build_models(world, cp.recognizer)
    out_dir.mkdir(parents=True, exist_ok=True)
    bag = out_dir / 'control_demo.mcap'
    rows: Dict[str, List] = {}
    grips: Dict[str, List] = {}
    t_base = 1_000_000_000
    try:
        from skeleton_msgs.msg import Intention
    except ImportError:
        Intention = None

    def frame(p, uid, st):
        return SkeletonFrame(positions=p, tracking_state=np.full(NUM_JOINTS, TRACKED, np.uint8),
                             reliability=np.ones(NUM_JOINTS, np.float32), user_id=uid,
                             stamp_ns=st, frame_id='kinect')
    with BagWriter(str(bag)) as w:
        for name in scenes:
            k = SCENES.index(name)   # a scene's user id and seed whichever others run
            uid = k + 1
            s, states = scene_stream(world, name, 300 + k, seconds)
            ctl = PerformanceController(world, cp, models,
                                        start='' if name == 'continuous' else name)
            sim = None
            if physics:
                from physics_sim.simulation import SimConfig, Simulation
                from skeleton_core.tf import Transform
                sim = Simulation(SimConfig(pin_feet=False, lift_feet=False,
                                           feature_world=world.path),
                                 sensor_pose=Transform.from_xyz_ypr(0.0, 0.0, SENSOR_HEIGHT))
            rows[name] = []
            grips[name] = []
            for i in range(len(s)):
                st = t_base + int(round((k * seconds + i / FPS) * 1e9))
                o = ctl.step(s[i], i / FPS, None if states is None else states[i])
                w.write_raw('/kinect/skeletons', frames_to_cdr([frame(s[i], uid, st)], st, 'kinect'), st)
                w.write_raw('/control/target',
                            frames_to_cdr([frame(o.positions_sensor, uid, st)], st, 'kinect'), st)
                phys = None
                if sim is not None:   # as the physics node does with /control/intention
                    sim.set_engaged(uid, list(o.contacts), list(o.contacts.values()))
                    sim.set_target(uid, o.positions_sensor, stamp_ns=st)
                    sim.advance(1.0 / FPS)
                    stt = sim.state(uid)
                    phys = stt.positions
                    w.write_raw('/character/skeletons', frames_to_cdr(
                        [frame(stt.positions_sensor, uid, st)], st, 'kinect'), st)
                if Intention is not None:
                    m = Intention()
                    m.header.stamp.sec, m.header.stamp.nanosec = divmod(st, 1_000_000_000)
                    m.header.frame_id = 'kinect'
                    m.user_id = uid
                    m.feature = o.feature
                    m.imitating = o.imitating
                    r = o.recognition
                    m.confidence = float(r.confidence) if r else 0.0
                    m.e1 = float(r.e1) if r else float('nan')
                    m.e2 = float(r.e2) if r else float('nan')
                    m.engaged_effectors = list(o.contacts)
                    m.engaged_features = list(o.contacts.values())
                    w.write('/control/intention', m, st)
                rows[name].append((o, phys, ctl.obstacles))
                if sim is not None:   # the physics hands gripping a feature: {hand joint: point}
                    grips[name].append(sim.grip_points(uid))
    return {'bag': bag, 'rows': rows, 'params': cp, 'grips': grips}


def _draw_world(ax, world, obstacles, scene: str) -> None:
    for f in world.features.values():
        if f.name not in (scene, 'floor') and not (scene == 'continuous'
                                                    and f.kind in ('water', 'bars', 'rope')):
            continue
        for g in f.geoms:
            if g.type == 'plane':
                ax.axhline(0.0, color='0.6', lw=1)
            elif g.type == 'volume':
                c, h = g.vec('center'), g.vec('half')
                ax.add_patch(__import__('matplotlib.patches', fromlist=['x']).Rectangle(
                    (c[0] - h[0], c[2] - h[2]), 2 * h[0], 2 * h[2], color=(0.2, 0.4, 0.9, 0.15)))
    for a, b, r, f in obstacles.capsules:
        if f != scene:
            continue
        ax.plot([a[0], b[0]], [a[2], b[2]], color='0.35', lw=3, solid_capstyle='round')
        if abs(a[0] - b[0]) < 1e-6 and abs(a[2] - b[2]) < 1e-6:
            ax.plot(a[0], a[2], 'o', color='0.35', ms=5)
    for c, h, f in obstacles.boxes:
        if f != scene:
            continue
        ax.add_patch(__import__('matplotlib.patches', fromlist=['x']).Rectangle(
            (c[0] - h[0], c[2] - h[2]), 2 * h[0], 2 * h[2], color=(0.2, 0.5, 0.9, 0.8)))


def plot(result: Dict, world, path: Path) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    rows, cp = result['rows'], result['params']
    fig, axes = plt.subplots(3, len(rows), figsize=(4.2 * len(rows), 10), squeeze=False)
    for col, (name, rr) in enumerate(rows.items()):
        ax = axes[0, col]
        n = len(rr)
        for i, shade in ((int(0.25 * n), 0.75), (int(0.5 * n), 0.45), (int(0.85 * n), 0.0)):
            o, phys, obstacles = rr[i]
            if shade == 0.0:
                _draw_world(ax, world, obstacles, name)
            p = phys if phys is not None else o.positions_world
            for a, b in SEGMENTS:
                ax.plot([p[a, 0], p[b, 0]], [p[a, 2], p[b, 2]], color=(0.85 * shade + 0.1,) * 2
                        + (0.9,), lw=2)
            for e, q in o.contact_points.items():
                ax.plot(q[0], q[2], 'o', color='red', ms=6)
        com = np.array([r[0].com for r in rr])
        ax.set_xlim(com[:, 0].mean() - 1.6, com[:, 0].mean() + 1.6)
        if name == 'continuous':      # the walk: the COM's path seen from above, shifted up
            ax.plot(com[:, 0], com[:, 1] + 6.0, color='C2', lw=1.5,
                    label='COM path, top view (y + 6 m)')
            wv = next(g for f in world.features.values() for g in f.geoms if g.type == 'volume')
            ax.axhline(wv.vec('center')[1] + wv.vec('half')[1] + 6.0, color='C0', lw=0.8,
                       ls='--', label="water's edge (top view)")
            ax.legend(fontsize=7, loc='lower left')
            ax.set_xlim(float(com[:, 0].min()) - 1.0, float(com[:, 0].max()) + 1.0)
        ax.set_ylim(-0.1, max(3.8, float(com[:, 2].max()) + 1.4))   # a climber stays in view
        ax.set_aspect('equal')
        ax.set_title(f'{name}: character at 25/50/85 % (side view)')
        ax.set_xlabel('x (m)')
        t = np.arange(n) / FPS
        ax = axes[1, col]
        e1 = [r[0].recognition.e1 if r[0].recognition else np.nan for r in rr]
        e2 = [r[0].recognition.e2 if r[0].recognition else np.nan for r in rr]
        ax.semilogy(t, e1, label='e1 (Eq. 5)')
        ax.semilogy(t, e2, label='e2 (Eq. 6)')
        ax.axhline(cp.recognizer.e1_threshold, color='C0', ls='--', lw=0.8)
        ax.axhline(cp.recognizer.e2_threshold, color='C1', ls=':', lw=0.8)
        imit = np.array([r[0].imitating for r in rr], float)
        ax.fill_between(t, 1e-4, 1e-4 + 10 * imit, color='green', alpha=0.12, step='mid',
                        label='imitating')
        ax.set_ylim(1e-4, 3)
        ax.set_title('intention recognition' if rr[0][0].recognition else 'no example motion')
        ax.legend(fontsize=7, loc='upper right')
        ax = axes[2, col]
        ax.plot(t, com[:, 2], color='k', label='COM height (m)')
        for j, e in enumerate(('HandLeft', 'HandRight', 'FootLeft', 'FootRight')):
            held = np.array([e in r[0].contacts for r in rr], float)
            ax.fill_between(t, -0.1 * (j + 1), -0.1 * (j + 1) + 0.08 * held, step='mid',
                            color=f'C{j}', label=f'{e} held')
        ax.set_xlabel('time (s)')
        ax.legend(fontsize=7, loc='upper right')
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--world', default='playground')
    ap.add_argument('--out', default='out', help='output directory')
    ap.add_argument('--seconds', type=float, default=8.0, help='length of every scene')
    ap.add_argument('--no-physics', action='store_true', help='skip the physics character')
    ap.add_argument('--scenes', default=','.join(SCENES),
                    help='comma-separated subset of the scenes (default: all; "continuous" runs '
                         'its whole performance, about 50 s, whatever --seconds)')
    a = ap.parse_args(argv)
    asked = {n for n in a.scenes.split(',') if n}
    scenes = [n for n in SCENES if n in asked]   # in the demo's order (its stamps follow it)
    bad = sorted(asked - set(SCENES))
    if bad or not scenes:
        ap.error(f'--scenes: unknown {bad or "(none given)"}; choose from {",".join(SCENES)}')
    world = load_world(a.world)
    out = Path(a.out)
    res = run(world, out, a.seconds, not a.no_physics, scenes)
    png = out / 'control_demo.png'
    plot(res, world, png)
    for name, rr in res['rows'].items():
        pen = max(r[0].penetration for r in rr)
        imit = np.mean([r[0].imitating for r in rr])
        held = np.mean([any(e.startswith('Hand') for e in r[0].contacts) for r in rr])
        print(f'{name:12s} imitating {100 * imit:5.1f} % of frames, hands held {100 * held:5.1f} %, '
              f'penetration max {100 * pen:.1f} cm')
    print(f'wrote {res["bag"]} and {png}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
