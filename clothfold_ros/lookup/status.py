"""Where the lookup tables of a tables root stand: runs so far, failures, best point, cost.

Read from each scenario's `runs.jsonl` (so it is current while a sweep runs, unlike a
table written by `finish`) and its `provenance.json` when one exists (the fan points the
sweep was asked for; otherwise the whole fan). Pure: the standard library and numpy.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..trajectory import fan
from . import doc_blocks
from .scenario import SCENARIOS, generation_order
from .sweep_dir import PROVENANCE, RUNS, best_row, lock_owner, read_runs

FAN_SIZE = len(fan())
BEGIN = "<!-- table-status (clothfold tables) -->"
END = "<!-- /table-status -->"
HEADLINE_BEGIN = "<!-- table-headline (clothfold tables) -->"
HEADLINE_END = "<!-- /table-headline -->"


@dataclass(frozen=True)
class TableStatus:
    """One scenario's sweep directory as it stands."""

    scenario: str
    runs: int  # wanted fan points recorded in runs.jsonl
    wanted: int  # fan points the sweep covers (its provenance, else the whole fan)
    failed: int  # of those
    best: dict | None  # the successful row of least loss
    cpu_s: list[float]  # each run's CPU seconds (its wall time where a row predates cpu_time_s)
    sweeping: bool  # a live sweep holds the directory's lock

    @property
    def complete(self) -> bool:
        return self.runs >= self.wanted > 0

    @property
    def median_cpu_s(self) -> float:
        return float(np.median(self.cpu_s)) if self.cpu_s else float("nan")

    @property
    def cpu_hours_to_go(self) -> float:
        """Missing runs times the median run so far (NaN before the first run)."""
        return (self.wanted - self.runs) * self.median_cpu_s / 3600.0 if self.cpu_s else float("nan")

    @property
    def state(self) -> str:
        if self.runs == 0:
            return "not started"
        word = "complete" if self.complete else "partial"
        return word + (", sweeping" if self.sweeping else "")


def _run_cpu_s(row: dict) -> float:
    return float(row.get("cpu_time_s") or row.get("wall_time_s") or 0.0)


def wanted_points(d: str | Path) -> set[int]:
    """The fan points a sweep directory covers: its provenance's, else the whole fan."""
    wanted = set(range(FAN_SIZE))
    if (Path(d) / PROVENANCE).exists():
        wanted = set(_fan_points(Path(d) / PROVENANCE)) or wanted
    return wanted


def sweep_rows(d: str | Path) -> tuple[list[dict], set[int]]:
    """(rows of `runs.jsonl` at the sweep's fan points, those points); a run outside the
    sweep's points (a log copied from elsewhere, a point no longer asked for) is left out."""
    d = Path(d)
    rows = read_runs(d / RUNS) if (d / RUNS).exists() else []
    wanted = wanted_points(d)
    return [r for r in rows if int(r["point"]) in wanted], wanted


def table_status(d: str | Path, name: str | None = None) -> TableStatus:
    """The status of one sweep directory (which need not exist yet)."""
    d = Path(d)
    name = name or d.name
    done, wanted = sweep_rows(d)
    return TableStatus(name, len(done), len(wanted), sum(not r["success"] for r in done), best_row(done),
                       [_run_cpu_s(r) for r in done], lock_owner(d) is not None)


def _fan_points(provenance: Path) -> list[int]:
    """The `fan_points` a provenance file lists ([] when it lists none); ValueError naming
    the file when it is not JSON or the list is not fan indices."""
    try:
        record = json.loads(provenance.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{provenance}: unreadable provenance ({e})") from None
    points = record.get("fan_points", []) if isinstance(record, dict) else None
    if not isinstance(points, list) or not all(isinstance(p, int) and 0 <= p < FAN_SIZE for p in points):
        raise ValueError(f"{provenance}: fan_points must be a list of fan indices 0..{FAN_SIZE - 1}")
    return points


def tables_status(root: str | Path) -> list[TableStatus]:
    """Every scenario of `SCENARIOS` under `root`, in generation order."""
    return [table_status(Path(root) / n, n) for n in generation_order(list(SCENARIOS))]


def markdown(statuses: list[TableStatus]) -> str:
    """A Markdown table of the statuses and a total line."""
    lines = ["| scenario | runs / fan points | failed | best: point (h, tilt deg), loss mm | median CPU s per run "
             "| CPU h so far | CPU h to go (at that median) | state |",
             "|---|---|---|---|---|---|---|---|"]
    for s in statuses:
        b = s.best
        best = "-" if b is None else \
            f"{b['point']} ({b['height_ratio']:.3f}, {b['tilt_deg']:.1f}), {b['loss_m'] * 1e3:.2f}"
        med = "-" if not s.cpu_s else f"{s.median_cpu_s:.0f}"
        togo = "-" if not s.cpu_s else f"{s.cpu_hours_to_go:.1f}"
        lines.append(f"| {s.scenario} | {s.runs} / {s.wanted} | {s.failed if s.runs else '-'} | {best} | {med} | "
                     f"{sum(s.cpu_s) / 3600:.1f} | {togo} | {s.state} |")
    runs = sum(s.runs for s in statuses)
    wanted = sum(s.wanted for s in statuses)
    done = [s.scenario for s in statuses if s.complete]
    known = sum(s.cpu_hours_to_go for s in statuses if s.cpu_s)
    unstarted = [s for s in statuses if not s.cpu_s]
    total = (f"\n{runs} of {wanted} runs, {sum(s.failed for s in statuses)} failed; complete: "
             f"{', '.join(done) if done else 'none'}. To go at each started table's median: {known:.1f} CPU h")
    if unstarted:
        total += f", plus {sum(s.wanted for s in unstarted)} runs of tables not started " \
                 f"({', '.join(s.scenario for s in unstarted)})"
    return "\n".join(lines) + total + "."


def headline(statuses: list[TableStatus]) -> str:
    """One bold sentence: how many tables are complete, which, their failures, and where the
    others stand (for the table-headline block)."""
    done = [s for s in statuses if s.complete]
    failed = sum(s.failed for s in done)
    fails = "no failure" if not failed else f"{failed} failed run{'s' if failed > 1 else ''}"
    if done and len(done) == len(statuses):
        sizes = {s.wanted for s in done}
        each = f"{sizes.pop()} fan points each" if len(sizes) == 1 else "every fan point each sweep covers"
        return f"**All {len(done)} tables are complete: {each}, {fails}.**"
    rest = []
    for s in statuses:
        if s.complete:
            continue
        where = "not started" if s.runs == 0 else \
            f"{'being swept' if s.sweeping else 'partial'} ({s.runs} of {s.wanted} fan points)"
        rest.append(f"`{s.scenario}` {where}")
    names = ", ".join(f"`{s.scenario}`" for s in done) or "none"
    return f"**{len(done)} of {len(statuses)} tables are complete ({names}; {fails}); {'; '.join(rest)}.**"


def replace_headline(text: str, block: str) -> str:
    """`text` with its table-headline block replaced, where it has one."""
    return doc_blocks.replace_block(text, block, HEADLINE_BEGIN, HEADLINE_END, required=False)


def replace_block(text: str, block: str) -> str:
    """`text` with the table-status block replaced by `block` (ValueError unless there is one)."""
    return doc_blocks.replace_block(text, block, BEGIN, END)
