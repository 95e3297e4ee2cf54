#!/usr/bin/env bash
# Regenerate the evidence of the likelihood refinement (docs/compare/*.md) with
# `rozyn compare`, 100 seeds per case, then docs/RESULTS.md (which includes them).
# About 30 minutes on 2 cores.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/bootstrap.sh"
cd "$root"
rozyn=.venv/bin/rozyn
out=docs/compare
mkdir -p "$out"
run() {  # name, then compare options
  local name=$1
  shift
  echo "rozyn compare $*  ->  $out/$name.md" >&2
  "$rozyn" compare "$@" --jobs "${JOBS:-2}" --quiet --format markdown > "$out/$name.md.tmp"
  mv "$out/$name.md.tmp" "$out/$name.md"
}
run issue6 --suite issue6
run acceptance-table5-1 --suite acceptance --methods rozyn,likelihood
run acceptance-second-vehicle --suite acceptance --vehicle-preset second --methods rozyn,likelihood
run robustness --suite robustness --methods rozyn,likelihood
run mismatch --suite mismatch --methods likelihood,rozyn
suspension="--noise 0.1 --methods likelihood,likelihood-nuisance"
# shellcheck disable=SC2086
{
  run stiffness-plus-10pct $suspension --stiffness-error 0.1
  run stiffness-minus-10pct $suspension --stiffness-error -0.1
  run damping-plus-10pct $suspension --damping-error 0.1
  run damping-minus-10pct $suspension --damping-error -0.1
}
.venv/bin/python scripts/study_report.py
