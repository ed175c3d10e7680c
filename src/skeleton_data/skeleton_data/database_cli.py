"""``ros2 run skeleton_data build_db`` / ``make build-db``: build (or fetch from the cache) the
motion database and print what went into it.

Examples::

    build_db                                   # default: CMU five-class database clips, cached
    build_db --source builtin                  # the built-in motions (no ../shared needed)
    build_db --all-clips --mirror --no-filter --out out/big_db.npz   # 53k postures, scale tests
    build_db --bvh-dir DIR --joint-map config/joint_maps/generic_bvh.yaml   # CMU + a lab's BVH
    build_db --marker-dir ../shared/kinect/ui-prmd/Vicon/Positions --exclude 'm*_s05_*'
                                               # CMU + Plug-in-Gait marker clips of s01-s04
"""
from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from . import database, mocap, motions
from .joint_map import JointMapError, load_joint_map, maps_dir


def _parser():
    p = argparse.ArgumentParser(
        prog='build_db', description='Build the motion database (Shum et al. 2013 Sec. V-A): '
        'normalise, retarget to the standard body, filter near-duplicate postures.')
    p.add_argument('--source', choices=('auto', 'cmu', 'builtin', 'none'), default='auto',
                   help='auto: CMU when the shared data folder exists, else built-in motions; '
                        'none: only the clips of --bvh-dir / --marker-dir')
    p.add_argument('--cmu-dir', type=Path, default=None,
                   help='folder of CMU cgspeed BVH files with index.csv '
                        '(default: <shared>/mocap/cmu; implies --source cmu)')
    p.add_argument('--classes', default=','.join(mocap.FIVE_CLASSES),
                   help='comma-separated CMU classes to use (default: the five paper classes)')
    p.add_argument('--all-clips', action='store_true',
                   help="use every clip: all classes including 'other', database and dev parts")
    p.add_argument('--mirror', action='store_true',
                   help='add left-right mirrored copies of every clip (doubles the frames)')
    p.add_argument('--threshold', type=float, default=None,
                   help=f'filter threshold, m^2 summed over joints (default '
                        f'{database.DEFAULT_THRESHOLD})')
    p.add_argument('--no-filter', action='store_true', help='keep every posture')
    g = p.add_argument_group('clips in other conventions, through a joint map (added beside '
                             '--source; every frame, no dev split)')
    g.add_argument('--bvh-dir', type=Path, default=None,
                   help='folder of BVH files (default map: config/joint_maps/generic_bvh.yaml)')
    g.add_argument('--marker-dir', type=Path, default=None,
                   help='folder of marker files (default map: config/joint_maps/plug_in_gait.yaml)')
    g.add_argument('--joint-map', type=Path, default=None,
                   help='joint-map YAML for --bvh-dir or --marker-dir')
    g.add_argument('--include', action='append', default=[], metavar='PATTERN',
                   help='only files whose name matches this shell pattern (repeatable)')
    g.add_argument('--exclude', action='append', default=[], metavar='PATTERN',
                   help="skip files whose name matches, e.g. 'm*_s05_*' (repeatable)")
    g.add_argument('--check', action='store_true',
                   help='before building, print per clip of --bvh-dir / --marker-dir the mapped '
                        "skeleton's segment lengths against the standard body")
    p.add_argument('--out', type=Path, default=None,
                   help='write the database here (default: the cache, keyed by the inputs, and '
                        "the nodes' default file <cache>/motion_db.npz)")
    p.add_argument('--cache-dir', type=Path, default=None,
                   help='cache folder (default $KINECT_POSTURE_CACHE or <repo>/cache)')
    p.add_argument('--rebuild', action='store_true', help='ignore a cached database')
    p.add_argument('--no-progress', action='store_true', help='no progress bars')
    return p


def _bar(total, desc, enabled):
    if not enabled:
        return None
    try:
        from tqdm import tqdm
        return tqdm(total=total, desc=desc, unit='clip', leave=False)
    except ImportError:  # pragma: no cover
        return None


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format='%(message)s')
    progress = not args.no_progress and sys.stderr.isatty()
    threshold = 0.0 if args.no_filter else (
        database.DEFAULT_THRESHOLD if args.threshold is None else args.threshold)
    if threshold < 0:
        print('build_db: --threshold must be >= 0', file=sys.stderr)
        return 2
    classes = None if args.all_clips else tuple(
        c.strip() for c in args.classes.split(',') if c.strip())
    if classes is not None:
        bad = [c for c in classes if c not in mocap.MOTION_CLASSES]
        if bad:
            print(f'build_db: unknown class(es) {", ".join(bad)}; known: '
                  f'{", ".join(mocap.MOTION_CLASSES)}', file=sys.stderr)
            return 2
    split = 'all' if args.all_clips else 'database'
    mapped = []
    if args.bvh_dir is not None and args.marker_dir is not None:
        print('build_db: give --bvh-dir or --marker-dir, not both (one joint map)', file=sys.stderr)
        return 2
    folder = args.bvh_dir or args.marker_dir
    if folder is None and (args.joint_map or args.include or args.exclude):
        print('build_db: --joint-map/--include/--exclude need --bvh-dir or --marker-dir',
              file=sys.stderr)
        return 2
    if folder is not None:
        jm_path = args.joint_map or maps_dir() / (
            'generic_bvh.yaml' if args.bvh_dir is not None else 'plug_in_gait.yaml')
        try:
            jm = load_joint_map(jm_path)
        except JointMapError as e:
            print(f'build_db: {e}', file=sys.stderr)
            return 2
        want = 'bvh' if args.bvh_dir is not None else 'markers'
        if jm.format != want:
            print(f'build_db: {jm_path} is a {jm.format} map; --{want.replace("markers", "marker")}'
                  f'-dir needs a {want} map', file=sys.stderr)
            return 2
        if not folder.is_dir():
            print(f'build_db: folder {folder} not found', file=sys.stderr)
            return 1
        mapped = [database.MappedSource(folder, Path(jm_path), tuple(args.include),
                                        tuple(args.exclude))]
        if not mapped[0].files():
            print(f'build_db: no {want} files selected in {folder}', file=sys.stderr)
            return 1
        if args.check:
            from .joint_map import segment_table
            rows = []
            for f in mapped[0].files():
                try:
                    rows.append((f.name, mocap.load_mapped_clip(f, jm).positions))
                except (mocap.MocapError, OSError) as e:
                    print(f'check: {f.name}: {e}')
                except JointMapError as e:
                    print(f'build_db: {e}', file=sys.stderr)
                    return 2
            print(segment_table(rows))
            print()
    elif args.check:
        print('build_db: --check needs --bvh-dir or --marker-dir', file=sys.stderr)
        return 2
    if args.source == 'none' and not mapped:
        print('build_db: --source none needs --bvh-dir or --marker-dir', file=sys.stderr)
        return 2
    try:
        if args.cmu_dir is not None or args.out is not None:
            # explicit build (not the cached default)
            source = args.source
            cmu_dir = args.cmu_dir
            if cmu_dir is None and source not in ('builtin', 'none'):
                shared = database.default_shared_dir()
                cmu_dir = shared / 'mocap' / 'cmu' if shared is not None else None
                if source == 'auto':
                    source = 'cmu' if cmu_dir is not None and cmu_dir.is_dir() else 'builtin'
            elif cmu_dir is not None:
                source = 'cmu'
            skipped = []
            t0 = time.perf_counter()
            if source == 'cmu':
                if cmu_dir is None or not cmu_dir.is_dir():
                    print(f'build_db: CMU folder {cmu_dir} not found', file=sys.stderr)
                    return 1
                n_files = len(list(cmu_dir.glob('*.bvh')))
                bar = _bar(n_files, 'loading BVH', progress)
                cb = (lambda name: bar.update(1)) if bar is not None else None
                clips = mocap.load_cmu_clips(cmu_dir, classes, skipped=skipped, progress=cb)
                if bar is not None:
                    bar.close()
                db_clips, dev_clips = mocap.split_clips(clips)
            elif source == 'builtin':
                db_clips, dev_clips = motions.builtin_split()
            else:
                db_clips, dev_clips = [], []
            sel = list(db_clips) + (list(dev_clips) if split == 'all' else [])
            sel += database.load_mapped_sources(mapped, skipped)
            if not sel:
                print('build_db: no usable clips', file=sys.stderr)
                return 1
            if args.mirror:
                sel += [mocap.mirror_clip(c) for c in sel]
            t_load = time.perf_counter() - t0
            db, st = database.build_database(sel, threshold=threshold, progress=progress,
                                             meta={'source': '+'.join(
                                                 [source] * (source != 'none')
                                                 + [m.joint_map.stem for m in mapped]),
                                                 'skipped': skipped})
            out = args.out or (database.default_cache_dir() / f'motion_db_{source}_custom.npz')
            db.save(out)
            st.update(cache_hit=False, path=str(out), skipped=skipped, load_seconds=t_load)
        else:
            st = {}
            # the cached build, written to the fixed file every node's default `database`
            # loads (nodes never build one)
            db = database.build_default(
                source=args.source, cache_dir=args.cache_dir, threshold=threshold,
                classes=classes, split=split, mirror=args.mirror, progress=progress,
                rebuild=args.rebuild, stats=st, mapped=mapped)
            st['default_path'] = str(database.default_path())
    except (database.DatabaseError, FileNotFoundError, ValueError) as e:
        print(f'build_db: {e}', file=sys.stderr)
        return 1
    for name, reason in st.get('skipped') or []:
        print(f'skipped {name}: {reason}')
    print(f"source: {db.meta.get('source', '?')}; clips: {len(db.class_names)}; "
          f"threshold: {db.meta.get('threshold')} m^2")
    print(f"postures: {st.get('frames_before', db.meta.get('frames_before'))} before filtering -> "
          f"{len(db)} after")
    print('per class (postures, SD of upper / lower body positions in cm, cf. Shum 2013 Table I):')
    for cls, v in database.class_statistics(db).items():
        print(f"  {cls:16s} {v['postures']:6d}   {v['upper_sd_cm']:5.1f} / {v['lower_sd_cm']:5.1f}")
    if st.get('cache_hit'):
        print(f"cache hit: {st['path']}")
    else:
        print(f"built in {st.get('seconds', float('nan')):.2f} s"
              + (f" (+{st['load_seconds']:.2f} s loading)" if 'load_seconds' in st else ''))
        print(f"written: {st['path']}")
    if st.get('default_path'):
        print(f"the nodes' default database: {st['default_path']}")
    return 0


if __name__ == '__main__':  # pragma: no cover
    sys.exit(main())
