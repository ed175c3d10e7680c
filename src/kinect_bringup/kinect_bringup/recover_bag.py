"""``recover_bag``: rewrite a cut recording (a recorder killed with SIGKILL, a power cut, a file
copied while it was being written, a truncated download) into a complete, indexed MCAP bag.

    ros2 run kinect_bringup recover_bag out/run.mcap out/run_recovered.mcap
    ros2 run kinect_bringup recover_bag out/day out/day_recovered   # a split recording's folder

A split recording (a folder of pieces, the recorder's ``split_size_mb`` / ``split_duration_s``) is
rewritten piece by piece into a new folder with the same names: the finished pieces copied, the
cut one (the piece being written when the recorder died) completed.

Every complete message of the input is kept with its topic, type, times and sequence number; what
follows the last complete record is lost (the command says how much). A complete bag is copied
as it is. The output opens in ``ros2 bag info``/``play``, Foxglove and every tool of this project
without a warning. See docs/recovery.md.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from skeleton_core.bagio import BagError, bag_topics, recover


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog='recover_bag', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('input', help='the cut or unfinished .mcap file, or the folder of a split '
                   'recording')
    p.add_argument('output', nargs='?', default=None,
                   help='the complete bag to write (default: <input>_recovered.mcap; for a '
                   'folder, the folder <input>_recovered)')
    args = p.parse_args(argv)
    src = Path(args.input)
    if src.is_dir():
        return _recover_folder(src, Path(args.output) if args.output else
                               src.with_name(src.name + '_recovered'))
    out = Path(args.output) if args.output else src.with_name(src.stem + '_recovered.mcap')
    try:
        n, cut = recover(src, out, warn=lambda text: None)
        topics = bag_topics(out)
    except BagError as e:
        print(f'recover_bag: error: {e}', file=sys.stderr)
        return 1
    if cut is None:
        print(f'recover_bag: {src} was complete: copied {n} messages to {out}')
    else:
        lost = cut.size - cut.offset
        print(f'recover_bag: {src} is truncated at byte {cut.offset} of {cut.size}: '
              f'{n} complete messages -> {out} ({lost} bytes after the last complete record '
              f'are lost)')
    for topic, (msgtype, count) in sorted(topics.items()):
        print(f'  {topic}: {count} x {msgtype}')
    return 0


def _recover_folder(src: Path, out: Path) -> int:
    from skeleton_core.bag_split import bag_pieces, pieces_topics
    from skeleton_core.bagio import BagError, recover
    try:
        pieces = bag_pieces(src)
        if out.resolve() == src.resolve():
            raise BagError(f'the output must be another folder than {src}')
        out.mkdir(parents=True, exist_ok=True)
        written = []
        for piece in pieces:
            n, cut = recover(piece, out / piece.name, warn=lambda text: None)
            written.append(out / piece.name)
            if cut is not None:
                print(f'recover_bag: {piece} is truncated at byte {cut.offset} of {cut.size}: '
                      f'{n} complete messages -> {out / piece.name} ({cut.size - cut.offset} '
                      f'bytes after the last complete record are lost)')
        topics = pieces_topics(written)
    except BagError as e:
        print(f'recover_bag: error: {e}', file=sys.stderr)
        return 1
    print(f'recover_bag: {len(pieces)} pieces of {src} -> {out}')
    for topic, (msgtype, count) in sorted(topics.items()):
        print(f'  {topic}: {count} x {msgtype}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
