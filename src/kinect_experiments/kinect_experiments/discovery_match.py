"""``python -m kinect_experiments.discovery_match``: how long a publisher and a subscriber in two
bare rclpy processes, started ``--gap`` s apart, take to match, with Fast DDS's default discovery
and with the start's profile (``config/fastdds_startup.xml``, kinect_bringup.dds_profile).

    python -m kinect_experiments.discovery_match [--runs 4] [--gap 1.0]

Per run and start order (publisher first, subscriber first) it prints when the subscription's
``matched`` event came, in s after the later of the two processes had made its endpoint. The
wait it shows is not work: Fast DDS's default announces a participant 5 times, 0.1 s apart, then
every 3 s, and a participant started after another's first 0.5 s is often met by it only at
that one's next announcement. Uses ROS_DOMAIN_ID (set one of your own); the environment's
ROS_AUTOMATIC_DISCOVERY_RANGE applies (scripts/env.sh: LOCALHOST).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from typing import Dict, Optional

from kinect_bringup.dds_profile import PROFILE_VARS, profile_path, profile_var

# one process: make a node and a publisher or subscription on TOPIC, spin, print when matched
_CHILD = r'''
import json, sys, time
import rclpy
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String
role, topic, hold = sys.argv[1], sys.argv[2], float(sys.argv[3])
ctx = rclpy.Context()
rclpy.init(context=ctx)
node = rclpy.create_node('discovery_match_' + role, context=ctx)
got = {}
def matched(_info):
    got.setdefault('matched', time.time())
if role == 'pub':
    node.create_publisher(String, topic, 10,
                          event_callbacks=PublisherEventCallbacks(matched=matched))
else:
    node.create_subscription(String, topic, lambda m: None, 10,
                             event_callbacks=SubscriptionEventCallbacks(matched=matched))
print(json.dumps(dict(role=role, made=time.time())), flush=True)
ex = SingleThreadedExecutor(context=ctx)
ex.add_node(node)
end = time.time() + hold
# the subscriber ends once matched; the publisher stays until it is stopped (leaving at its own
# match could take it away before the subscriber has matched it)
while time.time() < end and (role == 'pub' or 'matched' not in got):
    ex.spin_once(timeout_sec=0.01)
    if 'matched' in got and not got.get('said'):
        print(json.dumps(dict(role=role, matched=got['matched'])), flush=True)
        got['said'] = True
rclpy.try_shutdown(context=ctx)
'''


def one_run(first: str, gap: float, env: Dict[str, str], hold: float = 8.0) -> Optional[float]:
    """Seconds from the later endpoint's creation to the subscription's match, or None."""
    topic = f'/discovery_match_{os.getpid()}_{time.monotonic_ns()}'
    second = 'sub' if first == 'pub' else 'pub'
    procs = [subprocess.Popen([sys.executable, '-c', _CHILD, first, topic, str(hold + gap)],
                              env=env, stdout=subprocess.PIPE, text=True)]
    time.sleep(gap)
    procs.append(subprocess.Popen([sys.executable, '-c', _CHILD, second, topic, str(hold)],
                                  env=env, stdout=subprocess.PIPE, text=True))
    out = {'pub': {}, 'sub': {}}
    sub = procs[0] if first == 'sub' else procs[1]
    pub = procs[1] if first == 'sub' else procs[0]
    sub_out, _ = sub.communicate(timeout=hold + gap + 60)
    pub.terminate()   # (SIGTERM: rclpy's handler shuts it down)
    pub_out, _ = pub.communicate(timeout=60)
    for line in (sub_out + pub_out).splitlines():
        if line.startswith('{'):
            r = json.loads(line)
            out[r['role']].update(r)
    if 'matched' not in out['sub'] or 'made' not in out['pub']:
        return None
    return out['sub']['matched'] - max(out['pub']['made'], out['sub']['made'])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog='discovery_match', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--runs', type=int, default=4, help='runs per start order and profile')
    p.add_argument('--gap', type=float, default=1.0,
                   help='seconds between the two processes\' starts')
    args = p.parse_args(argv)
    base = {k: v for k, v in os.environ.items() if k not in PROFILE_VARS}
    profile = profile_path()
    if profile is None:
        print('discovery_match: no config/fastdds_startup.xml (run make setup)', file=sys.stderr)
        return 1
    cases = {'Fast DDS default': base,
             'start profile': dict(base, **{profile_var(base): str(profile)})}
    print(f'ROS_AUTOMATIC_DISCOVERY_RANGE={os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "")} '
          f'ROS_DOMAIN_ID={os.environ.get("ROS_DOMAIN_ID", "0")} gap {args.gap:g} s; '
          'matched, s after the later endpoint was made:')
    for label, env in cases.items():
        for first in ('pub', 'sub'):
            got = [one_run(first, args.gap, env) for _ in range(args.runs)]
            shown = ' '.join('never' if g is None else f'{g:.2f}' for g in got)
            ok = [g for g in got if g is not None]
            med = f'median {statistics.median(ok):.2f}' if ok else ''
            print(f'  {label:16s} {first} first: {shown}  {med}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
