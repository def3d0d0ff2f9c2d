"""Checked numeric arrays: the one validator of shapes and finiteness for the core."""
from __future__ import annotations

import numpy as np


def finite_array(values: object, what: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """`values` as a float array with every entry finite and, if given, this `shape`
    (-1 = any length on that axis); ValueError naming `what` otherwise."""
    a = np.asarray(values, dtype=float)
    if shape is not None and (a.ndim != len(shape) or any(n not in (-1, m) for n, m in zip(shape, a.shape))):
        want = "a 3-vector" if shape == (3,) else "shape (" + ", ".join("N" if n == -1 else str(n) for n in shape) + ")"
        raise ValueError(f"{what} must be {want}, got shape {a.shape}")
    bad = ~np.isfinite(a)
    if bad.any():
        got = f"got {a}" if a.size <= 4 else f"{int(bad.sum())} of {a.size} entries are NaN or inf"
        raise ValueError(f"{what} must be finite, {got}")
    return a
