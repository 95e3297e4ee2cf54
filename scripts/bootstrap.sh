#!/usr/bin/env bash
# Create or refresh the virtualenv at .venv/ with everything the project needs.
# Idempotent: a second run only compares a stamp and returns.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/.venv"
stamp="$venv/.rozyn-stamp"
want="$(cat "$root/requirements.txt" "$root/requirements-dev.txt" "$root/setup.py" | sha256sum | cut -c1-16)"

if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] && [ -x "$venv/bin/rozyn" ]; then
  exit 0
fi

python=""
for candidate in python3.12 python3.11 python3; do
  if command -v "$candidate" >/dev/null 2>&1 &&
     "$candidate" -c 'import sys; sys.exit(not (3, 11) <= sys.version_info[:2] <= (3, 12))' 2>/dev/null; then
    python="$candidate"
    break
  fi
done
if [ -z "$python" ]; then
  echo "error: Python 3.11 or 3.12 is needed (the ROS 2 Jazzy wheels exist for those)" >&2
  exit 1
fi

echo "Setting up $venv (first run: about a minute) ..." >&2
log="$(mktemp)"
trap 'rm -f "$log"' EXIT
install() {
  "$venv/bin/python" -m pip install --disable-pip-version-check "$@" >>"$log" 2>&1 || {
    cat "$log" >&2
    echo "error: pip install $* failed (log above)" >&2
    exit 1
  }
}
[ -x "$venv/bin/python" ] || "$python" -m venv "$venv"
install --upgrade pip
install -r "$root/requirements-dev.txt"
install --no-deps -e "$root"
echo "$want" > "$stamp"
echo "Ready: $venv" >&2
