"""Which state of the shirt a cloud shows, given the folds done so far (plain Python, no ROS).

`estimate_keypoints` fits one hypothesis (a list of folds, optionally from an earlier
estimate). Between stages a perception has more to go on and more to fear: the previous
estimate (`prior`) fixes the hidden parts, but the cloth slides while it is folded, so the
earlier creases may no longer lie where they were fitted; a fold reported failed may have
folded the cloth all the same; the shirt may have been laid flat again. `estimate_state`
tries those hypotheses in tiers and says which one it took:

  1. `prior`: the folds done so far, the previous estimate's shape and fold lines kept, the
     pose and newer lines fitted; and `failed fold`: the same with a fold reported failed
     added (from the prior where there is one);
  2. `prior shape`: the prior's shape kept, every fold line refitted from its pose (the
     cloth slid);
  3. `fresh`: shape, pose and lines fitted from the cloud alone. A folded silhouette is
     ambiguous (a shirt with short sleeves fits one with its sleeves folded; after the
     middle fold a near-rectangle fits turned by 90 deg as well), so while folds are expected
     a fresh fit whose flat shirt is smaller than FLAT_AGAIN_AREA of the one seen flat is not
     taken (with no fold done, a flat cloud of a smaller shirt is taken: a new shirt);
  the best of a tier is taken when its residual is within `good_enough x max_residual`,
  else the lowest residual within `max_residual` over the three tiers;
  4. only when none fits, `flat again`: no folds, a fresh fit, with the same size check.

Frames and units as `estimate_keypoints`: table frame, metres, z up.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .estimator import (BadCloudError, EstimatorConfig, FitError, KeypointEstimate, MultipleBlobsError,
                        NoClothError, PoorFitError, check_fold_names, estimate_keypoints, flat_area)

#: a flat fit of a folded shirt's cloud is taken as the shirt laid flat again from this share
#: of the flat shirt's area as last seen flat
FLAT_AGAIN_AREA = 0.9
#: errors of the cloud itself: no hypothesis can fit it
CLOUD_ERRORS = (BadCloudError, NoClothError, MultipleBlobsError)


@dataclass
class StateEstimate:
    """folds: the folds the cloud was fitted with (the expected ones, one more, or none);
    start: the hypothesis taken ('prior', 'prior shape', 'fresh', 'failed fold', 'flat again');
    estimate: its fit; tried: one line per hypothesis fitted (start, residual or why not);
    warnings: what a node should log (a flat fit not taken as the shirt laid flat again)."""

    folds: list[str]
    start: str
    estimate: KeypointEstimate
    tried: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def smaller_shirt(estimate: KeypointEstimate, flat_shirt_area: float | None) -> str | None:
    """None when the flat shirt of a fit `estimate` is at least FLAT_AGAIN_AREA of
    `flat_shirt_area` m^2 (or no flat shirt was seen), else a phrase saying how much smaller."""
    if flat_shirt_area is None:
        return None
    ratio = flat_area(estimate.shape) / flat_shirt_area
    if ratio >= FLAT_AGAIN_AREA:
        return None
    return f"a flat shirt of {ratio:.0%} the area of the one seen flat"


def estimate_state(points: np.ndarray, folds: Sequence[str], prior: KeypointEstimate | None = None,
                   failed: str | None = None, flat_shirt_area: float | None = None,
                   config: EstimatorConfig = EstimatorConfig()) -> StateEstimate:
    """The state a cloud (N, 3) m, table frame, shows after `folds` (names, in order).

    prior: the last good estimate of this shirt; failed: a fold reported failed since it;
    flat_shirt_area: m^2, the flat shirt's area as last fitted with no fold done (`flat_area`;
    None: not seen). ValueError for unknown or repeated folds or a bad area (before any fit);
    the cloud's `PerceptionError` when the cloud itself is bad; when no hypothesis fits, a
    `PoorFitError` carrying the closest estimate (or, when every fit failed to converge, a
    `FitError`) whose message names every hypothesis tried and why it was not taken."""
    folds = list(folds)
    check_fold_names(folds + ([failed] if failed is not None else []))  # the failed fold is not done yet
    if flat_shirt_area is not None and not (math.isfinite(flat_shirt_area) and flat_shirt_area > 0):
        raise ValueError(f"flat_shirt_area must be a positive area in m^2 (or None), got {flat_shirt_area}")
    tiers: list[list[tuple[str, list[str], dict]]] = [[], [], [("fresh", folds, {})]]
    from_prior = {"prior": prior} if prior is not None else {}
    if prior is not None:
        tiers[0].append(("prior", folds, from_prior))
        if folds:
            tiers[1].append(("prior shape", folds, {"shape_prior": prior.shape, "pose_prior": prior.pose}))
    if failed is not None:
        tiers[0].append(("failed fold", folds + [failed], from_prior))
    last_resort = [("flat again", [], {})] if folds else []

    tried: list[str] = []
    warnings: list[str] = []
    rejected: list[PoorFitError] = []
    errors: list[ValueError] = []
    refused: list[tuple[str, KeypointEstimate]] = []  # fits of a smaller shirt

    def fit(start: str, names: list[str], kwargs: dict) -> KeypointEstimate | None:
        try:
            est = estimate_keypoints(points, folds=names, config=config, **kwargs)
        except CLOUD_ERRORS:
            raise
        except PoorFitError as err:
            rejected.append(err)
            tried.append(f"{start}: residual {err.estimate.residual * 1e3:.1f} mm, over max_residual")
            return None
        except ValueError as err:  # a fit that did not converge or ended in no shirt's shape
            errors.append(err)
            tried.append(f"{start}: {type(err).__name__}: {err}")
            return None
        tried.append(f"{start}: residual {est.residual * 1e3:.1f} mm")
        # folds expected: a fresh fit must find the shirt seen flat (none: a flat cloud may be a new shirt)
        smaller = smaller_shirt(est, flat_shirt_area) if folds and start in ("fresh", "flat again") else None
        if smaller is not None:
            tried[-1] += f", {smaller}"
            warnings.append(f"the cloud fits {smaller}: not taken as the shirt laid flat again (folds {folds})"
                            if start == "flat again" else
                            f"a fresh fit with folds {names} finds {smaller}: not taken (a folded silhouette "
                            "fits a smaller shirt too)")
            refused.append((tried[-1], est))
            return None
        return est

    good = config.good_enough * config.max_residual
    best: tuple[str, list[str], KeypointEstimate] | None = None
    for tier in tiers + [last_resort]:
        if tier is last_resort and best is not None:
            break
        for start, names, kwargs in tier:
            est = fit(start, names, kwargs)
            if est is not None and (best is None or est.residual < best[2].residual):
                best = (start, names, est)
        if best is not None and best[2].residual <= good:
            break
    if best is None:  # every hypothesis named with why it was not taken
        if rejected:
            err = min(rejected, key=lambda e: e.estimate.residual)
            raise PoorFitError(f"no hypothesis fits ({'; '.join(tried)}); the closest: {err}", err.estimate)
        if refused:
            raise PoorFitError(f"the cloud fits only a smaller shirt than the one seen flat ({'; '.join(tried)})",
                               refused[0][1])
        raise FitError(f"no hypothesis fits ({'; '.join(tried)})") from errors[-1]
    start, names, est = best
    return StateEstimate(list(names), start, est, tried, warnings)
