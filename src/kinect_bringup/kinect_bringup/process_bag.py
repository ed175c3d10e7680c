"""``process_bag``: run the reconstruction (and optionally the physics character) over a recorded
bag without DDS, as fast as possible, and write an output bag (+ an accuracy report when the bag
holds ground truth on /kinect/ground_truth).

    ros2 run kinect_bringup process_bag out/demo.mcap --out out/processed.mcap
    ros2 run kinect_bringup process_bag cache/uiprmd/m01_s02_e01.mcap --method A --physics

The output bag holds every input topic unchanged plus ``/posture/completed`` (method A) or
``/posture/reconstructed`` (B, C) and, with ``--physics``, ``/character/skeletons`` — the same
topics and types the live graph publishes, so the report and replay tools take it like any bag.

A recording of the Azure Kinect ROS driver (``ros2 bag record /body_tracking_data``: no
SkeletonArray, one ``*body_tracking_data`` MarkerArray topic) is taken as it is: its markers are
converted to skeletons (:mod:`skeleton_data.k4abt`), written to the output on
``/kinect/skeletons`` with the tracker ``azure_kinect_bt``, and processed.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np
from skeleton_core.bag_split import bag_pieces, pieces_topics, read_pieces
from skeleton_core.bagio import BagError, BagWriter
from skeleton_core.cdr import SKELETON_ARRAY, CdrError, frames_from_cdr, frames_to_cdr
from skeleton_core.presence import Presence
from pose_reconstruction.bone_lengths import SensorLengthNoise
from pose_reconstruction.profile import SEGMENT_NAMES
from pose_reconstruction.reconstructor import Reconstructor
from skeleton_eval.metrics import eq18_error, length_rigidity, mpjpe

SKELETONS = 'skeleton_msgs/msg/SkeletonArray'
CONVERTED_TOPIC = '/kinect/skeletons'   # where a recording of body markers is converted to


def _progress(total: int, enabled: bool):
    try:
        from tqdm import tqdm
        return tqdm(total=total, unit='frame', disable=not enabled, dynamic_ncols=True)
    except ImportError:  # pragma: no cover
        class _Null:
            def update(self, n=1):
                pass

            def close(self):
                pass
        return _Null()


def process(bag, out: Path, method: str = 'C', database: str = '', physics: bool = False,
            input_topic: str = '/kinect/skeletons', user_timeout_s: float = 2.0,
            time_jump_reset_s: float = 1.0, progress: bool = True,
            params: Optional[Dict] = None, warn=None, correction: str = 'auto',
            input_tracker: str = '', info=None, save_profile: str = '',
            profile_dir: str = '') -> Dict:
    """Process ``bag`` into ``out``; returns a summary (frames, wall time, users, refusals,
    accuracy). ``bag``: one file, a folder of pieces (a split recording) or a list of pieces,
    processed in order as one recording.

    Users come and go as they do live, in the bag's time (the messages' header stamps, the log
    time when unstamped): a user unseen for ``user_timeout_s`` (the reconstruction node's
    ``user_timeout_s``) leaves, and its reconstruction state and character go with it; a later
    sighting is a new arrival. A message whose stamp repeats the previous one or goes back less
    than ``time_jump_reset_s`` is skipped like the live node does (counted in
    ``skipped_messages``); a bigger step back (a concatenated or looped recording) restarts every
    user. Frames the physics world refuses (a 7th simultaneous user, an invalid target) are
    counted per reason in ``refused`` and warned once per reason (``warn(text)``, default
    stderr).

    The learned sensor correction (``correction``: 'auto', a file, or '' = off) is picked for
    the skeleton tracker the bag declares (``/kinect/tracker``, :mod:`skeleton_core.tracker`)
    or ``input_tracker`` when given (it overrides); a correction for another tracker is refused
    with one line through ``warn`` (the run goes on without it); ``info(text)`` gets which one
    was applied.

    ``bone_lengths`` in the summary: per user track, each segment's length std over time (cm),
    raw and output, beside the jitter (:func:`skeleton_eval.metrics.length_rigidity`), and the
    constant lengths of the longest track; ``save_profile`` (a name) saves them as that user
    profile (``<profile_dir>/<name>.json``, default ``cache/profiles``)."""
    from skeleton_core.model import NOT_TRACKED

    if warn is None:
        def warn(text):
            print(f'process_bag: warning: {text}', file=sys.stderr, flush=True)
    try:
        pieces = bag_pieces(bag)
        topics = pieces_topics(pieces)
    except BagError as e:
        raise ValueError(str(e)) from None
    if not isinstance(bag, (str, Path)):
        bag = f'{pieces[0]} (+{len(pieces) - 1} pieces)'
    from skeleton_data import k4abt as K4
    marker_topic = _marker_topic(bag, topics, input_topic)
    if marker_topic is not None:   # an Azure Kinect ROS driver recording: converted as it is read
        input_topic = CONVERTED_TOPIC
    elif input_topic not in topics:
        raise ValueError(f'{bag}: no {input_topic} in the bag (topics: {sorted(topics)})')
    n_in = topics[marker_topic or input_topic][1]
    from pose_reconstruction import correction as corr_mod
    from skeleton_core import tracker as tracker_mod
    if info is None:
        def info(text):
            print(f'process_bag: {text}', file=sys.stderr, flush=True)
    streamed = tracker_mod.from_bag(pieces[0])   # declared once, at the start of the recording
    declare = marker_topic is not None and not streamed
    if declare:
        streamed = K4.TRACKER
    tracker = tracker_mod.resolve(input_tracker, streamed)
    corr = corr_mod.select(correction, tracker, log=info, warn=warn)
    params = dict(params or {})
    if corr is not None:
        params.update(correction=corr, input_tracker=tracker)
        info(f'{corr_mod.describe_file(corr)} applied (tracker {tracker}: '
             f'{"--input-tracker" if input_tracker else "declared by the bag"})')
    # node_common imports rclpy: process_bag runs without a ROS graph
    from pose_reconstruction.node_common import load_database
    if save_profile:
        if method == 'A':
            raise ValueError('--save-profile needs method B or C (their output has one set of '
                             'bone lengths per user)')
        from pose_reconstruction.profile import profile_path
        profile_path(save_profile, profile_dir or None)   # a bad name: refused before the run
    db = load_database(database)
    out_topic = '/posture/completed' if method == 'A' else '/posture/reconstructed'
    users: Dict[int, object] = {}
    # one sensor: its segment length noise measured on a user is the next one's first guess
    length_noise = SensorLengthNoise()
    presence = Presence(user_timeout_s)
    sim = None
    if physics:
        from physics_sim.methods import PhysicsMethod
        sim = PhysicsMethod(upstream=None)
    truth: Dict[tuple, np.ndarray] = {}
    raw: Dict[tuple, np.ndarray] = {}
    rec: Dict[tuple, np.ndarray] = {}
    char: Dict[tuple, np.ndarray] = {}
    # one user's (raw, output) frames from arrival to leaving: the bone-length std per track
    tracks: List[tuple] = []
    track_of: Dict[int, tuple] = {}
    errors: List = []
    skipped: Dict[str, int] = {}
    warned: set = set()
    seen_users: set = set()
    char_users: set = set()
    user_frames = 0
    char_frames = 0
    arrivals = 0
    bar = _progress(n_in, progress)
    t0, c0 = time.perf_counter(), time.process_time()
    frame_no = 0
    corrupt = 0
    last_stamp: Optional[int] = None

    def leave(uid: int) -> None:
        users.pop(uid, None)
        track_of.pop(uid, None)
        if sim is not None:
            sim.remove(uid)

    out.parent.mkdir(parents=True, exist_ok=True)
    with BagWriter(str(out)) as writer:
        # SkeletonArray bytes are decoded and encoded by skeleton_core.cdr (numpy), not through
        # rclpy message objects: the I/O would otherwise cost as much as the reconstruction
        for m in _input_messages(pieces, marker_topic, warn):
            if declare:   # the converted recording declares its tracker, as an imported one does
                tracker_mod.write_to_bag(writer, streamed, m.stamp_ns)
                declare = False
            writer.write_raw(m.topic, m.data, m.stamp_ns, m.msgtype)
            if m.topic == '/kinect/ground_truth' and m.msgtype == SKELETONS:
                try:
                    for f in frames_from_cdr(m.data)[2]:
                        # a joint the ground truth marks NOT_TRACKED has no reference: not
                        # scored (e.g. UI-PRMD's hands, which the Kinect never recorded)
                        truth[(f.user_id, f.stamp_ns)] = np.where(
                            (f.tracking_state == NOT_TRACKED)[:, None], np.nan, f.positions)
                except CdrError:
                    corrupt += 1
                continue
            if m.topic != input_topic:
                continue
            if m.msgtype != SKELETON_ARRAY:
                raise ValueError(f'{bag}: {input_topic} holds {m.msgtype}, not {SKELETON_ARRAY}')
            frame_no += 1
            bar.update(1)
            try:
                stamp, frame_id, frames = frames_from_cdr(m.data, errors)
            except CdrError:   # a corrupt message: skipped and counted, the rest goes on
                corrupt += 1
                continue
            t = stamp or m.stamp_ns
            if last_stamp is not None and t <= last_stamp:
                back = (last_stamp - t) * 1e-9
                cause = ('duplicate stamp' if t == last_stamp else 'out-of-order stamp'
                         if back <= time_jump_reset_s else None)
                if cause is not None:   # as the live node: dropped where it arrives
                    skipped[cause] = skipped.get(cause, 0) + 1
                    continue
                for uid in list(users) + (list(sim.sim.characters) if sim else []):
                    leave(uid)   # time jumped back: every user starts again
                presence.clear()
            last_stamp = t
            presence.observe(t, ())            # the bag's clock moves on: who has left?
            for uid in presence.expired():
                leave(uid)
            presence.observe(t, [f.user_id for f in frames])
            outs = []
            for f in frames:
                r = users.get(f.user_id)
                if r is None:
                    r = users[f.user_id] = Reconstructor(db, method=method,
                                                                length_noise=length_noise,
                                                                **params)
                    arrivals += 1
                    track_of[f.user_id] = ([], [], r)
                    tracks.append(track_of[f.user_id])
                seen_users.add(f.user_id)
                raw[(f.user_id, f.stamp_ns)] = f.positions
                o = r.process(f)
                rec[(f.user_id, f.stamp_ns)] = o.positions
                track_of[f.user_id][0].append(f.positions)
                track_of[f.user_id][1].append(o.positions)
                outs.append(o)
            user_frames += len(outs)
            writer.write_raw(out_topic, frames_to_cdr(outs, stamp, frame_id), m.stamp_ns, SKELETONS)
            if sim is not None:
                sims = sim.process_frames(outs, t)
                for reason, uids in sim.refused_users.items():
                    if reason not in warned:
                        warned.add(reason)
                        warn(f'user {min(uids)} refused a character: {reason} (warned once per '
                             f'reason; every refusal is counted in the summary)')
                for s_ in sims:
                    char[(s_.user_id, s_.stamp_ns)] = s_.positions
                    char_users.add(s_.user_id)
                char_frames += len(sims)
                writer.write_raw('/character/skeletons', frames_to_cdr(sims, stamp, frame_id),
                                 m.stamp_ns, SKELETONS)
    bar.close()
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0   # this process's CPU: the figure on an idle core
    summary = {'input': str(bag), 'output': str(out), 'method': method, 'frames': frame_no,
               'wall_s': wall, 'recorded_s': frame_no / 30.0,
               'x_real_time': (frame_no / 30.0) / wall if wall > 0 else float('nan'),
               'cpu_s': cpu, 'x_real_time_cpu': (frame_no / 30.0) / cpu if cpu > 0 else float('nan'),
               'dropped_skeletons': len(errors), 'corrupt_messages': corrupt,
               'skipped_messages': skipped, 'physics': physics,
               'users': len(seen_users), 'user_arrivals': arrivals, 'user_frames': user_frames,
               'user_timeout_s': user_timeout_s, 'tracker': tracker, 'tracker_declared': streamed,
               'correction': (corr_mod.describe_file(corr) if corr is not None else None)}
    summary['bone_lengths'] = dict(length_rigidity(
        [(np.asarray(a), np.asarray(b)) for a, b, _ in tracks if a]), segments=SEGMENT_NAMES)
    # the user track with the most frames: its constant lengths (a profile can be saved)
    longest = max(tracks, key=lambda t: len(t[0]), default=None)
    lengths = longest[2].bone_lengths if longest is not None else None
    # lengths estimated again within a track: evidence of another person under the same id
    summary['bone_lengths']['restarts'] = int(sum(t[2].bone_length_restarts for t in tracks))
    summary['bone_lengths']['longest_track_lengths_m'] = (
        None if lengths is None else [round(float(v), 5) for v in lengths])
    if save_profile:
        from pose_reconstruction.profile import from_estimate, profile_path
        prof = from_estimate(lengths, save_profile, tracker or '',
                             frames=len(longest[0]) if longest else 0,
                             source=f'process_bag {bag} (method {method})')
        summary['profile'] = str(prof.save(profile_path(save_profile, profile_dir or None)))
    if sim is not None:
        summary.update({
            'characters': len(char_users), 'character_frames': char_frames,
            'character_frame_share': char_frames / user_frames if user_frames else float('nan'),
            'refused': {reason: {'frames': int(n), 'users': sorted(sim.refused_users[reason])}
                        for reason, n in sorted(sim.refused.items())}})
    if truth:
        summary['accuracy'] = accuracy(truth, {'raw': raw, method: rec, **({'physics': char} if char else {})})
    return summary


def _marker_topic(bag, topics, input_topic: str) -> Optional[str]:
    """The Azure Kinect ROS driver's body-marker topic to convert, if the input is one: the
    topic named (a MarkerArray), or, when the bag has neither it nor any SkeletonArray, its only
    ``*body_tracking_data`` topic."""
    from skeleton_data import k4abt as K4
    if input_topic in topics:
        return input_topic if topics[input_topic][0] == K4.MARKER_ARRAY else None
    if any(ty == SKELETONS for ty, _ in topics.values()):
        return None
    markers = K4.body_tracking_topics(topics)
    if len(markers) > 1:
        raise ValueError(f'{bag}: several body-marker topics ({", ".join(markers)}): name one '
                         f'with --topic')
    return markers[0] if markers else None


def _input_messages(pieces, marker_topic: Optional[str], warn):
    """The bag's messages in log order; with ``marker_topic``, each completed capture of the
    body markers follows as a SkeletonArray on :data:`CONVERTED_TOPIC` (skeleton_data.k4abt)."""
    if marker_topic is None:
        yield from read_pieces(pieces, decode=False)
        return
    from skeleton_core.bagio import BagMessage
    from skeleton_data import k4abt as K4
    stream = K4.MarkerStream('kinect_link', warn=warn, live=False)

    def converted(log_ns, stamp, frames):
        return BagMessage(CONVERTED_TOPIC, log_ns, SKELETONS, None,
                          frames_to_cdr(frames, stamp, 'kinect_link'))
    for m in read_pieces(pieces, decode=False):
        yield m
        if m.topic == marker_topic:
            for stamp, frames in stream.feed(m.data, m.stamp_ns):
                yield converted(m.stamp_ns, stamp, frames)
    for stamp, frames in stream.flush():
        yield converted(stamp + stream._latency_ns, stamp, frames)


def accuracy(truth: Dict, streams: Dict[str, Dict]) -> Dict:
    """Per-stream MPJPE and Eq. 18 error (cm) against the ground truth, matched by (user, stamp)."""
    out = {}
    for name, data in streams.items():
        keys = sorted(k for k in data if k in truth)
        if not keys:
            continue
        est = np.stack([data[k] for k in keys])
        ref = np.stack([truth[k] for k in keys])
        out[name] = {'frames': len(keys), 'mpjpe_cm': mpjpe(est, ref)[1],
                     'eq18_cm': eq18_error(est, ref)[1]}
    return out


def bone_length_text(b: Dict, method: str) -> str:
    """The summary's lines on the bone lengths: per user track, the std of each segment's
    length over time (cm), raw and output, beside the jitter (m/s^2)."""
    if not b.get('tracks'):
        return '  bone lengths: no user track of 3 frames or more'
    lines = [f"  bone-length std (cm, per user track, mean of 19 segments): raw "
             f"{b['raw_std_mean_cm']:.3f} -> {method} {b['out_std_mean_cm']:.4f} "
             f"({-b['std_reduction_pct']:+.1f} %); jitter raw {b['raw_jitter_ms2']:.2f} -> "
             f"{method} {b['out_jitter_ms2']:.2f} m/s^2; NaN frames {b['out_nan_frames']}; "
             f"{b['tracks']} track(s), {b['frames']} frames, lengths estimated again "
             f"{b.get('restarts', 0)} time(s)",
             '    per segment (raw -> ' + method + '): ' + ', '.join(
                 f'{n} {r:.2f}->{o:.2f}' for n, r, o in zip(b['segments'], b['raw_std_cm'],
                                                         b['out_std_cm']))]
    return '\n'.join(lines)


def main(argv=None) -> int:
    from skeleton_core.tracker import TRACKERS
    p = argparse.ArgumentParser(prog='process_bag', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('bag', nargs='+', help='input MCAP bag with skeleton_msgs/SkeletonArray: a '
                   'file, a folder of pieces (a split recording) or several pieces in order')
    p.add_argument('--out', default=None, help='output bag (default: <input>_processed.mcap)')
    p.add_argument('--method', choices=['A', 'B', 'C'], default='C')
    p.add_argument('--database', default='', help='database file ("" = default)')
    p.add_argument('--physics', action='store_true', help='also run the physics character')
    p.add_argument('--topic', default='/kinect/skeletons')
    p.add_argument('--user-timeout', type=float, default=2.0,
                   help='a user unseen this long in the bag\'s time leaves, with its character '
                        '(s; default 2.0 = the reconstruction node\'s user_timeout_s)')
    p.add_argument('--correction', default='auto',
                   help="learned sensor correction: 'auto' (default) = the one learned for the "
                        "bag's skeleton tracker (cache/sensor_correction_<tracker>.npz), a file, "
                        "or '' = off")
    p.add_argument('--input-tracker', default='', choices=('',) + TRACKERS,
                   help="the input's skeleton tracker (default: the one the bag declares on "
                        "/kinect/tracker); overrides the bag's")
    p.add_argument('--report', default=None, help='write the summary JSON here')
    p.add_argument('--save-profile', default='', metavar='NAME',
                   help="save the reconstruction's constant bone lengths of the user with the "
                        'most frames as user profile NAME (cache/profiles/NAME.json; the '
                        "reconstruction's user_profile parameter); methods B and C")
    p.add_argument('--profile-dir', default='', help='--save-profile: profile directory')
    p.add_argument('--no-progress', action='store_true')
    args = p.parse_args(argv)
    bag = [Path(b) for b in args.bag] if len(args.bag) > 1 else Path(args.bag[0])
    first = Path(args.bag[0])
    out = Path(args.out) if args.out else first.with_name(first.stem + '_processed.mcap')
    try:
        summary = process(bag, out, args.method, args.database, args.physics, args.topic,
                          user_timeout_s=args.user_timeout, progress=not args.no_progress,
                          correction=args.correction, input_tracker=args.input_tracker,
                          save_profile=args.save_profile, profile_dir=args.profile_dir)
    except (ValueError, FileNotFoundError, OSError, RuntimeError) as e:
        print(f'process_bag: error: {e}', file=sys.stderr)
        return 1
    report = Path(args.report) if args.report else out.with_suffix('.json')
    report.write_text(json.dumps(summary, indent=2))
    print(f"process_bag: {summary['frames']} frames in {summary['wall_s']:.2f} s = "
          f"{summary['x_real_time']:.1f}x real time (method {args.method}"
          f"{', physics' if args.physics else ''}) -> {out}")
    if args.physics:
        refused = ', '.join(f"{r}: {v['frames']} frames of users {v['users']}"
                            for r, v in summary['refused'].items()) or 'none'
        print(f"  users: {summary['users']} ({summary['user_arrivals']} arrivals), characters: "
              f"{summary['characters']}, frames with a character: "
              f"{summary['character_frame_share']:.1%} of {summary['user_frames']}; refused: "
              f"{refused}")
    print(bone_length_text(summary['bone_lengths'], args.method))
    for name, acc in summary.get('accuracy', {}).items():
        print(f"  {name:>8}: MPJPE {acc['mpjpe_cm']:.2f} cm, Eq.18 {acc['eq18_cm']:.2f} cm "
              f"over {acc['frames']} frames")
    if summary.get('profile'):
        print(f"  user profile (the reconstruction's bone lengths): {summary['profile']}")
    print(f'  report: {report}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
