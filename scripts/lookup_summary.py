#!/usr/bin/env python3
"""Print a Markdown coverage table of the lookup tables (from their provenance.json)."""
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from clothfold_ros.lookup.scenario import SCENARIOS  # noqa: E402

root = Path(sys.argv[1] if len(sys.argv) > 1 else "config/tables")
print("| scenario | simulated / fan points | failed | best (point: h, tilt, loss mm) | CPU s | s per run | status |")
print("|---|---|---|---|---|---|---|")
total = 0.0
for name in SCENARIOS:
    p = root / name / "provenance.json"
    if not p.exists():
        print(f"| {name} | 0 | - | - | - | - | not generated |")
        continue
    v = json.loads(p.read_text())
    b = v["best"]
    best = "-" if b is None else f"{b['point']}: {b['height_ratio']:.2f}, {b['tilt_deg']:.1f}, {b['loss_m'] * 1e3:.1f}"
    n = max(v["simulated"], 1)
    total += v["cpu_seconds"]
    status = "complete" if v["complete"] else f"missing {len(v['missing_points'])}"
    if b is None:
        status += ", no successful run"
    print(f"| {name} | {v['simulated']} / {len(v['fan_points'])} | {v['failures']} | {best} | {v['cpu_seconds']:.0f} | "
          f"{v['cpu_seconds'] / n:.1f} | {status} |")
print(f"\ntotal simulated CPU time {total / 60:.1f} min")
