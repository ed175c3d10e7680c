"""CPU cost of the ROS-ecosystem outputs per frame: ``ros2 run viz bench_hri [--frames 150]``.

For 1, 2 and 6 users of a built-in motion: the ``hri`` node's work per input frame (REP-155 bodies:
angles, lengths, transforms; openni2_tracker's frames; the TFMessage bytes and the JointState
messages serialized, as published), and the physics node's ``/character/joint_states`` and root
transforms for as many characters. CPU time of this process (``time.process_time``), so a loaded
machine changes the figures less than wall time would; the budget is one Kinect frame, 33 ms.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from skeleton_core.conversions import SkeletonFrame
from skeleton_core.model import NUM_JOINTS
from skeleton_core.rep155 import BodyTracker


def _frames(clips, k, users):
    return [SkeletonFrame(positions=np.asarray(clips[u % len(clips)].positions[k % 180])
                          + (2.5, u - users / 2, 0.0),
                          tracking_state=np.full(NUM_JOINTS, 2, np.uint8), user_id=u + 1,
                          frame_id='kinect_link') for u in range(users)]


def bench_hri(users: int, frames: int, openni: bool = True) -> dict:
    """CPU ms per frame of the hri node's library work and of its messages."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    from skeleton_data.motions import builtin_clips

    from skeleton_core.rep155 import TfEncoder
    clips = builtin_clips(seed=1)
    tracker = BodyTracker(openni=openni)
    encoder, js = TfEncoder(), {}
    t_lib = t_msg = 0.0
    n_tf = 0
    for k in range(frames):
        fr = _frames(clips, k, users)
        t0 = time.process_time()
        out = tracker.update(fr, k * 33_333_333, 'kinect_link', k / 30)
        t1 = time.process_time()
        encoder.encode(out.tf_pairs, out.stamp_ns, out.tf_translations, out.tf_rotations)
        for bid in out.tracked:
            m = js.setdefault(bid, JointState())
            m.name = out.joint_names[bid]
            m.position = out.angles[bid].tolist()
            serialize_message(m)
        t2 = time.process_time()
        if k >= 5:   # (the first frames make the URDFs)
            t_lib += t1 - t0
            t_msg += t2 - t1
        n_tf = len(out.tf_pairs)
    n = frames - 5
    return {'lib_ms': 1e3 * t_lib / n, 'msg_ms': 1e3 * t_msg / n, 'transforms': n_tf}


def bench_character(characters: int, frames: int) -> dict:
    """CPU ms per tick of the physics node's character joint states (library + messages)."""
    from physics_sim.character_urdf import CharacterRobots
    from physics_sim.simulation import Simulation
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    from skeleton_core.tf import Transform
    from skeleton_core.tf_ros import to_tf_message
    from skeleton_data.motions import builtin_clips
    clips = builtin_clips(seed=2)
    sim = Simulation()
    states = sim.step({u + 1: np.asarray(clips[u].positions[0]) + (0.0, 1.5 * u, 0.0)
                       for u in range(characters)})
    robots = CharacterRobots()
    t = 0.0
    for k in range(frames):
        t0 = time.process_time()
        urdf, names, angles, roots = robots.update(states, sim.characters, np.zeros(3))
        serialize_message(JointState(name=names, position=angles.tolist()))
        serialize_message(to_tf_message([('world', c, Transform(p, q)) for c, p, q in roots]))
        if k >= 1:
            t += time.process_time() - t0
    return {'ms': 1e3 * t / (frames - 1)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog='bench_hri', description=__doc__)
    ap.add_argument('--frames', type=int, default=150)
    a = ap.parse_args(argv)
    print('hri node, CPU ms per input frame (REP-155 bodies + openni2_tracker frames):')
    for users in (1, 2, 6):
        r = bench_hri(users, a.frames)
        print(f'  {users} user(s): {r["lib_ms"]:.2f} library + {r["msg_ms"]:.2f} messages = '
              f'{r["lib_ms"] + r["msg_ms"]:.2f} ms ({r["transforms"]} transforms)')
    print('physics node, /character/joint_states + root transforms, CPU ms per tick:')
    for n in (1, 2, 6):
        print(f'  {n} character(s): {bench_character(n, a.frames)["ms"]:.2f} ms')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
