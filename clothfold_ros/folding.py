"""Fold specifications from shirt keypoints (docs/method.md section 5).

Frame: table frame, metres, z up. A fold line is a horizontal line (point + unit
direction); the cloth on the grippers' side of the vertical plane through it is folded
onto the other side. Gripper frame: x = world up, z = horizontal approach direction.

Tilt signs (used by `trajectory.bezier_control_point`): a positive tilt rotates the
raised control point about k = unit(e - s) (right hand), which moves it sideways along
k x z_up. For each gripper the sign is sign((k x z_up) . o) with o the outward direction
along the fold line: toward the shoulder for a sleeve, away from the other gripper for
the side and middle folds. So a larger tilt always makes the arc bow further outward.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from .arrays import finite_array
from .pose import Pose


@dataclass(frozen=True)
class FoldKind:
    """A fold type: its geometry branch in `fold_spec`, the folded layer's offset in the
    target (x cloth thickness), its code in the scenario features (lookup/scenario.py) and
    what it does to the keypoints a camera sees (perception/visible.py):

    - keeps_keypoints: the folded part lands on top of all the rest, so every keypoint stays
      the material point (the middle fold);
    - outline_corners: keypoint -> the outline path it follows toward the shirt's middle; such a
      keypoint moved by the fold becomes the point where the fold line cuts that path (the
      folded outline's corner; "{side}" is the fold's side). Other moved keypoints are
      projected onto the fold line, sleeve keypoints stay material points.
    """

    name: str
    layer_offset_factor: float
    feature_code: float
    keeps_keypoints: bool = False
    outline_corners: tuple[tuple[str, tuple[str, ...]], ...] = ()


@dataclass(frozen=True)
class Fold:
    """A named fold: its type and its stage group in the lookup tables (0 first sleeve,
    1 second sleeve, 2 the side folds, 3 the middle fold)."""

    name: str
    kind: str
    stage_group: int


#: The fold registry: the one place a fold (type) is named. In sequence order.
FOLD_KINDS: dict[str, FoldKind] = {k.name: k for k in (
    FoldKind("sleeve", 2.0, 0.0, outline_corners=(("shoulder_{side}", ("neck_{side}", "neck_middle")),
                                                  ("neck_{side}", ("neck_middle",)))),
    FoldKind("side", 3.0, 1.0),
    FoldKind("middle", 4.0, 2.0, keeps_keypoints=True))}
FOLDS: dict[str, Fold] = {f.name: f for f in (
    Fold("left_sleeve", "sleeve", 0), Fold("right_sleeve", "sleeve", 1), Fold("left_side", "side", 2),
    Fold("right_side", "side", 2), Fold("middle", "middle", 3))}
FOLD_NAMES: tuple[str, ...] = tuple(FOLDS)
FOLD_SEQUENCE: tuple[str, ...] = FOLD_NAMES  # the order a shirt is folded in
LAYER_OFFSET_FACTOR: dict[str, float] = {k.name: k.layer_offset_factor for k in FOLD_KINDS.values()}  # x thickness
MIN_GRIPPER_LINE_DISTANCE = 1e-3  # m
SLEEVE_LINE_ANGLE_DEG = 30.0  # sleeve fold line vs the side seam

_UP = np.array([0.0, 0.0, 1.0])


def fold_type(name: str) -> str:
    """'sleeve', 'side' or 'middle' for a name in FOLD_NAMES (ValueError otherwise)."""
    if name not in FOLDS:
        raise ValueError(f"unknown fold {name!r}; known folds: {', '.join(FOLD_NAMES)}")
    return FOLDS[name].kind


def _vec3(v: object, what: str) -> np.ndarray:
    return finite_array(v, what, (3,))


def _horizontal_unit(v: np.ndarray, what: str) -> np.ndarray:
    h = np.array([v[0], v[1], 0.0])
    n = np.linalg.norm(h)
    if n < 1e-9:
        raise ValueError(f"{what} has no horizontal extent")
    return h / n


@dataclass(frozen=True, eq=False)
class FoldSpec:
    """A fold: horizontal fold line (line_point m, unit line_direction) and per gripper a
    start and end pose and a tilt sign; layer_offset_factor x thickness raises the
    folded layer in the target."""

    name: str
    line_point: np.ndarray
    line_direction: np.ndarray
    start_poses: tuple[Pose, ...]
    end_poses: tuple[Pose, ...]
    tilt_signs: tuple[float, ...]
    layer_offset_factor: float
    normal: np.ndarray = field(init=False, repr=False)  # horizontal unit, toward the grippers

    def __post_init__(self) -> None:
        p = _vec3(self.line_point, "fold line point")
        d = _vec3(self.line_direction, "fold line direction")
        nd = np.linalg.norm(d)
        if nd < 1e-9:
            raise ValueError("fold line direction is zero")
        d = d / nd
        if abs(d[2]) > 1e-6:
            raise ValueError(f"fold line direction must be horizontal, got {d}")
        d = _horizontal_unit(d, "fold line direction")
        starts, ends = tuple(self.start_poses), tuple(self.end_poses)
        signs = tuple(float(s) for s in self.tilt_signs)
        if not starts:
            raise ValueError("a fold needs at least one gripper")
        if not all(isinstance(q, Pose) for q in starts + ends):
            raise ValueError("start_poses and end_poses must be Pose objects")
        if not len(starts) == len(ends) == len(signs):
            raise ValueError(
                f"{len(starts)} start poses, {len(ends)} end poses and {len(signs)} tilt signs: counts differ")
        if any(s not in (-1.0, 1.0) for s in signs):
            raise ValueError(f"tilt signs must be +1 or -1, got {signs}")
        if not (math.isfinite(self.layer_offset_factor) and self.layer_offset_factor > 0):
            raise ValueError(f"layer_offset_factor must be > 0, got {self.layer_offset_factor}")
        n0 = np.cross(_UP, d)
        dist = np.array([n0 @ (q.position - p) for q in starts])
        for i, di in enumerate(dist):
            if abs(di) < MIN_GRIPPER_LINE_DISTANCE:
                raise ValueError(
                    f"fold {self.name!r}: gripper {i} at {starts[i].position} is {abs(di) * 1e3:.3g} mm from "
                    f"the fold line (needs >= {MIN_GRIPPER_LINE_DISTANCE * 1e3:g} mm)")
        if np.any(dist > 0) and np.any(dist < 0):
            raise ValueError(f"fold {self.name!r}: grippers lie on both sides of the fold line")
        for k, v in (("line_point", p), ("line_direction", d), ("start_poses", starts), ("end_poses", ends),
                     ("tilt_signs", signs), ("layer_offset_factor", float(self.layer_offset_factor)),
                     ("normal", n0 if dist[0] > 0 else -n0)):
            object.__setattr__(self, k, v)

    @property
    def n_grippers(self) -> int:
        return len(self.start_poses)

    def side_of_line(self, points: np.ndarray) -> np.ndarray:
        """Signed horizontal distance (m) of points (N, 3) from the vertical plane through
        the fold line; positive on the grippers' side. A single (3,) point gives a scalar."""
        pts = np.asarray(points, dtype=float)
        if pts.shape[-1] != 3:
            raise ValueError(f"points must have shape (..., 3), got {pts.shape}")
        return (pts - self.line_point) @ self.normal


MIN_HEM_WIDTH = 0.1  # m: a flat hem narrower than this is no shirt's (side and middle folds refuse it)


def check_end_angle(end_angle_deg: float) -> None:
    """ValueError unless 0 < end_angle_deg < 180: at 180 deg start and end orientation are a half
    turn apart, the gripper's turn has no shortest sense, and interpolating them could turn it
    against the fold."""
    if not (math.isfinite(end_angle_deg) and 0.0 < end_angle_deg < 180.0):
        raise ValueError(f"end_angle_deg must be in (0, 180) deg, got {end_angle_deg}")


def _keypoints(name: str, keypoints: Mapping[str, object], needed: list[str]) -> dict[str, np.ndarray]:
    missing = [k for k in needed if k not in keypoints]
    if missing:
        raise ValueError(f"fold {name!r} needs keypoints {', '.join(needed)}; missing: {', '.join(missing)}")
    kp = {k: _vec3(keypoints[k], f"keypoint {k!r}") for k in needed}
    for i, a in enumerate(needed):
        for b in needed[i + 1:]:
            if np.linalg.norm((kp[a] - kp[b])[:2]) < 1e-6:
                raise ValueError(f"fold {name!r}: keypoints {a!r} and {b!r} coincide at {kp[a][:2]}")
    return kp


def _outward_sign(start: np.ndarray, end: np.ndarray, outward: np.ndarray) -> float:
    """+1 if a positive tilt about unit(end - start) moves the control point along `outward`."""
    k = end - start
    side = np.cross(k / np.linalg.norm(k), _UP)
    return 1.0 if side @ outward >= 0 else -1.0


def _done(folds_done: Sequence[str] | None) -> frozenset[str]:
    done = frozenset(folds_done or ())
    unknown = sorted(done - set(FOLD_NAMES))
    if unknown:
        raise ValueError(f"unknown folds in folds_done: {', '.join(unknown)}; known folds: {', '.join(FOLD_NAMES)}")
    return done


def body_length(keypoints: Mapping[str, object]) -> float:
    """The flat shirt's body length (m): from the hem's midpoint to the shoulders' midpoint,
    across the hem (along the shirt's +y, toward the neck). Measure it on the flat shirt,
    before any fold: `fold_spec(..., body_length=...)` places the middle line with it."""
    kp = _keypoints("body length", keypoints, ["bottom_left", "bottom_right", "shoulder_left", "shoulder_right"])
    x_hat = _horizontal_unit(kp["bottom_right"] - kp["bottom_left"], "body length: hem")
    up = (kp["shoulder_left"] + kp["shoulder_right"]) / 2 - (kp["bottom_left"] + kp["bottom_right"]) / 2
    length = float(up @ np.cross(_UP, x_hat))
    if not length > 0.0:
        raise ValueError(f"body length: the shoulders lie {length * 1000:.1f} mm from the hem toward the neck; "
                         "they must lie beyond it")
    return length


def fold_spec(
    name: str,
    keypoints: Mapping[str, object],
    end_angle_deg: float = 175.0,
    end_height: float = 0.05,
    folds_done: Sequence[str] | None = None,
    body_length: float | None = None,
) -> FoldSpec:
    """The fold `name` (FOLD_NAMES) from keypoint positions (name -> (3,) m, table frame).

    folds_done: the folds already made on the shirt; the keypoints are then its visible
    keypoints (`clothfold_ros.perception.visible`: after a side fold that side's hem corner
    is the folded outline's corner on the crease, a quarter of the flat hem width in).
    With the other side folded, a side fold line stays a quarter of the *flat* hem width
    (4/3 of the visible one) in from its side; after both side folds the middle fold
    grasps the visible hem corners, i.e. a quarter of the flat width in from each side,
    where the study grasped. None or () = a flat shirt (the study planned every stage from
    the flat keypoints). On an ideally folded shirt the visible keypoints give the study's
    side lines and grasps, and its middle grasps. The middle line lies half the body length
    above the visible hem: `body_length` (m, `body_length()` of the flat shirt's keypoints)
    when given, which gives the study's line; without it the visible shoulders stand in for
    the flat ones, and after the sleeve folds those are the creases' corners, nearer the neck,
    so the line lies above the study's (11-26 mm on the three shapes).
    The end pose is the start pose rotated by end_angle_deg about the fold line (over the
    top), then moved to z = end_height m.
    """
    kind = fold_type(name)
    done = _done(folds_done)
    check_end_angle(end_angle_deg)
    if not (math.isfinite(end_height) and end_height >= 0.0):
        raise ValueError(f"end_height must be >= 0 m, got {end_height}")
    if body_length is not None and not (math.isfinite(body_length) and body_length > 0.0):
        raise ValueError(f"body_length must be > 0 m, got {body_length}")

    if kind == "sleeve":
        side = name.split("_")[0]
        kp = _keypoints(name, keypoints, [f"armpit_{side}", f"bottom_{side}", f"sleeve_top_{side}",
                                          f"sleeve_bottom_{side}", f"shoulder_{side}"])
        armpit, shoulder = kp[f"armpit_{side}"], kp[f"shoulder_{side}"]
        seam = _horizontal_unit(kp[f"bottom_{side}"] - armpit, f"{name}: armpit to bottom")
        angle = SLEEVE_LINE_ANGLE_DEG if side == "right" else 180.0 - SLEEVE_LINE_ANGLE_DEG
        d = Rotation.from_rotvec(math.radians(angle) * _UP).apply(seam)
        line_point = armpit
        grips = [(kp[f"sleeve_top_{side}"] + kp[f"sleeve_bottom_{side}"]) / 2]
        approach = [_horizontal_unit((shoulder + armpit) / 2 - grips[0], f"{name}: approach")]
        outward = [d * np.sign(d @ (shoulder - armpit))]
    else:
        hem_names = ["bottom_left", "bottom_right"]
        extra = ([f"armpit_{name.split('_')[0]}", "neck_left", "neck_right"] if kind == "side"
                 else ["shoulder_left", "shoulder_right"])
        kp = _keypoints(name, keypoints, hem_names + extra)
        bl, br = kp["bottom_left"], kp["bottom_right"]
        x_hat = _horizontal_unit(br - bl, f"{name}: hem")  # the shirt's +x (its right side)
        y_hat = np.cross(_UP, x_hat)  # the shirt's +y (toward the neck)
        sides_done = [s for s in ("left", "right") if f"{s}_side" in done]
        # visible hem width -> flat hem width: each side fold hides a quarter of it
        seen = np.linalg.norm((br - bl)[:2])
        width = seen / (1.0 - 0.25 * len(sides_done))
        if width < MIN_HEM_WIDTH:  # e.g. the hem corners' cloth folded onto the middle: not the hem seen
            raise ValueError(f"{name}: hem corners {seen * 1000:.1f} mm apart give a flat "
                             f"hem width of {width * 1000:.1f} mm, under {MIN_HEM_WIDTH * 1000:.0f} mm: not a "
                             "shirt's hem (keypoints of cloth an earlier fold moved?)")
        flat_left = bl - (width / 4 if "left" in sides_done else 0.0) * x_hat  # flat hem corners
        flat_right = br + (width / 4 if "right" in sides_done else 0.0) * x_hat
        if kind == "side":
            side = name.split("_")[0]
            sgn = 1.0 if side == "right" else -1.0
            corner = br if side == "right" else bl
            line_point = corner - sgn * (width / 4) * x_hat
            d = -sgn * y_hat  # grippers on the up x d side
            grips = [kp[f"armpit_{side}"], corner]
            centre = (bl + br + kp["neck_left"] + kp["neck_right"]) / 4
            if sides_done:  # the flat shirt's centre: midway between the flat hem corners across
                centre = (flat_left + flat_right) / 2 + ((centre - (bl + br) / 2) @ y_hat) * y_hat
            approach = [_horizontal_unit(centre - g, f"{name}: approach") for g in grips]
        else:
            hem_middle = (bl + br) / 2
            if body_length is None:
                line_point = ((kp["shoulder_left"] + kp["shoulder_right"]) / 2 + hem_middle) / 2
            else:
                line_point = hem_middle + (body_length / 2) * y_hat
            d = -x_hat  # grippers (below the line) on the up x d side
            grips = [flat_left + 0.25 * (flat_right - flat_left), flat_left + 0.75 * (flat_right - flat_left)]
            approach = [y_hat, y_hat]
        outward = [d * np.sign(d @ (grips[0] - grips[1])), d * np.sign(d @ (grips[1] - grips[0]))]

    starts = tuple(Pose.from_axes(g, _UP, a) for g, a in zip(grips, approach))
    n0 = np.cross(_UP, d)
    ends, signs = [], []
    for q, o in zip(starts, outward):
        # rotate over the top: the positive sense about d lifts a point on the up x d side
        sense = 1.0 if n0 @ (q.position - line_point) >= 0 else -1.0
        rot = Rotation.from_rotvec(sense * math.radians(end_angle_deg) * d)
        pos = line_point + rot.apply(q.position - line_point)
        pos[2] = end_height
        ends.append(Pose(pos, (rot * q.rotation).as_quat()))
        signs.append(_outward_sign(q.position, pos, o))
    return FoldSpec(name, line_point, d, starts, tuple(ends), tuple(signs), LAYER_OFFSET_FACTOR[kind])


def fold_sequence_specs(keypoints: Mapping[str, object], **kwargs: float) -> list[FoldSpec]:
    """All FOLD_SEQUENCE specs from the flat shirt's keypoints (as the study planned them)."""
    return [fold_spec(n, keypoints, **kwargs) for n in FOLD_SEQUENCE]
