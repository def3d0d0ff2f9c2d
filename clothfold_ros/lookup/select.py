"""Robust choice of (height ratio, tilt) from the nearest scenario table(s) (docs/method.md section 9).

Rule (docs/lookup.md):
1. Distance: normalized Euclidean distance between the scenario features
   (scenario.FEATURE_SCALES); the nearest table and every table within `blend_margin`
   units of it are used, weighted 1 / (1 + distance).
2. Per table, every fan point gets a smoothed loss: the Gaussian-weighted mean of the
   losses of the points around it in the fan layout (x = h cos tilt, y = h sin tilt),
   bandwidth sigma = the median nearest-neighbour spacing of the table's points,
   cut off at 2 sigma (the point itself has weight 1). A failed run counts as the
   table's worst successful loss (the failure penalty).
3. Candidates are the nearest table's fan points whose (blended) smoothed loss lies within
   `tie_margin` (0.5 mm) of the least; a table blended in must hold all of them (a
   partial table is left out, not intersected with). Losses closer than that rank nothing
   (the simulator's fast settings are held to 0.5 mm of a converged reference), so among
   the candidates the point nearest the middle of the fan wins (the study's suggestion
   for one static trajectory); then the lower score, the lower raw loss, the lower index.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..trajectory import fan
from .scenario import normalized_distance
from .table import Table

DEFAULT_BLEND_MARGIN = 0.5  # normalized feature units
DEFAULT_TIE_MARGIN = 5e-4  # m: smoothed losses closer than this to the least count as equal
CUTOFF_SIGMAS = 2.0


def fan_xy(height_ratio: np.ndarray, tilt_deg: np.ndarray) -> np.ndarray:
    """(K, 2) positions of fan points in the fan layout (radius h, angle tilt)."""
    t = np.radians(np.asarray(tilt_deg, dtype=float))
    h = np.asarray(height_ratio, dtype=float)
    return np.column_stack([h * np.cos(t), h * np.sin(t)])


def middle_of_fan() -> int:
    """The fan point nearest (in the fan layout) to the middle of the fan: height ratio
    halfway between its least and largest, tilt halfway between 0 and 60 deg."""
    f = fan()
    xy = fan_xy(f[:, 0], f[:, 1])
    mid = fan_xy(np.array([0.5 * (f[:, 0].min() + f[:, 0].max())]), np.array([0.5 * (f[:, 1].min() + f[:, 1].max())]))
    return int(np.argmin(np.linalg.norm(xy - mid, axis=1)))


def failure_penalty(table: Table) -> float:
    """Loss (m) a failed run counts as: the table's worst successful loss (1 m if none)."""
    ok = table.success & np.isfinite(table.loss)
    return float(table.loss[ok].max()) if ok.any() else 1.0


def penalized_loss(table: Table) -> np.ndarray:
    """(K,) losses (m) with failures replaced by the failure penalty."""
    ok = table.success & np.isfinite(table.loss)
    return np.where(ok, table.loss, failure_penalty(table))


def bandwidth(xy: np.ndarray) -> float:
    """Median nearest-neighbour distance of fan-layout points (K, 2)."""
    if len(xy) < 2:
        return 1.0
    d = np.linalg.norm(xy[:, None, :] - xy[None, :, :], axis=-1)
    np.fill_diagonal(d, np.inf)
    return float(np.median(d.min(axis=1)))


def smoothed_loss(table: Table, sigma: float | None = None) -> np.ndarray:
    """(K,) neighbourhood-smoothed loss (m) of every fan point of `table` (rule step 2)."""
    xy = fan_xy(table.height_ratio, table.tilt_deg)
    s = bandwidth(xy) if sigma is None else float(sigma)
    d = np.linalg.norm(xy[:, None, :] - xy[None, :, :], axis=-1)
    w = np.exp(-0.5 * (d / s) ** 2) * (d <= CUTOFF_SIGMAS * s)
    return (w @ penalized_loss(table)) / w.sum(axis=1)


@dataclass(frozen=True)
class Choice:
    """A chosen fan point and where it came from (losses in m)."""

    point: int
    height_ratio: float
    tilt_deg: float
    scenarios: tuple[str, ...]
    distances: tuple[float, ...]
    expected_loss: float  # blended smoothed loss at the point
    raw_loss: float  # simulated loss at the point in the nearest table (NaN if it failed there)


def nearest(tables: Mapping[str, Table], feats: Mapping[str, float], exclude: tuple[str, ...] = (),
            blend_margin: float = DEFAULT_BLEND_MARGIN) -> list[tuple[str, float]]:
    """[(scenario, distance)] of the tables used for `feats`, nearest first (rule step 1)."""
    cands = sorted(((normalized_distance(feats, t.features), n) for n, t in tables.items()
                    if n not in exclude and t.success.any()))  # a table without a success cannot choose
    if not cands:
        raise ValueError("no lookup table to choose from" + (f" (excluding {', '.join(exclude)})" if exclude else ""))
    d0 = cands[0][0]
    return [(n, d) for d, n in cands if d <= d0 + blend_margin]


def choose(tables: Mapping[str, Table], feats: Mapping[str, float], exclude: tuple[str, ...] = (),
           blend_margin: float = DEFAULT_BLEND_MARGIN, robust: bool = True,
           tie_margin: float = DEFAULT_TIE_MARGIN) -> Choice:
    """The robust choice for scenario features `feats` (robust=False: the raw argmin of
    the nearest table, for comparison; tie_margin applies to the robust rule only)."""
    used = nearest(tables, feats, exclude, blend_margin if robust else 0.0)
    if not robust:
        used = used[:1]
    first = tables[used[0][0]]
    common = set(first.point.tolist())
    # a table blended in must hold every point of the nearest one: intersecting with a
    # partial table would restrict the choice to the few points it has simulated
    used = used[:1] + [(n, d) for n, d in used[1:] if common <= set(tables[n].point.tolist())]
    pts = np.array(sorted(common))
    score = np.zeros(len(pts))
    wsum = 0.0
    for n, dist in used:
        t = tables[n]
        vals = smoothed_loss(t) if robust else penalized_loss(t)
        idx = {p: i for i, p in enumerate(t.point.tolist())}
        w = 1.0 / (1.0 + dist)
        score += w * vals[[idx[p] for p in pts]]
        wsum += w
    score /= wsum
    raw = penalized_loss(first)[[int(np.flatnonzero(first.point == p)[0]) for p in pts]]
    if robust:  # equal within the margin: nearest the middle of the fan first
        f = fan()
        mid = fan_xy(f[[middle_of_fan()], 0], f[[middle_of_fan()], 1])
        off_middle = np.linalg.norm(fan_xy(f[pts, 0], f[pts, 1]) - mid, axis=1)
        off_middle[score > score.min() + tie_margin] = np.inf
        order = np.lexsort((pts, raw, np.round(score, 12), np.round(off_middle, 12)))
    else:
        order = np.lexsort((pts, raw, np.round(score, 12)))
    p = int(pts[order[0]])
    k = int(np.flatnonzero(first.point == p)[0])
    return Choice(p, float(first.height_ratio[k]), float(first.tilt_deg[k]), tuple(n for n, _ in used),
                  tuple(float(d) for _, d in used), float(score[order[0]]),
                  float(first.loss[k]) if first.success[k] else math.nan)
