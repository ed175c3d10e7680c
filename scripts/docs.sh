#!/usr/bin/env bash
# `make docs`: build the documentation site from docs/ into out/site/ with MkDocs in strict mode
# (mkdocs.yml): a broken link or anchor, a page missing from the navigation or a navigation entry
# without a page fails the build. MkDocs lives in a venv of its own (.venv-docs, pinned in
# requirements-docs.txt), created on first use; the ROS venv is not touched. With --check-generated
# it also fails when a generated reference page (parameters, launch arguments, commands) is stale.
#   scripts/docs.sh                      # build (a few seconds once the venv exists)
#   scripts/docs.sh --check-generated    # and check the generated pages (needs `make setup`)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
venv="$root/.venv-docs"
want="$(sha256sum requirements-docs.txt | cut -c1-16)"
if [ ! -f "$venv/.kp-stamp" ] || [ "$(cat "$venv/.kp-stamp")" != "$want" ]; then
  echo "[docs] creating .venv-docs (requirements-docs.txt)" >&2
  [ -x "$venv/bin/python" ] || "${PYTHON:-python3}" -m venv "$venv"
  "$venv/bin/python" -m pip install -q -r requirements-docs.txt ||
    { echo "[docs] pip could not install requirements-docs.txt into .venv-docs" >&2; exit 1; }
  echo "$want" > "$venv/.kp-stamp"
fi
if [ "${1:-}" = --check-generated ]; then
  scripts/run.sh ros2 run kinect_experiments param_docs --check ||
    { echo "[docs] a generated reference page is stale: run \`make params\`" >&2; exit 1; }
fi
rc=0
"$venv/bin/mkdocs" build --strict --config-file mkdocs.yml 2>&1 | { grep -v "^INFO" || true; } || rc=$?
[ "$rc" = 0 ] || { echo "[docs] the site did not build (warnings above are errors)" >&2; exit "$rc"; }
echo "[docs] site built: out/site/index.html" >&2
