#!/usr/bin/env bash
# Figures and reports of a lookup-table root, as a sweep finishes tables (or at a checkpoint):
# every table's landscape.png and best_worst.png, the 13 landscapes side by side
# (ROOT/landscapes.png), the leave-one-out regret over the complete tables (ROOT/regret.md) and
# the table-headline, table-status, table-summary, table-choices and regret-summary blocks of each
# Markdown file named (a file without a block keeps its text). tests/test_lookup_regret_report.py holds docs/results.md's
# and docs/lookup.md's regret rows to the tables; the prose around them is updated by hand.
# Usage: scripts/report_lookup_tables.sh [ROOT [MARKDOWN ...]]
#   scripts/report_lookup_tables.sh config/tables docs/results.md docs/lookup.md config/tables/README.md
set -eu
if ! command -v clothfold >/dev/null 2>&1; then
  ROOT_DIR=$(cd "$(dirname "$0")/.." && pwd)
  if [ -f "$ROOT_DIR/.venv/clothfold_env.sh" ]; then . "$ROOT_DIR/.venv/clothfold_env.sh"
  else echo "clothfold not found: run $ROOT_DIR/clothfold --help once to set up .venv" >&2; exit 2; fi
fi
TABLES=${1:-config/tables}
shift || true
# each table's landscape and best/worst renders (a table whose sweep has no run yet has no table.csv)
# (a partial table has its landscape only: the best/worst renders read finals.npz, written when it is complete)
for csv in "$TABLES"/*/table.csv; do
  [ -f "$csv" ] || continue
  name=$(basename "$(dirname "$csv")")
  if [ -f "$TABLES/$name/finals.npz" ]; then
    clothfold plot --tables "$TABLES" "$name"
  else
    clothfold plot --tables "$TABLES" "$name" 2>/dev/null && echo "$name: partial, landscape only"
  fi
done
clothfold plot --overview --tables "$TABLES"       # the 13 landscapes side by side
clothfold regret --tables "$TABLES" --out "$TABLES/regret.md" --write "$@" > /dev/null
if [ "$#" -gt 0 ]; then
  clothfold tables --tables "$TABLES" --write "$@"
else
  clothfold tables --tables "$TABLES"
fi
