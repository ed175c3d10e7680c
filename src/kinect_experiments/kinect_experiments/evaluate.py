"""``ros2 run kinect_experiments evaluate`` / ``make evaluate``: accuracy of every method on sensor-model
streams of the dev clips (Shum et al. 2013 Table III/IV, Fig. 8; Shum & Ho 2012 Fig. 5).

Writes ``<out>/<experiment>.md`` and ``<out>/<experiment>.json`` and prints the Markdown table and
the sensor model's noise statistics. No ROS graph is started (the methods are run in-process).

Examples::

    evaluate                                   # table4: all methods, classes a-e, dev clips
    evaluate --methods raw,holt,one_euro --source builtin --max-frames 300
    evaluate --experiment table3 --methods raw,C                     # calibrated user (T-pose)
    evaluate --experiment table3 --methods raw,C --calibration none  # no calibration segment
    evaluate --experiment fig5
    evaluate --experiment fig8 --methods C --params k,steps
    evaluate --tracker azure_kinect_bt         # the Azure Kinect body tracking's sensor model
    evaluate --perturb                         # raw and C, classes a-e, seeds 0-2, sensor model
                                               # noise/offset/occlusion/failure/tracked groups
                                               # 0.5x, 1.5x
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

from kinect_bringup.graph import preset_path, repo_root
from skeleton_core.geometry import normalize, retarget
from skeleton_core.model import standard_body
from . import fusion_eval, real_loso
from pose_reconstruction.methods import load_preset
from skeleton_eval import perturb as P
from skeleton_eval import evaluation as E
from skeleton_eval.clips import load_clips
from skeleton_eval.figures import FIG8_SWEEPS, _database_postures, fig5, fig8
from skeleton_eval.registry import available_methods, load_plugins
from skeleton_eval.report import calibration_text, to_json, to_markdown
from skeleton_eval.sensor_model import SensorModel
from skeleton_eval.sensor_params import tracker_params
from skeleton_eval.table3 import table3


def _parser():
    p = argparse.ArgumentParser(prog='evaluate', description=__doc__.split('\n\n')[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--methods', default='',
                   help='comma-separated method names (default: every registered method)')
    p.add_argument('--source', default='auto', choices=('auto', 'cmu', 'builtin'),
                   help='clips: CMU dev split from ../shared (auto falls back to built-ins)')
    p.add_argument('--scenarios', default='a,b,c,d,e',
                   help='sensor-model scenario classes (d: confident failures, e: small '
                        'persistent errors of TRACKED joints)')
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--max-frames', type=int, default=300,
                   help='frames (30 Hz) per clip; 0 = whole clips (default 300 = 10 s)')
    p.add_argument('--repeats', type=int, default=1,
                   help='run every clip N times with independent sensor noise/events (seed, seed+1..)')
    p.add_argument('--out', default='out/eval', help='output directory')
    p.add_argument('--experiment', default='table4',
                   choices=('table3', 'table4', 'fig5', 'fig8'))
    p.add_argument('--sensor-params', default=None,
                   help='sensor model YAML (default: config/sensor_model.yaml or built-ins)')
    p.add_argument('--tracker', default='', metavar='NAME',
                   help='the sensor model of this skeleton tracker (skeleton_core.tracker: e.g. '
                        'azure_kinect_bt, config/sensor_model_azure_kinect_bt.yaml) over '
                        '--sensor-params; default: the Kinect v1 model')
    p.add_argument('--params', default='',
                   help='fig8: comma-separated parameters to sweep (db_size,k,pca_dims,steps,'
                        'samples)')
    p.add_argument('--reference', default='input', choices=('input', 'truth'),
                   help='table3: score against the full input skeleton (paper) or the truth')
    p.add_argument('--calibration', default='tpose', choices=('tpose', 'standing', 'none'),
                   help='table3: before each clip the method sees --calibration-seconds of the '
                        'same user in a T-pose (default, the paper\'s calibrated user) or standing '
                        'pose with every joint tracked, not scored; none = the other joints are '
                        'hidden from the first frame')
    p.add_argument('--calibration-seconds', type=float, default=1.0,
                   help='table3: length of the calibration segment (s, at 30 Hz; default 1)')
    p.add_argument('--perturb', action='store_true',
                   help='robustness to the sensor model: the table (default methods raw,C, classes '
                        'a-d) for the nominal model and each parameter group scaled by each '
                        '--perturb-factors, for each --perturb-seeds (skeleton_eval.perturb)')
    p.add_argument('--perturb-seeds', default='0,1,2',
                   help='--perturb: sensor seeds (parameters were tuned on seed 0 only)')
    p.add_argument('--perturb-factors', default='0.5,1.5', help='--perturb: scale factors')
    p.add_argument('--perturb-groups', default='noise,offset,occlusion,failure,tracked',
                   help='--perturb: parameter groups (noise, offset, occlusion, failure, tracked)')
    p.add_argument('--method-params', default='', metavar='JSON',
                   help='table4 / --perturb / --real (C rows): parameter overrides per method, e.g. '
                        '\'{"C": {"plausibility": false, "smooth_lead": 0}}\'')
    p.add_argument('--preset', default='', metavar='NAME',
                   help='reconstruction preset (config/presets/NAME.yaml or a path, e.g. shum2013: '
                        'the papers\' variant) for methods A, B, C (and the C rows of --real); '
                        '--method-params override it')
    p.add_argument('--sensors', type=int, default=1,
                   help='N > 1: N sensor-model views (front, side at 90 deg, ...) fused '
                        '(pose_reconstruction.fusion): single-sensor raw and C against fused raw '
                        'and fused + C per class (docs/multi_sensor.md)')
    p.add_argument('--layout', default='front-side', choices=('front-side', 'diagonal'),
                   help='--sensors 2: front-side = sensor 1 in front of the user and sensor 2 on '
                        'the side (90 deg); diagonal = the two 90 deg apart at 45 deg either side '
                        'of the front (single-sensor rows: the front sensor alone either way)')
    p.add_argument('--quiet', action='store_true', help='no progress lines')
    p.add_argument('--real', nargs='?', const='auto', default=None, metavar='UIPRMD_DIR',
                   help='real-data mode: raw, holt, one_euro, C and C with the learned sensor '
                        'correction and user profiles on UI-PRMD-layout Kinect recordings against '
                        'their Vicon marker reference. Default dir ../shared/kinect/ui-prmd: '
                        'leave-one-subject-out; another dir (other subjects): the correction '
                        'learned from all development subjects (--methods: variants of '
                        'kinect_experiments.real_loso)')
    p.add_argument('--max-clips', type=int, default=0,
                   help='--real: clips per movement row, 0 = all')
    return p


def run_real(args) -> int:
    """``--real``: the development subjects (default folder) leave-one-subject-out; another
    folder (other subjects, same layout) with the correction learned from every development
    subject (kinect_experiments.real_loso)."""
    src = args.real
    shared = os.environ.get('KP_SHARED') or str((repo_root() or Path.cwd()).parent / 'shared')
    dev = Path(shared) / 'kinect' / 'ui-prmd'
    if src == 'auto':
        src = str(dev)
    argv = ['--src', src, '--out', args.out, '--max-clips', str(args.max_clips)]
    if args.methods:
        argv += ['--variants', args.methods]
    if args.quiet:
        argv.append('--quiet')
    if args.preset:
        argv += ['--preset', args.preset]
    if getattr(args, 'method_params', ''):
        over = json.loads(args.method_params)
        if not isinstance(over, dict) or set(over) - {'C'}:
            print('evaluate --real: --method-params takes {"C": {...}} (overrides of method C in '
                  'the C rows)', file=sys.stderr)
            return 2
        if over.get('C'):
            argv += ['--method-params', json.dumps(over['C'])]
    same = dev.is_dir() and Path(src).resolve() == dev.resolve()
    if not same:
        argv.append('--no-loso')  # other subjects: the correction from all development ones
    return real_loso.main(argv)


def _with_params(methods, text, preset: str = ''):
    """``methods`` with the ``--preset`` values (methods A, B, C) and the ``--method-params``
    overrides on top: (name, params, name) for those that get any."""
    over = json.loads(text) if text else {}
    if not isinstance(over, dict) or not all(isinstance(v, dict) for v in over.values()):
        raise ValueError('--method-params must be a JSON object of objects')
    unknown = set(over) - set(methods)
    if unknown:
        raise ValueError(f'--method-params names methods not run: {sorted(unknown)}')
    values = _preset(preset)
    if values:
        over = {m: {**values, **over.get(m, {})} if m in PRESET_METHODS else over.get(m)
                for m in methods}
        over = {m: v for m, v in over.items() if v is not None}
    return [(m, over[m], m) if m in over else m for m in methods]


# the methods a reconstruction preset applies to
PRESET_METHODS = ('A', 'B', 'C')


def _preset(name: str) -> dict:
    """The values of the preset ``name`` ('' = none); ValueError (one line) when it is missing
    or invalid."""
    if not name:
        return {}
    try:
        return load_preset(preset_path(name))
    except FileNotFoundError as exc:
        raise ValueError(str(exc)) from None


def run_perturb(args, dev_clips, source) -> int:
    try:
        seeds = [int(v) for v in args.perturb_seeds.split(',') if v]
        factors = [float(v) for v in args.perturb_factors.split(',') if v]
        groups = [g for g in args.perturb_groups.split(',') if g]
        bad = [g for g in groups if g not in P.GROUPS]
        if bad or not seeds or not factors or any(not f > 0 for f in factors):
            raise ValueError(f'unknown group(s) {bad}' if bad else 'need seeds and factors > 0')
    except ValueError as exc:
        print(f'evaluate: --perturb: {exc}', file=sys.stderr)
        return 2
    methods = [m for m in args.methods.split(',') if m] or ['raw', 'C']
    scenarios = [s for s in args.scenarios.split(',') if s]
    max_frames = args.max_frames if args.max_frames and args.max_frames > 0 else None

    def progress(label, seed):
        if not args.quiet:
            print(f'[evaluate] perturb {label} seed {seed}', file=sys.stderr)
    try:
        run_methods = _with_params(methods, args.method_params, args.preset)
    except ValueError as exc:
        print(f'evaluate: {exc}', file=sys.stderr)
        return 2
    res = P.run(run_methods, dev_clips, scenarios, seeds, factors, groups, max_frames,
                args.sensor_params, source, progress)
    res['method_params'] = args.method_params
    method = 'C' if 'C' in methods else methods[-1]
    md = P.to_markdown(res, method=method, reference='raw' if 'raw' in methods else methods[0])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / 'perturb.md').write_text(md)
    to_json(res, out / 'perturb.json')
    print(md)
    print(f'[evaluate] wrote {out / "perturb.md"} and {out / "perturb.json"}', file=sys.stderr)
    return 0


def run(argv=None) -> int:
    args = _parser().parse_args(argv)
    if args.real:
        return run_real(args)
    if args.tracker:
        try:
            args.sensor_params = tracker_params(args.tracker, args.sensor_params)
        except (ValueError, OSError) as exc:
            print(f'evaluate: --tracker: {exc}', file=sys.stderr)
            return 2
        print(f'[evaluate] sensor model of tracker {args.tracker}', file=sys.stderr)

    plugins = load_plugins()
    for mod, st in plugins.items():
        print(f'[evaluate] plug-in {mod}: {st}', file=sys.stderr)
    avail = available_methods()
    methods = [m for m in args.methods.split(',') if m] or avail
    unknown = [m for m in methods if m not in avail]
    if unknown:
        print(f'evaluate: unknown method(s) {", ".join(unknown)}; available: {", ".join(avail)}',
              file=sys.stderr)
        return 2
    scenarios = [s for s in args.scenarios.split(',') if s]
    max_frames = args.max_frames if args.max_frames and args.max_frames > 0 else None
    try:
        db_clips, dev_clips, source = load_clips(args.source, args.seed)
    except (FileNotFoundError, ValueError) as exc:
        print(f'evaluate: {exc}', file=sys.stderr)
        return 1
    print(f'[evaluate] data {source}: {len(dev_clips)} dev clips, methods {", ".join(methods)}',
          file=sys.stderr)

    def progress(method, key, clip):
        if not args.quiet:
            print(f'[evaluate] {method} {key} {clip}', file=sys.stderr)

    exp = args.experiment
    if args.sensors > 1:
        return fusion_eval.run(args, dev_clips)
    if args.perturb:
        return run_perturb(args, dev_clips, source)
    if exp == 'table4':
        try:
            methods = _with_params(methods, args.method_params, args.preset)
        except ValueError as exc:
            print(f'evaluate: {exc}', file=sys.stderr)
            return 2
        res = E.evaluate(methods, dev_clips, scenarios, seed=args.seed, max_frames=max_frames,
                         sensor_params=args.sensor_params, data_source=source, progress=progress,
                         repeats=args.repeats)
    elif exp == 'table3':
        try:
            methods = _with_params(methods, '', args.preset)
        except ValueError as exc:
            print(f'evaluate: {exc}', file=sys.stderr)
            return 2
        res = table3(methods, dev_clips, seed=args.seed, max_frames=max_frames,
                       sensor_params=args.sensor_params, data_source=source, progress=progress,
                       repeats=args.repeats, reference=args.reference,
                       calibration=args.calibration,
                       calibration_seconds=args.calibration_seconds)
        print(f'[evaluate] table3 {calibration_text(res)}', file=sys.stderr)
    elif exp == 'fig5':
        db = None
        try:
            from skeleton_data.database import load_or_build_default
            db = load_or_build_default(source='auto' if args.source == 'auto' else args.source)
        except Exception as exc:  # database module absent or failing: use the clips directly
            print(f'[evaluate] no motion database ({type(exc).__name__}: {exc}); '
                  f'using the database clips', file=sys.stderr)
        postures = _database_postures(db, db_clips)
        streams = E.make_streams(dev_clips, scenarios[:1], args.seed, max_frames,
                                 SensorModel(args.sensor_params, seed=args.seed))
        q = np.concatenate([s.positions for lst in streams.values() for s in lst])
        # queries as the database holds postures: normalised, retargeted to the standard body
        res = fig5(postures, retarget(normalize(q)[0], standard_body()))
        res['meta'] = E.run_meta(dev_clips, args.seed, SensorModel(args.sensor_params),
                              max_frames, source, {'query_scenario': scenarios[0]})
    else:  # fig8
        params = [p for p in args.params.split(',') if p] or list(FIG8_SWEEPS)
        bad = [p for p in params if p not in FIG8_SWEEPS]
        if bad:
            print(f'evaluate: unknown sweep(s) {bad}; known: {list(FIG8_SWEEPS)}', file=sys.stderr)
            return 2
        method = methods[0] if args.methods else ('C' if 'C' in avail else avail[-1])
        res = fig8(method, dev_clips, params, seed=args.seed,
                     max_frames=max_frames or 300, scenario=scenarios[0],
                     sensor_params=args.sensor_params, data_source=source, progress=progress)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    md = to_markdown(res)
    (out / f'{exp}.md').write_text(md)
    to_json(res, out / f'{exp}.json')
    print(md)
    print(f'[evaluate] wrote {out / (exp + ".md")} and {out / (exp + ".json")}', file=sys.stderr)
    return 0


def main(argv=None):
    try:
        code = run(argv)
    except KeyboardInterrupt:
        code = 130
    sys.exit(code)


if __name__ == '__main__':
    main()
