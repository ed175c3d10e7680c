"""``recover_bag``: rewrite a cut recording (a recorder killed with SIGKILL, a power cut, a file
copied while it was being written, a truncated download) into a complete, indexed MCAP bag.

    ros2 run kinect_bringup recover_bag out/run.mcap out/run_recovered.mcap

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
    p.add_argument('input', help='the cut or unfinished .mcap file')
    p.add_argument('output', nargs='?', default=None,
                   help='the complete bag to write (default: <input>_recovered.mcap)')
    args = p.parse_args(argv)
    src = Path(args.input)
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


if __name__ == '__main__':
    sys.exit(main())
