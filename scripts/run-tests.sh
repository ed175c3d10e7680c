#!/usr/bin/env bash
# The one test command (README, `make test`, .ci/run): bootstrap if needed, then pytest.
#   scripts/run-tests.sh [pytest args]      e.g. scripts/run-tests.sh -k reliability
#   ROS_DISTRO=kilted scripts/run-tests.sh  the same on ROS 2 Kilted (scripts/distro.sh)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
"$root/scripts/setup.sh"
set +u
# shellcheck disable=SC1091
source "$root/scripts/env.sh"
set -u
cd "$root"
# the numba kernels compiled once here, not by every node process of the first tests at once
python -m kinect_bringup.warm_kernels || echo "warm_kernels failed: the nodes compile their kernels themselves"
# each run gets its own DDS domain (conftest.py refines this per worker)
export ROS_DOMAIN_ID="${KP_TEST_DOMAIN_ID:-$(( 1 + $$ % 100 ))}"
failed_file="$(mktemp)"
trap 'rm -f "$failed_file"' EXIT
set +e
# no path given: pytest.ini's testpaths (tests/ and every package's src/<pkg>/test/); a path runs only that
KP_FAILED_FILE="$failed_file" python -m pytest "$@"
rc=$?
set -e
[ "$rc" = 5 ] && { echo "pytest: no tests were collected"; exit 1; }
# A few failures (at most KP_RERUN_MAX, default 3; 0 = never) are run once more, alone: most tests
# start processes and talk over DDS, whose timing a loaded machine can upset. A test that fails
# again fails the run; one that passes is named as flaky, never hidden. More failures than that:
# something is really broken, no rerun.
mapfile -t failed < "$failed_file"
max="${KP_RERUN_MAX:-3}"
if [ "$rc" = 1 ] && [ "${#failed[@]}" -ge 1 ] && [ "${#failed[@]}" -le "$max" ]; then
  echo "=== run-tests: ${#failed[@]} test(s) failed; running them once more, alone: ${failed[*]} ==="
  set +e
  KP_FAILED_FILE="$failed_file" python -m pytest "${failed[@]}"
  rc=$?
  set -e
  if [ "$rc" = 0 ]; then
    echo "=== run-tests: FLAKY (failed, then passed alone): ${failed[*]} ==="
  else
    echo "=== run-tests: failed again: $(tr '\n' ' ' < "$failed_file")==="
  fi
fi
exit "$rc"
