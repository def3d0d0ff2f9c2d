"""The fold sequence headless: every stage planned from the keypoints of the cloth as it is.

Each stage's fold specification comes from `perception.visible.visible_keypoints` of the
previous stage's final cloth (what a camera looking down sees, given the folds done), the
stage starts from that cloth, and its loss is taken against the composed target (the flat
shirt with every fold of the sequence so far applied, `loss.fold_target`). A failed stage
stops the sequence with its reason. No ROS; the pipeline does the same through its nodes.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

from ..folding import FOLD_SEQUENCE, FoldSpec, body_length, fold_spec
from .episode import FoldOutcome
from .runner import run_fold
from .scene import Scene


@dataclass
class StageResult:
    """One stage: its fold, the (height ratio, tilt deg) used, the spec and the outcome."""

    fold: str
    height_ratio: float
    tilt_deg: float
    spec: FoldSpec
    outcome: FoldOutcome


def run_sequence(scene: Scene, choices: Mapping[str, tuple[float, float]], folds: Sequence[str] = FOLD_SEQUENCE,
                 duration: float = 4.0, settle_time: float = 0.2,
                 progress: Callable[[StageResult], None] | None = None) -> list[StageResult]:
    """Fold `folds` in order on the scene's flat shirt; choices: fold -> (h, tilt deg)."""
    from ..perception.visible import visible_keypoints

    missing = [f for f in folds if f not in choices]
    if missing:
        raise ValueError(f"no (height ratio, tilt) given for {', '.join(missing)}")
    x = scene.flat.copy()
    base = None
    specs: list[FoldSpec] = []
    done: list[str] = []
    results: list[StageResult] = []
    length = body_length(visible_keypoints(scene.garment, x))  # measured on the flat shirt, like the planner node
    for fold in folds:
        kp = visible_keypoints(scene.garment, x, specs)
        spec = fold_spec(fold, kp, folds_done=done, body_length=length)
        h, tilt = choices[fold]
        out = run_fold(scene.garment, spec, scene.material, scene.friction, h, tilt, duration, scene.config.dt,
                       settle_time, vertices=x, target_base=base, config=scene.config)
        res = StageResult(fold, float(h), float(tilt), spec, out)
        results.append(res)
        if progress:
            progress(res)
        if not out.success:
            break
        x, base = out.vertices, out.target
        specs.append(spec)
        done.append(fold)
    return results


def stage_table(results: Sequence[StageResult]) -> str:
    """A Markdown table of the stages: fold, (h, tilt), loss or failure, steps, Newton its/step, wall."""
    rows = ["| stage | fold | (h, tilt) | loss vs composed target | Newton its/step | wall |", "|---|---|---|---|---|---|"]
    for i, r in enumerate(results):
        o = r.outcome
        loss = f"{o.loss * 1000:.1f} mm" if o.success else f"FAILED: {o.reason}"
        rows.append(f"| {i} | {r.fold} | ({r.height_ratio:.3f}, {r.tilt_deg:.1f}) | {loss} | "
                    f"{o.newton_iterations / max(o.steps, 1):.1f} | {o.wall_time:.0f} s |")
    return "\n".join(rows)
