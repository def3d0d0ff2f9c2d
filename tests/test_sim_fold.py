"""The issue-3 fold check: the default shirt's left sleeve at a coarse resolution.

(h, tilt) = (0.45, 51.4) must fold clearly better (the other loss over 1.3 times its own, or the other run fails) than (0.1, 60), (1.0, 0) must fold, and
the good loss must be below 2 cm, the method's threshold of a failed sleeve fold (with grasp springs
instead of the rigid box it measured 10.2 mm, 8.9 mm rigid; coarse meshes are chaotic for
this fold: at 3K the same point ended 2.6 mm and 10.8 mm with two solver variants that
differ only in how the Hessian pattern grows, measured when this check was written). 5e-4 m^2 triangles (about 1.2K) is the coarsest mesh that
folds without dragging the whole shirt: at 1e-3 m^2 and above, triangles of 4-6 cm
cannot buckle, the sleeve pushes the body across the table and no (h, tilt) folds well.
A failed simulation counts as worse than any completed fold (it is reported, not hidden).
Every accepted step is checked intersection-free by the simulator itself
(SimConfig.check_intersections, on by default).
"""
from __future__ import annotations

import math

import pytest

from clothfold_ros.folding import fold_spec
from clothfold_ros.garment import make_shirt
from clothfold_ros.materials import material
from clothfold_ros.sim.runner import flat_start, run_fold

COARSE = 5e-4  # m^2 max triangle area


@pytest.fixture(scope="module")
def outcomes():
    cotton = material("cotton")
    garment = make_shirt(1, max_area=COARSE)
    spec = fold_spec("left_sleeve", garment.keypoints(flat_start(garment, cotton)))
    return {
        (h, tilt): run_fold(garment, spec, cotton, 0.5, h, tilt, duration=4.0)
        for h, tilt in [(0.45, 51.4), (1.0, 0.0), (0.1, 60.0)]
    }


def _loss(outcome) -> float:
    return outcome.loss if outcome.success else math.inf


def test_good_fold_is_not_a_failed_fold(outcomes):
    good = outcomes[(0.45, 51.4)]
    assert good.success, good.reason
    assert good.loss < 0.02
    assert all(s.min_distance > 0 for s in good.step_stats)


def test_good_fold_beats_the_flat_path_and_the_steep_one_folds(outcomes):
    """The low, tilted path (0.1, 60) drags the sleeve instead of lifting it over: clearly
    worse at every resolution measured (12K: 7.6 mm against 2.2 mm; 1.2K, tight reference
    tolerance: 35 mm against 4-13 mm at the seven other points of the benchmark's fan
    subset). The low untilted path (0.1, 0) is not: at 12K it folds to
    2.8 mm, and at this resolution its rank against (0.45, 51.4) flips with solver details.
    The steep (1.0, 0) path also folds at this resolution, so it only has to complete."""
    good = _loss(outcomes[(0.45, 51.4)])
    flat = outcomes[(0.1, 60.0)]
    assert _loss(flat) > 1.3 * good, (flat.success, flat.reason, flat.loss)
    if not flat.success:
        assert flat.reason  # a failure always says why
    steep = outcomes[(1.0, 0.0)]
    assert steep.success and steep.loss < 0.02, (steep.reason, steep.loss)


def test_a_one_second_fold_does_not_cycle_on_a_vertex_sliding_past_its_sticking_point():
    """Regression (issue 10): the 1-s sleeve fold at (h 0.1, tilt 0) on 3K triangles hit the
    Newton cap at t = 0.28 s: a vertex lying on the table jumped +-9.75 mm about its sticking
    point while the rest of the cloth still lowered the energy. With the friction overshoot
    damping (sim/friction.py) every step of the stretch converges well below a cap of 150."""
    from clothfold_ros.loss import fold_target
    from clothfold_ros.sim.config import SimConfig
    from clothfold_ros.sim.episode import FoldEpisode
    from clothfold_ros.sim.simulator import ClothSimulator
    from clothfold_ros.trajectory import FoldTrajectory

    cotton = material("cotton")
    g = make_shirt(1, max_area=2e-4)
    start = flat_start(g, cotton)
    spec = fold_spec("left_sleeve", g.keypoints(start), 170.0)
    sim = ClothSimulator(start, g.triangles, cotton, 0.5, SimConfig(max_newton_iterations=150), rest=start)
    episode = FoldEpisode(sim, spec, fold_target(start, spec, cotton.thickness), 0.2)
    trajectory = FoldTrajectory(spec, 0.1, 0.0, 1.0)
    episode.grasp()
    iterations = [episode.advance(trajectory.poses_at(k * sim.dt)).newton_iterations for k in range(1, 9)]
    assert max(iterations) < 150, iterations
    assert sim.contact.friction.damped.any()  # the damping is what ended the cycle
