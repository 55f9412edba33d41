#!/usr/bin/env bash
# The wheel of what the repository holds: built from `git archive` of a commit (default HEAD),
# so that a file lying untracked in the checkout (a config of one's own in configs/robots, a
# scratch mission) never ends up in the shipped share/orccadd/. Usage:
#   packaging/build-wheel.sh [OUT_DIR [COMMIT]]    # OUT_DIR default dist/
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
out="$(realpath -m "${1:-$here/dist}")"
commit="${2:-HEAD}"
python="${PYTHON:-$here/.venv/bin/python}"
[ -x "$python" ] || python=python3
src="$(mktemp -d)"
trap 'rm -rf "$src"' EXIT
git -C "$here" archive --format=tar "$commit" | tar -x -C "$src"
mkdir -p "$out"
"$python" -m pip wheel --quiet --no-deps -w "$out" "$src"
ls "$out"/orccadd-*.whl
