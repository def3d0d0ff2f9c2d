#!/usr/bin/env bash
# Regenerate the 13 lookup tables of docs/method.md section 8 (resumable: rerun to continue).
# Usage: scripts/generate_lookup_tables.sh [POINTS] [MAX_AREA_M2] [OUT]
#   POINTS: all | alternate | every:R:T | comma list of fan indices (default every:4:6)
#   MAX_AREA_M2: mesh max triangle area (default 5e-4, ~1.2K triangles; the study's full resolution is 5e-5)
# The shipped 12K tables (resume them with this line): scripts/generate_lookup_tables.sh all 5e-5 config/tables
# The script sweeps at the defaults (400 Newton iterations, 170 deg end angle); a coarse run needs a
# fresh directory (a sweep directory refuses other settings):
#   scripts/generate_lookup_tables.sh every:4:6 5e-4 out/tables   (see docs/lookup.md)
set -u
# use this checkout's environment when clothfold is not on PATH (run ./clothfold once to create it)
if ! command -v clothfold >/dev/null 2>&1; then
  ROOT=$(cd "$(dirname "$0")/.." && pwd)
  if [ -f "$ROOT/.venv/clothfold_env.sh" ]; then . "$ROOT/.venv/clothfold_env.sh"
  else echo "clothfold not found: run $ROOT/clothfold --help once to set up .venv" >&2; exit 2; fi
fi
POINTS=${1:-every:4:6}
MAX_AREA=${2:-5e-4}
OUT=${3:-out/tables}
# sequence stages need the stage before them; the rest are independent. The short motions
# (T1, T2: 30 and 55 steps) come early: complete tables sooner for the leave-one-out regret.
# thin_cotton's 12K runs cost 3-4x a shape1 run (3,228 Newton iterations for its fan point 1;
# median CPU s per run: T1 69, T2 84, mu0.2 112, thick_cotton 130, thin_cotton about 270),
# so the cheaper single-fold tables, T8 included, come before it.
ORDER="shape1 T1 T2 both_sleeves shape2 shape3 thick_cotton mu0.2 mu0.8 T8 thin_cotton both_sides middle"
rc=0
for s in $ORDER; do  # a failed sweep does not stop the others; the script's exit code says so
  clothfold sweep "$s" --points "$POINTS" --max-area "$MAX_AREA" --out "$OUT" || { echo "sweep $s FAILED (exit $?)" >&2; rc=1; }
done
exit $rc
