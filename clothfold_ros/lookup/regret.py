"""Leave-one-scenario-out regret of the selection rule.

For each held-out scenario s: choose a fan point from the other tables using s's
features, look its loss up in s's own table, and report
regret(s) = loss_s(chosen) - min successful loss_s  (m).
A chosen point that failed in s counts as s's failure penalty (select.failure_penalty)
and is flagged; a chosen point s did not simulate gives NaN and is flagged.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from .select import choose, failure_penalty
from .table import Table


@dataclass(frozen=True)
class RegretRow:
    """Regret of one held-out scenario (losses in m)."""

    scenario: str
    chosen_from: str
    point: int
    height_ratio: float
    tilt_deg: float
    chosen_loss: float
    best_loss: float
    regret: float
    flag: str  # '' | 'failed in held-out' | 'not simulated in held-out' | 'no success in held-out'


def evaluate(tables: Mapping[str, Table], robust: bool = True) -> list[RegretRow]:
    """Leave-one-scenario-out regret rows, one per table (needs >= 2 tables)."""
    if len(tables) < 2:
        raise ValueError("leave-one-scenario-out needs at least two tables")
    rows = []
    for name, held in tables.items():
        c = choose(tables, held.features, exclude=(name,), robust=robust)
        ok = held.success & np.isfinite(held.loss)
        best = float(held.loss[ok].min()) if ok.any() else math.nan
        flag = "" if ok.any() else "no success in held-out"
        try:
            loss, success = held.loss_at(c.point)
            if not success:
                loss, flag = failure_penalty(held), flag or "failed in held-out"
        except KeyError:
            loss, flag = math.nan, "not simulated in held-out"
        rows.append(RegretRow(name, "+".join(c.scenarios), c.point, c.height_ratio, c.tilt_deg, loss, best,
                              loss - best, flag))
    return rows


def mean_regret(rows: list[RegretRow]) -> float:
    """Mean regret (m) over rows with a finite regret (NaN if none)."""
    r = [x.regret for x in rows if math.isfinite(x.regret)]
    return float(np.mean(r)) if r else math.nan


def report(rows: list[RegretRow], title: str = "regret") -> str:
    """A Markdown table of regret rows (mm) with the mean."""
    lines = [f"| held out | chosen from | point (h, tilt) | chosen loss mm | best loss mm | regret mm | note |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.scenario} | {r.chosen_from} | {r.point} ({r.height_ratio:.3f}, {r.tilt_deg:.1f}) | "
                     f"{r.chosen_loss * 1e3:.1f} | {r.best_loss * 1e3:.1f} | {r.regret * 1e3:.1f} | {r.flag} |")
    n = sum(math.isfinite(r.regret) for r in rows)
    lines.append(f"\n{title}: mean regret {mean_regret(rows) * 1e3:.1f} mm over {n} of {len(rows)} scenarios")
    return "\n".join(lines)
