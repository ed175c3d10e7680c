#!/usr/bin/env bash
# Unpack the hri_msgs release sources (REP-155's messages) for colcon, checked against SHA256SUMS.
#   usage: unpack.sh DIR    -> prints the directory colcon builds (DIR/hri_msgs-<version>)
# Idempotent: an unpacked copy of the same tarball is kept. scripts/setup.sh calls it when the
# ROS 2 underlay has no hri_msgs of its own.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
dest=${1:?usage: unpack.sh DIR}
tarball=$(cd "$here" && ls hri_msgs-*.tar.gz)
(cd "$here" && sha256sum --quiet -c SHA256SUMS) >&2 ||
  { echo "unpack.sh: $here/$tarball does not match SHA256SUMS" >&2; exit 1; }
out="$dest/${tarball%.tar.gz}"
sum=$(sha256sum "$here/$tarball" | cut -c1-16)
if [ ! -f "$out/.unpacked" ] || [ "$(cat "$out/.unpacked")" != "$sum" ]; then
  rm -rf "$out" && mkdir -p "$dest"
  tar -xzf "$here/$tarball" -C "$dest"
  echo "$sum" > "$out/.unpacked"
fi
echo "$out"
