"""What each lookup table's landscape says, one row per scenario: best and worst fan point,
median loss, how many points fold within 2 cm and within 0.5 mm of the best, the fan
middle's loss and the rank correlation with the default table (shape1).

Read from each scenario's `runs.jsonl` (current while a sweep runs), at the fan points its sweep
covers, as `status` counts them. Losses in mm; (h, tilt)
in the fan's units (height ratio, deg). Spearman's rho over the fan points both tables
completed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .scenario import SCENARIOS, generation_order
from .select import middle_of_fan
from .status import sweep_rows
from .sweep_dir import RUNS, best_row

BEGIN = "<!-- table-summary (clothfold tables) -->"
END = "<!-- /table-summary -->"
REFERENCE = "shape1"  # the default table the others are ranked against
SUCCESS_M = 0.02  # the sleeve folds' failed-fold line (docs/method.md section 7), applied to every table
PLATEAU_M = 0.0005  # the selection rule's tie margin


@dataclass(frozen=True)
class LandscapeSummary:
    """One scenario's landscape; losses in m, rows of `runs.jsonl`."""

    scenario: str
    rows: list[dict]

    @property
    def ok(self) -> list[dict]:
        """The successful runs (with a finite loss)."""
        return [r for r in self.rows if r["success"] and math.isfinite(r["loss_m"])]

    def losses(self) -> dict[int, float]:
        """Fan point -> loss (m) of the successful runs."""
        return {int(r["point"]): float(r["loss_m"]) for r in self.ok}

    def best(self) -> dict | None:
        """The successful run of least loss."""
        return best_row(self.rows)

    def worst(self) -> dict | None:
        """The successful run of largest loss."""
        ok = self.ok
        return max(ok, key=lambda r: (r["loss_m"], -r["point"])) if ok else None

    def spearman(self, other: "LandscapeSummary") -> float:
        """Spearman's rho of the losses over the points both completed (NaN under 3, or when
        either landscape is flat over them: no ranking to compare)."""
        from scipy.stats import spearmanr

        a, b = self.losses(), other.losses()
        common = sorted(set(a) & set(b))
        if len(common) < 3 or len({a[p] for p in common}) < 2 or len({b[p] for p in common}) < 2:
            return float("nan")
        return float(spearmanr([a[p] for p in common], [b[p] for p in common]).statistic)


def landscape_summaries(root: str | Path) -> list[LandscapeSummary]:
    """Every scenario of `SCENARIOS` under `root` that has runs, in generation order."""
    out = []
    for name in generation_order(list(SCENARIOS)):
        d = Path(root) / name
        if (d / RUNS).exists():
            out.append(LandscapeSummary(name, sweep_rows(d)[0]))  # the sweep's fan points, as `status` counts
    return out


def _point(r: dict | None) -> str:
    return "-" if r is None else f"({r['height_ratio']:.3f}, {r['tilt_deg']:.1f}) {r['loss_m'] * 1e3:.2f}"


def markdown(summaries: list[LandscapeSummary]) -> str:
    """A Markdown table of the summaries."""
    ref = next((s for s in summaries if s.scenario == REFERENCE), None)
    middle = middle_of_fan()
    lines = ["| scenario | runs | best (h, tilt) mm | median mm | worst (h, tilt) mm | within 2 cm | within 0.5 mm "
             f"of the best | fan middle ({middle}) mm | Spearman vs {REFERENCE} |",
             "|---|---|---|---|---|---|---|---|---|"]
    for s in summaries:
        losses = s.losses()
        v = np.array(list(losses.values()))
        best = s.best()
        med = f"{np.median(v) * 1e3:.2f}" if len(v) else "-"
        within = f"{int(np.sum(v <= SUCCESS_M))}" if len(v) else "-"
        plateau = f"{int(np.sum(v <= best['loss_m'] + PLATEAU_M))}" if best else "-"
        mid = f"{losses[middle] * 1e3:.2f}" if middle in losses else "-"
        rho = "-" if ref is None or s is ref else f"{s.spearman(ref):.2f}"
        failed = len(s.rows) - len(s.ok)
        runs = f"{len(s.rows)}" + (f" ({failed} failed)" if failed else "")
        lines.append(f"| {s.scenario} | {runs} | {_point(best)} | {med} | {_point(s.worst())} | {within} | "
                     f"{plateau} | {mid} | {rho} |")
    return "\n".join(lines)
