"""Compare the runs of a sweep directory with another sweep of the same scenario, point by point.

For every fan point both hold it prints the two losses and their difference, then the
median and largest absolute difference and the points that moved by more than a given
spread (default 3.0 mm: the median run-to-run spread measured at 12K, docs/lookup.md). Used
to show whether a simulator change moves a table (issue 35: the fast-fold fix against the
tables made before it). Simulates nothing.

    python scripts/compare_runs.py NEW_SWEEP_DIR OLD_SWEEP_DIR [--spread 3e-3]
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from clothfold_ros.lookup.sweep_dir import read_runs  # noqa: E402

RUNS = "runs.jsonl"


def losses(d: Path) -> dict[int, float]:
    """Fan point -> loss (m) of a sweep directory's runs (nan for a failed run; the last row of a point wins)."""
    path = d / RUNS
    if not path.exists():
        raise FileNotFoundError(f"{d} holds no {RUNS}")
    return {int(r["point"]): (float(r["loss_m"]) if r.get("success") else math.nan) for r in read_runs(path)}


def compare(new: dict[int, float], old: dict[int, float], spread: float) -> tuple[list[str], dict]:
    """Report lines and a summary (points, median and max |difference| m, points beyond spread)."""
    common = sorted(set(new) & set(old))
    if not common:
        raise ValueError("the two sweeps share no fan point")
    lines, diffs, moved = [], [], []
    for p in common:
        d = new[p] - old[p]
        lines.append(f"  fan {p:3d}: new {new[p] * 1e3:7.2f} mm  old {old[p] * 1e3:7.2f} mm  {d * 1e3:+7.2f} mm")
        if math.isfinite(d):
            diffs.append(abs(d))
            if abs(d) > spread:
                moved.append(p)
    a = np.array(diffs) if diffs else np.array([math.nan])
    summary = dict(points=len(common), median_abs=float(np.median(a)), max_abs=float(np.max(a)), moved=moved,
                   failed=[p for p in common if not (math.isfinite(new[p]) and math.isfinite(old[p]))])
    return lines, summary


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("new", type=Path)
    ap.add_argument("old", type=Path)
    ap.add_argument("--spread", type=float, default=3e-3, help="m: differences beyond this count as moved")
    a = ap.parse_args(argv)
    try:
        lines, s = compare(losses(a.new), losses(a.old), a.spread)
    except (FileNotFoundError, ValueError) as err:
        print(f"compare_runs: {err}", file=sys.stderr)
        return 2
    print(f"{a.new} against {a.old}:")
    print("\n".join(lines))
    print(f"{s['points']} points; |new - old| median {s['median_abs'] * 1e3:.2f} mm, max {s['max_abs'] * 1e3:.2f} mm; "
          f"{len(s['moved'])} moved by more than {a.spread * 1e3:.1f} mm"
          + (f" ({', '.join(map(str, s['moved']))})" if s["moved"] else "")
          + (f"; failed in one of them: {s['failed']}" if s["failed"] else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
