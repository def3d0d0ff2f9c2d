"""Leave-one-scenario-out regret of trajectory selection rules.

For each held-out scenario s a rule picks a fan point without s's table, the point's loss
is looked up in s's own table, and regret(s) = loss_s(chosen) - min successful loss_s (m).
A chosen point that failed in s counts as s's failure penalty (select.failure_penalty) and
is flagged; a chosen point s did not simulate gives NaN and is flagged. The rules
(`RULES`): the planner's robust rule, the raw argmin of the nearest table, one static
trajectory for everything (the fan point at the middle of the fan) and the default
table's best point used everywhere.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from typing import Callable, Mapping

import numpy as np

from ..trajectory import fan
from .select import DEFAULT_TIE_MARGIN, choose, failure_penalty, middle_of_fan
from .table import Table

DEFAULT_SCENARIO = "shape1"
FAILED_FOLD_LOSS = 0.02  # m: a sleeve fold ending farther than 2 cm from its target failed (method, loss)


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
    flag: str  # '' | 'failed in held-out' | 'not simulated in held-out' | 'no success in held-out' | 'n/a: ...'


Rule = Callable[[Mapping[str, Table], str], "tuple[int, str] | None"]


def _nearest_tables(tables: Mapping[str, Table], held: str, robust: bool,
                    tie_margin: float = DEFAULT_TIE_MARGIN) -> tuple[int, str]:
    """select.choose without the held-out table (robust or raw argmin; tie_margin in m)."""
    c = choose(tables, tables[held].features, exclude=(held,), robust=robust, tie_margin=tie_margin)
    return c.point, "+".join(c.scenarios)


def _static(tables: Mapping[str, Table], held: str) -> tuple[int, str]:
    return middle_of_fan(), "(fan middle)"


def _default_best(tables: Mapping[str, Table], held: str) -> tuple[int, str] | None:
    """The default table's best successful point; None when the default is held out or absent."""
    t = tables.get(DEFAULT_SCENARIO)
    if held == DEFAULT_SCENARIO or t is None or not t.success.any():
        return None
    ok = np.flatnonzero(t.success & np.isfinite(t.loss))
    return int(t.point[ok[np.argmin(t.loss[ok])]]), DEFAULT_SCENARIO


#: name -> (rule, description). A rule maps (tables, held-out name) to (fan point, source).
RULES: dict[str, tuple[Rule, str]] = {
    "robust": (partial(_nearest_tables, robust=True), "robust rule (the planner's: neighbourhood-smoothed, nearest tables, ties within 0.5 mm to the fan's middle)"),
    "argmin": (partial(_nearest_tables, robust=False), "raw argmin of the nearest table"),
    "static": (_static, "one static trajectory: the middle of the fan"),
    "default_best": (_default_best, "the default table's best point everywhere"),
}


def evaluate(tables: Mapping[str, Table], rule: str = "robust", tie_margin: float | None = None) -> list[RegretRow]:
    """Leave-one-scenario-out regret rows of `rule` (a key of RULES), one per table (needs >= 2 tables).
    tie_margin (m): the robust rule's, instead of select.DEFAULT_TIE_MARGIN (robust rule only)."""
    if len(tables) < 2:
        raise ValueError("leave-one-scenario-out needs at least two tables")
    if rule not in RULES:
        raise ValueError(f"unknown rule {rule!r} ({', '.join(RULES)})")
    if tie_margin is not None and rule != "robust":
        raise ValueError(f"tie_margin applies to the robust rule only, not {rule!r}")
    pick = RULES[rule][0] if tie_margin is None else partial(RULES[rule][0], tie_margin=tie_margin)
    f = fan()
    rows = []
    for name, held in tables.items():
        ok = held.success & np.isfinite(held.loss)
        best = float(held.loss[ok].min()) if ok.any() else math.nan
        try:
            picked = pick(tables, name)
        except ValueError as err:  # e.g. no other table with a successful run to choose from
            rows.append(RegretRow(name, "-", -1, math.nan, math.nan, math.nan, best, math.nan, f"n/a: {err}"))
            continue
        if picked is None:
            rows.append(RegretRow(name, "-", -1, math.nan, math.nan, math.nan, best, math.nan,
                                  "n/a: the rule's own table is held out"))
            continue
        point, source = picked
        flag = "" if ok.any() else "no success in held-out"
        try:
            loss, success = held.loss_at(point)
            if not success:
                loss, flag = failure_penalty(held), flag or "failed in held-out"
        except KeyError:
            loss, flag = math.nan, "not simulated in held-out"
        rows.append(RegretRow(name, source, point, float(f[point, 0]), float(f[point, 1]), loss, best, loss - best,
                              flag))
    return rows


def mean_regret(rows: list[RegretRow]) -> float:
    """Mean regret (m) over rows with a finite regret (NaN if none)."""
    r = [x.regret for x in rows if math.isfinite(x.regret)]
    return float(np.mean(r)) if r else math.nan


def worst_regret(rows: list[RegretRow]) -> float:
    """Largest regret (m) over rows with a finite regret (NaN if none)."""
    r = [x.regret for x in rows if math.isfinite(x.regret)]
    return float(np.max(r)) if r else math.nan


def success_rate(rows: list[RegretRow]) -> tuple[int, int]:
    """(successes, evaluated): among held-out scenarios whose table holds the chosen point,
    how many folds completed within FAILED_FOLD_LOSS of the target."""
    evaluated = [r for r in rows if math.isfinite(r.chosen_loss)]
    good = sum(r.flag == "" and r.chosen_loss <= FAILED_FOLD_LOSS for r in evaluated)
    return good, len(evaluated)


def _mm(x: float) -> str:
    return f"{x * 1e3:.1f}" if math.isfinite(x) else "-"


def report(rows: list[RegretRow], title: str = "regret") -> str:
    """A Markdown table of regret rows (mm) with the mean."""
    lines = ["| held out | chosen from | point (h, tilt) | chosen loss mm | best loss mm | regret mm | note |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        where = f"{r.point} ({r.height_ratio:.3f}, {r.tilt_deg:.1f})" if r.point >= 0 else "-"
        lines.append(f"| {r.scenario} | {r.chosen_from} | {where} | {_mm(r.chosen_loss)} | {_mm(r.best_loss)} | "
                     f"{_mm(r.regret)} | {r.flag} |")
    n = sum(math.isfinite(r.regret) for r in rows)
    lines.append(f"\n{title}: mean regret {_mm(mean_regret(rows))} mm over {n} of {len(rows)} scenarios")
    return "\n".join(lines)


def summary(rows_by_rule: Mapping[str, list[RegretRow]]) -> str:
    """A Markdown table, one line per rule: mean and worst regret (mm) and success rate."""
    lines = ["| rule | scenarios with a regret | mean regret mm | worst regret mm | success (completed, <= 2 cm: the sleeve folds' threshold, on every fold) |",
             "|---|---|---|---|---|"]
    for name, rows in rows_by_rule.items():
        good, n_eval = success_rate(rows)
        n = sum(math.isfinite(r.regret) for r in rows)
        lines.append(f"| {RULES[name][1] if name in RULES else name} | {n} of {len(rows)} | "
                     f"{_mm(mean_regret(rows))} | {_mm(worst_regret(rows))} | "
                     f"{good} of {n_eval}" + (f" ({100 * good / n_eval:.0f} %)" if n_eval else "") + " |")
    return "\n".join(lines)


def tie_margin_report(tables: Mapping[str, Table], margins_m: list[float]) -> str:
    """Markdown table: the robust rule's leave-one-out regret for each tie margin (m), with the
    fan point it picks per held-out table (in the tables' order)."""
    names = list(tables)
    lines = [f"robust rule by tie margin (held out in order: {', '.join(names)})", "",
             "| tie margin mm | mean regret mm | worst regret mm | success | fan points picked |", "|---|---|---|---|---|"]
    for m in margins_m:
        rows = evaluate(tables, "robust", tie_margin=m)
        ok, n = success_rate(rows)
        lines.append(f"| {m * 1e3:g} | {mean_regret(rows) * 1e3:.3f} | {worst_regret(rows) * 1e3:.2f} | {ok} of {n} | "
                     f"{' '.join(str(r.point) for r in rows)} |")
    return "\n".join(lines)
