"""Which fan points a sweep runs, and in what order (indices into trajectory.fan())."""
from __future__ import annotations

from typing import Iterable

import numpy as np

from ..trajectory import fan


def fan_points(selection: str = "all") -> np.ndarray:
    """Fan indices (into trajectory.fan()) for a selection:

    - 'all': the 134 points;
    - 'every:R:T': every R-th ring counted down from the outermost (h = 1.0 always kept)
      and, within a kept ring, every T-th tilt from 60 deg with the 0 deg end kept;
    - 'alternate' = 'every:1:2';
    - a comma list of indices.
    """
    f = fan()
    if selection == "all":
        return np.arange(len(f))
    if selection == "alternate":
        selection = "every:1:2"
    if selection.startswith("every:"):
        try:
            r_step, t_step = (int(v) for v in selection.split(":")[1:])
        except ValueError:
            raise ValueError(f"fan selection 'every:R:T' needs two integers, got {selection!r}") from None
        if r_step < 1 or t_step < 1:
            raise ValueError(f"'every:R:T' needs R, T >= 1, got {selection!r}")
        heights = np.unique(f[:, 0])
        keep: list[int] = []
        for i, h in enumerate(heights):
            if (len(heights) - 1 - i) % r_step:
                continue
            ring = np.flatnonzero(f[:, 0] == h)
            j = np.arange(len(ring))
            keep += ring[(j % t_step == 0) | (j == len(ring) - 1)].tolist()
        return np.asarray(sorted(keep))
    try:
        idx = np.asarray(sorted({int(s) for s in selection.split(",") if s.strip()}))
    except ValueError:
        raise ValueError(f"fan points must be 'all', 'alternate', 'every:R:T' or comma-separated indices, "
                         f"got {selection!r}") from None
    if len(idx) == 0 or idx.min() < 0 or idx.max() >= len(f):
        raise ValueError(f"fan indices must be in 0..{len(f) - 1}, got {selection!r}")
    return idx


#: Fan subsamples from coarse to fine (`fan_points` selections): a sweep runs the points of each
#: before those of the next, so a table left partial covers the whole fan, first at the first
#: coarse tables' spacing (config/tables_1k2), rather than the lowest rings only.
COVERAGE_LEVELS: tuple[str, ...] = ("every:4:6", "every:3:3", "every:2:2", "all")


def coverage_order(points: Iterable[int]) -> list[int]:
    """`points` in the order a sweep runs them: by the first of COVERAGE_LEVELS holding each,
    then by fan index."""
    points = [int(p) for p in points]
    n = len(fan())
    outside = sorted({p for p in points if not 0 <= p < n})
    if outside:
        raise ValueError(f"fan indices must be in 0..{n - 1}, got {outside}")
    level: dict[int, int] = {}
    for i, selection in enumerate(COVERAGE_LEVELS):
        for p in fan_points(selection):
            level.setdefault(int(p), i)
    return sorted(points, key=lambda p: (level[p], p))
