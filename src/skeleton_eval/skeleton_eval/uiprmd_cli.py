"""``ros2 run skeleton_eval import_uiprmd``: UI-PRMD Kinect recordings -> MCAP bags.

    ros2 run skeleton_eval import_uiprmd --src ../shared/kinect/ui-prmd --out cache/uiprmd
    ros2 run skeleton_eval import_uiprmd --src ../shared/kinect/ui-prmd --calibrate

One bag per repetition, ``<out>/mMM_sSS_eEE.mcap``: ``skeleton_msgs/msg/SkeletonArray`` at 30 Hz on
``/kinect/skeletons`` (one skeleton, user_id 1, frame ``kinect_link``: REP-103 axes of the sensor,
origin ``--sensor-height`` (default 0.8 m, nominal) above the floor, see
:mod:`skeleton_data.uiprmd`) with monotonic stamps starting at
``--start-sec``; where a Vicon file exists, the marker-derived joint centres registered into the
same frame on ``/kinect/ground_truth`` with the same stamps (frames the Vicon recording does not
cover have no ground-truth message). ``<out>/import_report.json`` lists the clips written, the
per-session registration (rotation, translation, lags, residual per joint) and every skipped file
with the reason. Malformed files are reported and skipped; the rest continue.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from skeleton_core.bagio import BagWriter
from skeleton_core.conversions import frames_to_array_msg
from skeleton_core.model import HAND_LEFT, HAND_RIGHT, NOT_TRACKED, NUM_JOINTS, TRACKED
from skeleton_core.tracker import write_to_bag
from skeleton_data.uiprmd import TRACKER, clip_frames
from .paired import load_dataset

SKELETON_TOPIC = '/kinect/skeletons'
DEFAULT_SENSOR_HEIGHT = 0.8  # m: config/sensor_model.yaml placement.sensor_height_m, physics node
GROUND_TRUTH_TOPIC = '/kinect/ground_truth'


def _int_list(text, prefix):
    if not text:
        return None
    out = set()
    for part in text.split(','):
        part = part.strip().lower().lstrip(prefix)
        if part:
            out.add(int(part))
    return out


def write_clip_bag(path, rc, start_ns: int, user_id: int = 1, frame_id: str = 'kinect_link'):
    """Write one :class:`~skeleton_eval.paired.RealClip` to an MCAP bag; returns message counts."""

    frames = clip_frames(rc.kinect, start_ns, user_id, frame_id)
    n_sk = n_gt = 0
    tmp = Path(str(path) + '.part')
    with BagWriter(tmp) as bag:
        if frames:   # the tracker travels with the data (skeleton_core.tracker)
            write_to_bag(bag, TRACKER, frames[0].stamp_ns)
        for i, f in enumerate(frames):
            bag.write(SKELETON_TOPIC, frames_to_array_msg([f], f.stamp_ns, frame_id), f.stamp_ns)
            n_sk += 1
            if rc.reference is not None and np.isfinite(rc.reference[i]).all():
                # the hands are not scored (the Kinect's are extrapolated, not recorded: as in
                # skeleton_eval.real_eval): NOT_TRACKED in the truth, left out by process_bag
                state = np.full(NUM_JOINTS, TRACKED, np.uint8)
                state[[HAND_LEFT, HAND_RIGHT]] = NOT_TRACKED
                g = f.copy(positions=rc.reference[i].copy(), tracking_state=state)
                bag.write(GROUND_TRUTH_TOPIC, frames_to_array_msg([g], f.stamp_ns, frame_id),
                          f.stamp_ns)
                n_gt += 1
    tmp.replace(path)
    return n_sk, n_gt


def build_parser():
    ap = argparse.ArgumentParser(
        prog='import_uiprmd',
        description='Import UI-PRMD Kinect recordings (and the Vicon marker reference) into MCAP '
                    'bags of skeleton_msgs/SkeletonArray; optionally calibrate the sensor model.')
    ap.add_argument('--src', default='../shared/kinect/ui-prmd',
                    help='UI-PRMD folder (with Kinect/ and Vicon/) [%(default)s]')
    ap.add_argument('--out', default='cache/uiprmd', help='output folder [%(default)s]')
    ap.add_argument('--subjects', default='', help='e.g. s02,s04 (default: all)')
    ap.add_argument('--movements', default='', help='e.g. m01,m03 (default: all)')
    ap.add_argument('--repetitions', default='', help='e.g. 1,2 (default: all)')
    ap.add_argument('--no-reference', action='store_true', help='skip the Vicon reference')
    ap.add_argument('--start-sec', type=float, default=1.0,
                    help='header stamp of the first frame of every bag, s [%(default)s]')
    ap.add_argument('--user-id', type=int, default=1)
    ap.add_argument('--frame-id', default='kinect_link')
    ap.add_argument('--sensor-height', type=float, default=DEFAULT_SENSOR_HEIGHT,
                    help='nominal sensor height (m): the origin is put this far above the floor '
                         '(floor at z = -height); the true height was not recorded. Default: '
                         'the sensor model / physics node default; 0 = origin on the floor '
                         '[%(default)s]')
    ap.add_argument('--calibrate', action='store_true',
                    help='measure the real sensor error and print it next to the sensor model '
                         '(writes <out>/calibration.{md,json}); no bags unless --bags is given')
    ap.add_argument('--bags', action='store_true', help='with --calibrate: also write the bags')
    ap.add_argument('--reference-csv', action='store_true',
                    help='also write each clip\'s Vicon joint centres as a reference CSV on the '
                         'Vicon\'s own clock and frame (<clip>.reference.csv, not registered) and '
                         'a manifest pairs.csv (bag, reference, subject, session = subject and '
                         'movement): the input of build_correction --pairs, as a lab\'s own pairs')
    ap.add_argument('--quiet', action='store_true', help='no progress bar')
    return ap


def main(argv=None):
    args = build_parser().parse_args(argv)
    src = Path(args.src)
    if not src.is_dir():
        print(f'import_uiprmd: no UI-PRMD folder at {src}', file=sys.stderr)
        return 1
    out = Path(args.out)
    try:
        subjects = _int_list(args.subjects, 's')
        movements = _int_list(args.movements, 'm')
        reps = _int_list(args.repetitions, 'e')
    except ValueError as e:
        print(f'import_uiprmd: bad selection: {e}', file=sys.stderr)
        return 1
    progress = None
    if not args.quiet:
        try:
            from tqdm import tqdm

            def progress(it):
                return tqdm(it, desc='reading', unit='clip')
        except ImportError:
            progress = None
    clips, skipped, regs = load_dataset(src, subjects, movements, reps,
                                        with_reference=not args.no_reference,
                                        progress=progress, sensor_height=args.sensor_height)
    if not clips:
        print(f'import_uiprmd: no usable clips under {src}', file=sys.stderr)
        for p, why in skipped:
            print(f'  skipped {p}: {why}', file=sys.stderr)
        return 1
    out.mkdir(parents=True, exist_ok=True)
    written = []
    if not args.calibrate or args.bags:
        it = clips
        if not args.quiet and progress is not None:
            from tqdm import tqdm
            it = tqdm(clips, desc='writing', unit='bag')
        start_ns = int(round(args.start_sec * 1e9))
        pairs = ['bag,reference,subject,session']
        for rc in it:
            path = out / f'{rc.clip.name}.mcap'
            try:
                n_sk, n_gt = write_clip_bag(path, rc, start_ns, args.user_id, args.frame_id)
            except Exception as e:  # one bad clip must not stop the import
                skipped.append((str(path), f'cannot write bag: {e}'))
                continue
            # (the tracking-failure clips stay out of the manifest, as the UI-PRMD path
            # leaves them out of the fit)
            if args.reference_csv and rc.reference is not None \
                    and not rc.clip.is_tracking_failure:
                from skeleton_data import vicon
                from skeleton_data.reference import write_csv
                ref = vicon.load_reference(vicon.vicon_path_for(src, rc.clip.name))
                csv_path = write_csv(out / f'{rc.clip.name}.reference.csv',
                                     np.arange(len(ref)) / vicon.FRAME_RATE, ref)
                pairs.append(f'{path.name},{csv_path.name},s{rc.clip.subject:02d},'
                             f's{rc.clip.subject:02d}_m{rc.clip.movement:02d}')
            written.append({'clip': rc.clip.name, 'bag': str(path), 'skeletons': n_sk,
                            'ground_truth': n_gt,
                            'lag_s': None if rc.lag is None else round(rc.lag, 3)})
        if args.reference_csv:
            (out / 'pairs.csv').write_text('\n'.join(pairs) + '\n')
            print(f'import_uiprmd: {len(pairs) - 1} bag + reference CSV pairs in '
                  f'{out / "pairs.csv"}')
    report = {
        'src': str(src), 'frame_id': args.frame_id, 'sensor_height_m': args.sensor_height,
        'clips_read': len(clips), 'bags': written,
        'registration': {s: {'rotation': r.rotation.round(6).tolist(),
                             'translation_m': r.translation.round(4).tolist(),
                             'residual_per_joint_mm': (r.residual_per_joint * 1000).round(1)
                             .tolist()}
                         for s, r in regs.items()},
        'skipped': [{'file': p, 'reason': why} for p, why in skipped],
    }
    (out / 'import_report.json').write_text(json.dumps(report, indent=1))
    n_gt = sum(1 for w in written if w['ground_truth'])
    print(f'import_uiprmd: {len(clips)} clips read, {len(written)} bags written to {out} '
          f'({n_gt} with {GROUND_TRUTH_TOPIC}), {len(skipped)} skipped')
    for s, r in regs.items():
        res_mm = np.nanmean(r.residual_per_joint) * 1000
        print(f'  session {s}: registration residual {res_mm:.0f} mm '
              f'mean over joints, t = {np.round(r.translation, 3).tolist()} m')
    for p, why in skipped:
        print(f'  skipped {p}: {why}')
    if args.calibrate:
        from .calibration import calibrate, write_report
        result = calibrate(clips, regs, src=src)
        md = write_report(result, out)
        print(md)
    return 0


if __name__ == '__main__':
    sys.exit(main())
