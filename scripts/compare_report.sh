#!/usr/bin/env bash
# Regenerate the comparison evidence (docs/compare/*.md) with `rozyn compare`, both cars,
# then docs/results.md (which includes the tables) from the studies in out/: run
# `scripts/study_report.py --run` and `scripts/refined_report.py --run` once first.
# About 75 minutes on 2 cores (the full car's 1000-road runs are half of it).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/bootstrap.sh"
cd "$root"
rozyn=.venv/bin/rozyn
out=docs/compare
mkdir -p "$out"
run() {  # name, then compare options: a markdown table per case
  local name=$1
  shift
  echo "rozyn compare $*  ->  $out/$name.md" >&2
  "$rozyn" compare "$@" --jobs "${JOBS:-2}" --quiet --format markdown > "$out/$name.md.tmp"
  mv "$out/$name.md.tmp" "$out/$name.md"
}
run_text() {  # name, title, then compare options: the text tables under a heading and the command
  local name=$1 title=$2
  shift 2
  echo "rozyn compare $*  ->  $out/$name.md" >&2
  {
    printf '# %s\n\n`rozyn compare %s`\n\n```text\n' "$title" "$*"
    "$rozyn" compare "$@" --jobs "${JOBS:-2}" --quiet
    printf '```\n'
  } > "$out/$name.md.tmp"
  mv "$out/$name.md.tmp" "$out/$name.md"
}
run methods --suite methods
run acceptance-table5-1 --suite acceptance --methods rozyn,likelihood
run acceptance-second-vehicle --suite acceptance --vehicle-preset second --methods rozyn,likelihood
run robustness --suite robustness --methods rozyn,likelihood
run mismatch --suite mismatch --methods likelihood,rozyn
full="--model full"
# shellcheck disable=SC2086
{
  run_text full-acceptance-table5-1 "The full car's acceptance cases, Table 5-1 extended" $full --suite acceptance --seeds 1-100
  run_text full-acceptance-second "The full car's acceptance cases, a second full car" $full --suite acceptance \
    --vehicle-preset second --seeds 1-100
  run_text full-acceptance-table5-1-1000-seeds "The full car's acceptance cases on 1000 roads, Table 5-1 extended" \
    $full --suite acceptance --seeds 1-1000 --methods likelihood
  run_text full-acceptance-second-1000-seeds "The full car's acceptance cases on 1000 roads, a second full car" \
    $full --suite acceptance --vehicle-preset second --seeds 1-1000 --methods likelihood
  run_text full-mismatch-table5-1 "The full car off its file, Table 5-1 extended" $full --suite mismatch \
    --seeds 1-100 --methods likelihood
  run_text full-mismatch-second "The full car off its file, a second full car" $full --suite mismatch \
    --vehicle-preset second --seeds 1-100 --methods likelihood
}
.venv/bin/python scripts/study_report.py
.venv/bin/python scripts/refined_report.py
