"""Refresh the coverage table and regret figures in docs/lookup.md from config/tables.

    python scripts/fill_lookup_docs.py   (after `clothfold regret --out config/tables/regret.md`)
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from clothfold_ros.lookup.select import smoothed_loss
from clothfold_ros.lookup.table import load_tables

ROOT = Path(__file__).resolve().parents[1]


def coverage_rows(tables) -> str:
    rows = []
    for name, t in sorted(tables.items()):
        ok = t.success
        best = int(np.nanargmin(np.where(ok, t.loss, np.nan))) if ok.any() else None
        robust = int(np.argmin(smoothed_loss(t)))
        best_s = f"{t.height_ratio[best]:.3f}, {t.tilt_deg[best]:.1f}, {t.loss[best] * 1000:.1f} mm" if best is not None else "-"
        rows.append(
            f"| {name} | {len(t.point)} / {len(t.point)} | {int((~ok).sum())} | {best_s} | "
            f"{t.height_ratio[robust]:.3f}, {t.tilt_deg[robust]:.1f} ({t.loss[robust] * 1000:.1f} mm) | complete |"
        )
    return "\n".join(rows)


def main() -> None:
    doc = ROOT / "docs/lookup.md"
    text = doc.read_text()
    tables = load_tables(ROOT / "config/tables")
    text = re.sub(r"(\| scenario \| simulated / fan points .*?\n\|[-| ]+\|\n)(?:\|.*\|\n|TABLE_ROWS\n)+",
                  lambda m: m.group(1) + coverage_rows(tables) + "\n", text, flags=re.S)
    regret = (ROOT / "config/tables/regret.md").read_text().strip()
    start = text.index("## Regret (leave-one-scenario-out")
    head_end = text.index("`clothfold regret --out config/tables/regret.md`.", start) + len("`clothfold regret --out config/tables/regret.md`.")
    nxt = text.find("\n## ", head_end)
    tail = text[nxt:] if nxt >= 0 else "\n"
    text = text[:head_end] + "\n\n" + regret + "\n" + tail
    doc.write_text(text)


if __name__ == "__main__":
    main()
