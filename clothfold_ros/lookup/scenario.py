"""The 13 study scenarios and the scenario features (docs/method.md sections 8 and 9).

Features are measured from keypoints (name -> (3,) m, table frame) so the same function
describes a scenario when its table is built and the current shirt at run time.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Mapping

import numpy as np

from ..folding import FOLD_KINDS, FOLD_NAMES, FOLDS, fold_spec, fold_type
from ..garment import SHAPES, shirt_outline, KEYPOINT_NAMES
from ..materials import MATERIALS, material

#: Stage groups of the fold sequence: 0 first sleeve on a flat shirt, 1 second sleeve
#: ("both sleeves"), 2 the side folds ("both sides"), 3 the middle fold.
STAGE_OF_FOLD: dict[str, int] = {n: f.stage_group for n, f in FOLDS.items()}  # from the fold registry

#: Feature names, their units and the scale that makes one unit of normalized distance.
FEATURE_SCALES: dict[str, float] = {
    "sleeve_length": 0.05,  # m
    "sleeve_angle": 15.0,  # deg
    "grip_distance": 0.05,  # m, gripper start to fold line
    "log_thickness": math.log(5.0),  # thin / thick cotton are one unit from cotton
    "log_stiffness": math.log(2.0),  # Young's modulus E, factor 2 = one unit
    "friction": 0.3,  # Coulomb coefficient
    "log2_duration": 1.0,  # one doubling of the motion time = one unit
    "stage": 1.0,  # stage group (STAGE_OF_FOLD)
    "fold_type": 0.2,  # 0 sleeve / 1 side / 2 middle: a different fold type is 5 units away
}
FEATURE_NAMES: tuple[str, ...] = tuple(FEATURE_SCALES)
#: Fold type name -> its `fold_type` feature code (from the fold registry), and back.
FOLD_TYPE_CODE: dict[str, float] = {k.name: k.feature_code for k in FOLD_KINDS.values()}
FOLD_TYPE_NAME: dict[float, str] = {code: name for name, code in FOLD_TYPE_CODE.items()}


@dataclass(frozen=True)
class Scenario:
    """One study scenario: shape preset, material, friction, motion time (s), and the fold.

    `after` names the scenario whose best final state this one starts from (sequence
    stages); `folds` are simulated one after another with the same (h, tilt) per fan point.
    """

    name: str
    label: str
    shape: int = 1
    material: str = "cotton"
    friction: float = 0.5
    duration: float = 4.0
    folds: tuple[str, ...] = ("left_sleeve",)
    after: str | None = None

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise ValueError(f"scenario {self.name!r}: shape must be one of {sorted(SHAPES)}, got {self.shape!r}")
        material(self.material)  # ValueError naming the known materials
        if not (math.isfinite(self.friction) and self.friction >= 0):
            raise ValueError(f"scenario {self.name!r}: friction must be finite and >= 0, got {self.friction}")
        if not (math.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"scenario {self.name!r}: duration must be > 0 s, got {self.duration}")
        unknown = [f for f in self.folds if f not in STAGE_OF_FOLD]
        if not self.folds or unknown:
            raise ValueError(f"scenario {self.name!r}: folds must be one or more of {', '.join(STAGE_OF_FOLD)}, "
                             f"got {list(self.folds)}")

    @property
    def stage(self) -> int:
        return STAGE_OF_FOLD[self.folds[0]]

    def as_dict(self) -> dict:
        d = asdict(self)
        d["folds"] = list(self.folds)
        return d


SCENARIOS: dict[str, Scenario] = {s.name: s for s in (
    Scenario("shape1", "shape 1: long straight sleeves (default)"),
    Scenario("shape2", "shape 2: long sleeves angled down", shape=2),
    Scenario("shape3", "shape 3: short sleeves", shape=3),
    Scenario("thin_cotton", "thin cotton (thickness / 5)", material="thin_cotton"),
    Scenario("thick_cotton", "thick cotton (thickness x 5)", material="thick_cotton"),
    Scenario("mu0.2", "friction 0.2", friction=0.2),
    Scenario("mu0.8", "friction 0.8", friction=0.8),
    Scenario("both_sleeves", "stage: second sleeve after the best first sleeve",
             folds=("right_sleeve",), after="shape1"),
    Scenario("both_sides", "stage: left then right side after the best both-sleeves state",
             folds=("left_side", "right_side"), after="both_sleeves"),
    Scenario("middle", "stage: middle fold after the best both-sides state", folds=("middle",), after="both_sides"),
    Scenario("T1", "motion time 1 s", duration=1.0),
    Scenario("T2", "motion time 2 s", duration=2.0),
    Scenario("T8", "motion time 8 s", duration=8.0),
)}


#: The study's figure groups: each varies one factor against the default scenario (shape1),
#: which therefore appears in every group; together they hold all 13 scenarios.
SCENARIO_GROUPS: dict[str, tuple[str, ...]] = {
    "shirt shape": ("shape1", "shape2", "shape3"),
    "thickness": ("thin_cotton", "shape1", "thick_cotton"),
    "friction": ("mu0.2", "shape1", "mu0.8"),
    "motion time": ("T1", "T2", "shape1", "T8"),
    "fold sequence": ("shape1", "both_sleeves", "both_sides", "middle"),
}


def scenario(name: str) -> Scenario:
    """A scenario by name, with a clear error for unknown names."""
    try:
        return SCENARIOS[name]
    except KeyError:
        raise ValueError(f"unknown scenario {name!r}; known: {', '.join(SCENARIOS)}") from None


def folds_before(name: str) -> tuple[str, ...]:
    """The folds made before scenario `name` starts: those of the scenarios it starts after
    (its `after` chain), in order; () for a flat start."""
    dep = scenario(name).after
    return () if dep is None else folds_before(dep) + SCENARIOS[dep].folds


def generation_order(names: list[str] | None = None) -> list[str]:
    """Scenario names (default all) plus their `after` dependencies, dependencies first."""
    todo = list(SCENARIOS) if names is None else [scenario(n).name for n in names]
    out: list[str] = []

    def visit(n: str) -> None:
        if n in out:
            return
        dep = SCENARIOS[n].after
        if dep is not None:
            visit(dep)
        out.append(n)

    for n in todo:
        visit(n)
    return out


def _sleeve_measures(kp: Mapping[str, np.ndarray], side: str) -> tuple[float, float]:
    """(length m, angle deg below the outward horizontal) of one sleeve from keypoints."""
    mid = (np.asarray(kp[f"shoulder_{side}"]) + np.asarray(kp[f"armpit_{side}"])) / 2
    cuff = (np.asarray(kp[f"sleeve_top_{side}"]) + np.asarray(kp[f"sleeve_bottom_{side}"])) / 2
    d = (cuff - mid)[:2]
    outward = 1.0 if side == "right" else -1.0
    return float(np.hypot(*d)), float(math.degrees(math.atan2(-d[1], outward * d[0])))


def grip_distance(spec) -> float:
    """Mean horizontal distance (m) of the gripper start positions from the fold line."""
    return float(np.mean([abs(spec.side_of_line(p.position)) for p in spec.start_poses]))


def spec_for(fold_name: str, keypoints: Mapping[str, np.ndarray],
             fallback_keypoints: Mapping[str, np.ndarray] | None = None,
             end_angle_deg: float = 175.0) -> tuple[object, str]:
    """(FoldSpec, note) from `keypoints`; if they give no valid fold (e.g. coinciding
    hem corners after the side folds) and `fallback_keypoints` (the flat shirt's) are
    given, the spec comes from those and the note says why. Otherwise the error is raised."""
    try:
        return fold_spec(fold_name, keypoints, end_angle_deg), "spec from the current keypoints"
    except ValueError as err:
        if fallback_keypoints is None:
            raise ValueError(f"no fold spec for {fold_name!r} from these keypoints: {err}") from err
        return (fold_spec(fold_name, fallback_keypoints, end_angle_deg),
                f"spec from the flat shirt's keypoints (current keypoints invalid: {err})")


def features(*, fold_name: str, keypoints: Mapping[str, np.ndarray], material_name: str, friction: float,
             duration: float, stage: int | None = None, grip: float | None = None) -> dict[str, float]:
    """Scenario features (units in FEATURE_SCALES) of a fold from keypoints.

    Sleeve measures are the folded sleeve's side for sleeve folds, else the mean of both
    sides. `grip` (m) overrides the grip-to-fold-line distance (when the spec came from
    other keypoints); `stage` defaults to STAGE_OF_FOLD[fold_name]. A feature that is not
    finite (a non-finite keypoint it is measured from) is a ValueError naming both.
    """
    kind = fold_type(fold_name)
    missing = [k for k in KEYPOINT_NAMES if k not in keypoints]
    if missing:
        raise ValueError(f"keypoints missing: {', '.join(missing)}")
    if not (math.isfinite(friction) and friction >= 0):
        raise ValueError(f"friction must be >= 0, got {friction}")
    if not (math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be > 0 s, got {duration}")
    mat = material(material_name)
    if grip is not None and not (math.isfinite(grip) and grip >= 0):
        raise ValueError(f"grip distance must be finite and >= 0 m, got {grip}")
    if stage is not None and not (float(stage).is_integer() and stage >= 0):
        raise ValueError(f"stage must be a whole number >= 0 (a stage group), got {stage}")
    sides = [fold_name.split("_")[0]] if kind == "sleeve" else ["left", "right"]
    ml = np.array([_sleeve_measures(keypoints, s) for s in sides])
    if grip is None:
        grip = grip_distance(spec_for(fold_name, keypoints)[0])
    out = {
        "sleeve_length": float(ml[:, 0].mean()),
        "sleeve_angle": float(ml[:, 1].mean()),
        "grip_distance": float(grip),
        "log_thickness": math.log(mat.thickness),
        "log_stiffness": math.log(mat.youngs_modulus),
        "friction": float(friction),
        "log2_duration": math.log2(duration),
        "stage": float(STAGE_OF_FOLD[fold_name] if stage is None else stage),
        "fold_type": FOLD_TYPE_CODE[kind],
    }
    sleeve = [f"{p}_{s}" for s in sides for p in ("shoulder", "armpit", "sleeve_top", "sleeve_bottom")]
    for k, v in out.items():
        if not math.isfinite(v):
            source = sleeve if k.startswith("sleeve_") else KEYPOINT_NAMES  # grip: the fold spec's keypoints
            bad = [n for n in source if not np.all(np.isfinite(np.asarray(keypoints[n], dtype=float)))]
            raise ValueError(f"feature {k} is {v}: " + (f"non-finite keypoint(s) {', '.join(bad)}, which it is "
                             "measured from" if bad else f"measured from keypoints {', '.join(source)}"))
    return out


def flat_keypoints(shape: int, material_name: str) -> dict[str, np.ndarray]:
    """Keypoints of the flat shirt preset lying at z = 2 t (no meshing needed)."""
    if shape not in SHAPES:
        raise ValueError(f"shape must be one of {sorted(SHAPES)}, got {shape!r}")
    xy = shirt_outline(SHAPES[shape])
    z = 2.0 * material(material_name).thickness
    return {n: np.array([p[0], p[1], z]) for n, p in zip(KEYPOINT_NAMES, xy)}


def definition_features(s: Scenario) -> dict[str, float]:
    """Features of a flat-start scenario from its definition (shape preset outline).
    Sequence stages depend on the previous stage's result: their features are measured
    by the sweep from the actual start state and stored in the table."""
    if s.after is not None:
        raise ValueError(f"scenario {s.name!r} starts from {s.after!r}'s result: its features come from its table")
    return features(fold_name=s.folds[0], keypoints=flat_keypoints(s.shape, s.material), material_name=s.material,
                    friction=s.friction, duration=s.duration)


def normalized_distance(a: Mapping[str, float], b: Mapping[str, float]) -> float:
    """Euclidean distance between two feature dicts, each feature divided by its scale
    (ValueError for a missing or non-finite feature)."""
    for name, f in (("first", a), ("second", b)):
        bad = [k for k in FEATURE_NAMES if k not in f or not math.isfinite(f[k])]
        if bad:
            raise ValueError(f"{name} feature set lacks finite {', '.join(bad)}")
    d = np.array([(a[k] - b[k]) / FEATURE_SCALES[k] for k in FEATURE_NAMES])
    return float(np.sqrt(d @ d))


assert set(MATERIALS) and set(STAGE_OF_FOLD) == set(FOLD_NAMES)
