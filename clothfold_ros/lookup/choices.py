"""What the fold planner chooses for the default shirt, from a tables root: for each fold of
FOLD_SEQUENCE, `TableSelector`'s choice (the planner's) on the flat shirt's keypoints, and in
the sequence, on the keypoints visible after the ideal earlier folds (each planned like the
planner plans it: from the keypoints it sees, with the flat shirt's body length).

The default shirt: shape 1, cotton, friction 0.5, 4 s folds (docs/method.md section 8). The
ideal folds are `perception.visible`'s (the flat outline folded over each line); a simulated
fold ends near them, which is why the sequence's folds are chosen from its own keypoints.
Losses in mm; (h, tilt) in the fan's units.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

BEGIN = "<!-- table-choices (clothfold tables) -->"
END = "<!-- /table-choices -->"
SHAPE, MATERIAL, FRICTION, DURATION = 1, "cotton", 0.5, 4.0


@dataclass(frozen=True)
class PlannerChoice:
    """One fold's choice: the keypoints it was made on ("flat" or "in sequence"), and the
    planner's Selection, or the reason there is none."""

    fold: str
    keypoints: str
    selection: object | None  # planner_selector.Selection
    error: str = ""
    partial: tuple[tuple[str, int], ...] = ()  # (scenario, fan points so far) of the partial tables used


def sequence_keypoints(shape: int = SHAPE, material: str = MATERIAL) -> list[dict[str, np.ndarray]]:
    """Per fold of FOLD_SEQUENCE, the keypoints (name -> (3,) m) seen before it when the earlier
    folds were made ideally, each planned from the keypoints seen before it."""
    from ..folding import FOLD_SEQUENCE, body_length, fold_spec
    from ..garment import KEYPOINT_NAMES
    from ..perception.visible import ideal_visible_keypoints
    from .scenario import flat_keypoints

    flat = flat_keypoints(shape, material)
    outline = np.array([flat[n][:2] for n in KEYPOINT_NAMES])
    z = float(flat[KEYPOINT_NAMES[0]][2])
    length = body_length(flat)
    seen, specs = [], []
    for fold in FOLD_SEQUENCE:
        xy = ideal_visible_keypoints(outline, specs)
        kp = {n: np.array([x, y, z]) for n, (x, y) in zip(KEYPOINT_NAMES, xy)}
        seen.append(kp)
        specs.append(fold_spec(fold, kp, folds_done=[s.name for s in specs], body_length=length))
    return seen


def planner_choices(root: str | Path) -> list[PlannerChoice]:
    """Every fold's choice on the flat keypoints and in sequence, from the tables under `root`
    as the planner reads them (partial tables that hold their coarse points included)."""
    from ..folding import FOLD_SEQUENCE
    from .planner_selector import TableSelector
    from .scenario import flat_keypoints

    selector = TableSelector(root)
    flat = flat_keypoints(SHAPE, MATERIAL)
    out = []
    for stage, (fold, seq) in enumerate(zip(FOLD_SEQUENCE, sequence_keypoints())):
        for label, kp in (("flat", flat), ("in sequence", seq)):
            if label == "in sequence" and stage == 0:
                continue  # the first fold's keypoints are the flat shirt's
            try:
                sel = selector.select(fold_name=fold, keypoints=kp, material=MATERIAL, friction=FRICTION,
                                      duration=DURATION, stage=stage)
                partial = tuple((n, len(selector.tables[n].point)) for n, _ in sel.blended
                                if not selector.tables[n].complete)
                out.append(PlannerChoice(fold, label, sel, partial=partial))
            except (ValueError, RuntimeError) as err:
                out.append(PlannerChoice(fold, label, None, f"{type(err).__name__}: {err}"))
    return out


def markdown(choices: list[PlannerChoice]) -> str:
    """A Markdown table of the choices."""
    lines = ["| fold | keypoints | fan point (h, tilt) | tables used (scaled distance) | smoothed mm | "
             "simulated mm (nearest table) |", "|---|---|---|---|---|---|"]
    for c in choices:
        s = c.selection
        if s is None:
            lines.append(f"| {c.fold} | {c.keypoints} | - | {c.error} | - | - |")
            continue
        sizes = dict(c.partial)
        used = ", ".join(f"{n} ({d:.2f}" + (f"; partial, {sizes[n]} points" if n in sizes else "") + ")"
                         for n, d in s.blended) or s.scenario
        raw = "failed" if math.isnan(s.raw_loss) else f"{s.raw_loss * 1e3:.2f}"
        lines.append(f"| {c.fold} | {c.keypoints} | {s.point} ({s.height_ratio:.3f}, {s.tilt_deg:.1f}) | {used} | "
                     f"{s.expected_loss * 1e3:.2f} | {raw} |")
    return "\n".join(lines)
