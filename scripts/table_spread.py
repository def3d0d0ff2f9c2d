"""Run-to-run spread of a shipped lookup table: rerun some of its fan points with h moved by dh.

A loss difference between two fan points smaller than the loss change under a tiny change of
the trajectory ranks nothing (docs/lookup.md, "Resolution study", did this for shape1). This
reruns fan points of any table, sequence stages included (from the table's own start state,
with the sweep's own settings), and prints each point's table loss beside the rerun's:

    python scripts/table_spread.py middle --points 133,84,99 [--dh 1e-3] [--tables config/tables]

Rows are appended to docs/resolution/spread_<scenario>.jsonl (`--out` another directory) (resumable: points already there
are skipped). h + dh is used, or h - dh where h + dh would leave the fan (h <= 1). Losses in mm.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "resolution"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenario")
    ap.add_argument("--points", required=True, help="comma-separated fan indices, e.g. 133,84,99")
    ap.add_argument("--dh", type=float, default=1e-3, help="change of the height ratio (default 1e-3)")
    ap.add_argument("--tables", default=str(ROOT / "config" / "tables"))
    ap.add_argument("--out", default=str(OUT), help="directory of spread_<scenario>.jsonl (default docs/resolution)")
    a = ap.parse_args(argv)

    from clothfold_ros.lookup import sweep_dir as layout
    from clothfold_ros.lookup.sweep import Job, run_job
    from clothfold_ros.trajectory import fan

    d = Path(a.tables) / a.scenario
    if not layout.has_runs(d):
        print(f"{d} holds no sweep (no runs.jsonl)", file=sys.stderr)
        return 2
    settings = layout.read_settings(d)  # the table's own mesh, stepping, Newton settings
    start = layout.start_file(d)        # a sequence stage starts from the previous stage's best
    table = {int(r["point"]): r for r in layout.read_runs(d)}
    out = Path(a.out) / f"spread_{a.scenario}.jsonl"  # rows like runs.jsonl's, plus dh
    done = {int(r["point"]): r for r in layout.read_runs(out)} if out.exists() else {}
    f = fan()
    try:
        points = [int(p) for p in a.points.split(",") if p.strip()]
    except ValueError:
        print(f"--points: comma-separated integers, got {a.points!r}", file=sys.stderr)
        return 2
    for p in points:
        if not 0 <= p < len(f):
            print(f"fan point {p} is outside the fan (0-{len(f) - 1})", file=sys.stderr)
            return 2
        if p not in table:
            print(f"fan point {p} is not in {d / 'runs.jsonl'}", file=sys.stderr)
            return 2
    for p in points:
        if p not in done:
            h = float(f[p, 0]) + a.dh
            if h > 1.0:
                h = float(f[p, 0]) - a.dh
            row, _ = run_job(Job(settings, p, h, float(f[p, 1]), start))
            row["dh"] = h - float(f[p, 0])
            out.parent.mkdir(parents=True, exist_ok=True)
            with out.open("a") as fh:
                fh.write(json.dumps(row) + "\n")
            done[p] = row
        r, t = done[p], table[p]
        moved = (f"{r['loss_m'] * 1e3:.2f} mm, change {(r['loss_m'] - t['loss_m']) * 1e3:+.2f} mm"
                 if r["success"] and t["success"] else r["reason"] or t["reason"])
        print(f"{a.scenario} point {p} (h {float(f[p, 0]):.4f}, tilt {float(f[p, 1]):.1f}): table "
              f"{t['loss_m'] * 1e3:.2f} mm; h {r['dh']:+.0e}: {moved}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
