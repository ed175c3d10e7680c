#!/usr/bin/env bash
# CI's budget guard (make bench-guard): a short A/B of the graph against the previous landed
# commit -- this tree (B) and HEAD^ (A, built beside it in cache/ab/), 2 users as ros2 launch runs
# it, alternated A B A B A B -- that fails only on a large regression seen every time: an
# output's p95 or the graph's CPU more than 1.5x AND 5 ms / 10 points worse than the reference in
# 3 of 3 alternations, or frames dropped in every run where the reference dropped none
# (kinect_experiments.ab.regressions). Not a timed test: one slow run of a shared machine cannot
# fail it. It says so and passes when it cannot judge: no HEAD^ in the clone (a shallow clone:
# fetch with depth >= 2), the same source tree as HEAD^, or a machine busy before a run
# (the load guard, after waiting up to 60 s) or slower than the runs already taken (the speed
# guard, likewise). About 2-3 minutes (+ the reference's first build).
#   scripts/bench-guard.sh            KP_BENCH_REF=<commit> scripts/bench-guard.sh
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
ref="${KP_BENCH_REF:-HEAD^}"
say() { echo "[bench-guard] $*"; }
if ! git rev-parse --verify -q "$ref^{commit}" >/dev/null; then
  say "skipped: no commit $ref in this clone (a shallow clone has no history: git fetch --deepen=1)"
  exit 0
fi
if [ "$(git rev-parse "$ref^{tree}")" = "$(git rev-parse 'HEAD^{tree}')" ] && git diff --quiet HEAD -- src; then
  say "skipped: the source tree is the same as $ref's"
  exit 0
fi
scripts/run.sh ros2 run kinect_experiments bench --against "$ref" --users 2 --seconds 5 \
  --warmup 3 --alternations 3 --fail-ratio 1.5 --load-wait 60 --slow-wait 60 \
  --out "$root/out/bench-guard"
rc=$?
case $rc in
  0) say "passed: no output or CPU regression against $ref (out/bench-guard/ab.md)" ;;
  1) say "FAILED: a regression against $ref in every alternation (out/bench-guard/ab.md)"; exit 1 ;;
  3) say "skipped: the machine was busy or its speed changed (the load or speed guard refused; nothing judged)" ;;
  *) say "not judged: the comparison did not run (exit $rc; out/bench-guard/*.log)" ;;
esac
exit 0
