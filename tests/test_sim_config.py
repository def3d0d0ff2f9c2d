"""SimConfig checks every setting on creation: ValueError naming the field and the value."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from clothfold_ros.sim.config import SimConfig

NAN, INF = math.nan, math.inf

BAD = [
    ("psd_projection", "ABS"), ("psd_projection", "Clamp"), ("psd_projection", None),
    ("linear_solver", "nope"), ("linear_solver", "PARDISO"), ("linear_precision", "half"),
    ("dt", INF), ("dt", NAN), ("dt", 0.0), ("dt", -0.04), ("dt", "0.04"), ("dt", True),
    ("gravity", (0.0, 0.0, NAN)), ("gravity", (INF, 0.0, -9.81)), ("gravity", (0.0, -9.81)),
    ("gravity", (0.0, 0.0, -9.81, 0.0)), ("gravity", "xyz"), ("gravity", None), ("gravity", (0.0, 0.0, "g")),
    ("newton_tol", NAN), ("newton_tol", INF), ("newton_tol", 0.0),
    ("newton_window", 0), ("newton_window", 1.0),
    ("force_tol", 0.0), ("force_tol", -1e-3), ("force_tol", NAN), ("force_tol", INF), ("force_tol", "0.01"),
    ("max_newton_iterations", 0), ("max_newton_iterations", 2.5), ("max_newton_iterations", True),
    ("max_line_search_halvings", 0), ("max_line_search_halvings", 1075),
    ("model_ratio", -0.1), ("model_ratio", 1.0), ("model_ratio", NAN),
    ("grasp_stiffness", 0.0), ("grasp_stiffness", INF), ("grasp_stiffness", NAN),
    ("grasp_slip", 0.0), ("grasp_slip", -1e-3), ("grasp_slip", INF),
    ("pattern_growth_rings", -1), ("pattern_growth_rings", 0.5), ("pattern_keep_solves", 0),
    ("pattern_prune_fraction", -0.1), ("pattern_prune_fraction", 1.5), ("pattern_prune_fraction", NAN),
    ("pattern_growth_iterations", 0), ("pattern_growth_iterations", 2.5),
    ("xi", -1.0), ("xi", 0.0), ("xi", INF), ("xi", NAN), ("dhat", 0.0), ("dhat", -1e-3), ("dhat", INF),
    ("ccd_fraction", 0.0), ("ccd_fraction", 2.0), ("ccd_fraction", NAN),
    ("eps_v", 0.0), ("eps_v", -1.0), ("eps_v", INF),
    ("broad_phase_reuse", -1e-4), ("broad_phase_reuse", INF), ("broad_phase_reuse", NAN),
    ("table_margin", -0.01), ("table_margin", NAN),
    ("regularization_shifts", (1e-12, INF)), ("regularization_shifts", (NAN,)), ("regularization_shifts", ("a",)),
    ("regularization_shifts", (1e-6, 1e-8)),
    ("subspace_threshold", NAN), ("subspace_threshold", INF), ("subspace_start", 0), ("subspace_rings", -1),
    ("subspace_max_share", 0.0), ("subspace_max_share", NAN),
    ("check_intersections", "yes"), ("check_intersections", None),
    ("threads", 0), ("threads", 1.5), ("ccd_threads", 0), ("solver_threads", 0),
]


@pytest.mark.parametrize(("field", "value"), BAD, ids=[f"{f}={v!r}" for f, v in BAD])
def test_bad_setting_is_refused_naming_field_and_value(field, value):
    with pytest.raises(ValueError) as err:
        SimConfig(**{field: value})
    assert field in str(err.value) and repr(value) in str(err.value), str(err.value)


def test_defaults_and_valid_edges_construct_unchanged():
    """The defaults, every setting the repository passes and the edges of each range are
    accepted, and the values are stored as given (validation only)."""
    from clothfold_ros.sim.scene import SceneSettings

    default = SimConfig()
    assert dataclasses.replace(default) == default
    SceneSettings().config()
    a = 0.3
    good = dict(
        dt=np.float64(0.01), gravity=(9.81 * np.sin(a), 0.0, -9.81 * np.cos(a)), newton_tol=1e-6, newton_window=2,
        max_newton_iterations=np.int64(3000), max_line_search_halvings=1074, model_ratio=0.0, grasp_slip=1e-4,
        psd_projection="abs", pattern_growth_rings=2, pattern_keep_solves=3, pattern_prune_fraction=1.0,
        pattern_growth_iterations=400, linear_solver="superlu", linear_precision="double", xi=1e-4, dhat=2e-4,
        ccd_fraction=1.0, eps_v=1e-2, broad_phase_reuse=0.0, table_margin=0.0, regularization_shifts=(),
        subspace_threshold=0.0, subspace_start=1, subspace_rings=0, subspace_max_share=1.0,
        check_intersections=np.bool_(False), threads=4, ccd_threads=2, solver_threads=8)
    cfg = SimConfig(**good)
    for k, v in good.items():
        assert getattr(cfg, k) is v, k
    for backend in ("pardiso", "auto"):
        SimConfig(linear_solver=backend, psd_projection="clamp")


def test_simulation_inputs_are_checked_before_any_step():
    """A motion shorter than half a step (it was grasped, released and called a success), a NaN
    or misshaped rest shape (NaN masses, then 'non-positive diagonal' at the first step), a NaN
    fold target (found only after the whole fold) and an infinite settle time: ValueErrors that
    name them."""
    import math

    import numpy as np
    import pytest

    from clothfold_ros.folding import fold_spec
    from clothfold_ros.garment import make_shirt
    from clothfold_ros.materials import material
    from clothfold_ros.plan import FoldPlan
    from clothfold_ros.sim.episode import FoldEpisode
    from clothfold_ros.sim.runner import flat_start, run_plan
    from clothfold_ros.sim.simulator import ClothSimulator

    g = make_shirt(1, max_area=5e-3)
    cotton = material("cotton")
    spec = fold_spec("left_sleeve", g.keypoints())
    with pytest.raises(ValueError, match="shorter than half a simulator step"):
        run_plan(g, FoldPlan(spec, 0.5, 30.0, duration=0.01, settle_time=0.0), cotton, 0.5)
    x = flat_start(g, cotton)
    bad = x.copy()
    bad[3, 0] = math.nan
    with pytest.raises(ValueError, match="rest shape .* must be finite"):
        ClothSimulator(x, g.triangles, cotton, 0.5, rest=bad)
    with pytest.raises(ValueError, match="rest shape .* must be shape"):
        ClothSimulator(x, g.triangles, cotton, 0.5, rest=x[:-1])
    sim = ClothSimulator(x, g.triangles, cotton, 0.5)
    with pytest.raises(ValueError, match="fold target .* must be finite"):
        FoldEpisode(sim, spec, bad)
    with pytest.raises(ValueError, match="settle_time must be finite"):
        FoldEpisode(sim, spec, x, settle_time=math.inf)
    assert FoldEpisode(sim, spec, x).target.shape == x.shape


def test_a_start_inside_the_contact_offset_is_named():
    """Cloth laid 0.1 mm above the table, within cotton's 0.318 mm offset: a ValueError naming the
    vertex and the offset (it failed at the first step with 'CCD allows no step (contact locked)')."""
    import numpy as np
    import pytest

    from clothfold_ros.garment import make_shirt
    from clothfold_ros.materials import material
    from clothfold_ros.sim.simulator import ClothSimulator

    g = make_shirt(1, max_area=5e-3)
    low = g.vertices.copy()
    low[:, 2] = 1e-4
    with pytest.raises(ValueError, match=r"lies 0\.1000 mm above the table, within the contact offset 0\.3180 mm"):
        ClothSimulator(low, g.triangles, material("cotton"), 0.5)
    low[:, 2] = 4e-4
    assert ClothSimulator(low, g.triangles, material("cotton"), 0.5).x[:, 2].min() == pytest.approx(4e-4)
