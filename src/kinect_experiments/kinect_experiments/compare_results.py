"""``ros2 run kinect_experiments compare_results BEFORE.json AFTER.json``: field by field, two outputs
of `make evaluate` (table4.json, table3.json, ...) or `real_loso` (real_loso.json), e.g. before and
after a change that must not change behaviour.

Wall-clock fields (processing times, dates) are left out (keys matching TIMING); every other number
must be equal (floats within 1e-9 relative). Prints each difference and a summary; exit 1 when any
differs."""
import argparse
import json
import math
import re
import sys

# wall-clock fields (processing time per frame, dates); figures computed from the data, e.g. the
# cross-correlation latency_ms, are compared
TIMING = re.compile(r'^(time|times|timings|timings_ms|ms_per_frame|frame_ms|correction_ms|'
                    r'correction_ms_per_frame|search_ms_per_query|seconds|wall_s|elapsed_s|date|'
                    r'date_utc|commit|code)$|wall', re.I)


def walk(a, b, path, out, count):
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if TIMING.search(str(k)):
                continue
            if k not in a or k not in b:
                out.append(f'{path}/{k}: only in {"after" if k not in a else "before"}')
                continue
            walk(a[k], b[k], f'{path}/{k}', out, count)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out.append(f'{path}: length {len(a)} != {len(b)}')
            return
        for i, (x, y) in enumerate(zip(a, b)):
            walk(x, y, f'{path}[{i}]', out, count)
    else:
        count[0] += 1
        if isinstance(a, float) and isinstance(b, float):
            if (math.isnan(a) and math.isnan(b)) or a == b \
                    or abs(a - b) <= 1e-9 * max(abs(a), abs(b)):
                return
        elif a == b:
            return
        out.append(f'{path}: {a!r} != {b!r}')


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog='compare_results', description=__doc__.split('\n\n')[0],
                                epilog=__doc__.split('\n\n')[1])
    p.add_argument('before', help='JSON output before the change')
    p.add_argument('after', help='JSON output after the change')
    args = p.parse_args(argv)
    try:
        with open(args.before) as fa, open(args.after) as fb:
            a, b = json.load(fa), json.load(fb)
    except (OSError, ValueError) as e:
        print(f'[ERROR] compare_results: {e}', file=sys.stderr)
        return 2
    out, count = [], [0]
    walk(a, b, '', out, count)
    for line in out[:60]:
        print('DIFF', line)
    print(f'{args.before} vs {args.after}: {count[0]} fields compared, {len(out)} differ')
    return 1 if out else 0


if __name__ == '__main__':
    sys.exit(main())
