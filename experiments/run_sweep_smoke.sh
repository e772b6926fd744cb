#!/usr/bin/env bash
# Run the --smoke variant of every shipped sweep (experiments/sweeps/*.toml), analyse
# each, and print the wall time per sweep. Each smoke sweep is a handful of 30-40 s
# runs on a short road: about 15-55 s each on a busy 2-core machine.
#
#   experiments/run_sweep_smoke.sh [OUT_DIR] [extra cosim-sweep options, e.g. --workers 2]
#
# Output: OUT_DIR/<name>_smoke/{results.csv,runs/,analysis/} (default outputs/sweeps_smoke).
# Exit status: non-zero if any sweep had a failed run or could not start.
set -uo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
OUT=${1:-outputs/sweeps_smoke}
shift || true
status=0
for file in experiments/sweeps/*.toml; do
    name=$(basename "$file" .toml)
    out="$OUT/${name}_smoke"
    rm -rf "$out"
    start=$(date +%s.%N)
    "$PY" -c 'import sys; from cosim.sweeps import main; sys.exit(main(sys.argv[1:]))' \
        "$file" --smoke --out "$out" --quiet "$@"
    rc=$?
    end=$(date +%s.%N)
    printf '== %s --smoke: exit %d, %s s\n' "$name" "$rc" "$(awk "BEGIN{printf \"%.1f\", $end - $start}")"
    [ "$rc" -eq 0 ] || status=1
    if [ -f "$out/results.csv" ]; then
        "$PY" -c 'import sys; from cosim.analysis import main; sys.exit(main(sys.argv[1:]))' \
            "$out" > /dev/null || status=1
    fi
done
exit $status
