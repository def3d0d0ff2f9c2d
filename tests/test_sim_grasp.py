"""Grasp springs through a stack of cloth layers, slip, and determinism on a 3K-triangle shirt."""
from __future__ import annotations

import numpy as np

from clothfold_ros.folding import fold_spec
from clothfold_ros.garment import make_shirt
from clothfold_ros.materials import MATERIALS
from clothfold_ros.pose import Pose
from clothfold_ros.sim import ClothSimulator, SimConfig
from clothfold_ros.sim.runner import flat_start
from clothfold_ros.trajectory import FoldTrajectory
from sim_helpers import intersection_free, rectangle

COTTON = MATERIALS["cotton"]
T = COTTON.thickness


def _two_layers():
    """A 20 x 10 cm strip whose right half lies folded onto its left half (one mesh, two layers)."""
    v, f = rectangle(0.2, 0.1, 2e-4, 2 * T, origin=(-0.1, -0.05))
    x = v.copy()
    right = x[:, 0] > 0.0
    x[right, 0] = -x[right, 0]
    x[right, 2] = 4 * T  # the folded half rests one layer offset above the other
    return v, x, f


def test_a_gripper_holds_every_layer_of_a_stack_and_lifts_it_without_failing():
    rest, x, f = _two_layers()
    sim = ClothSimulator(x, f, COTTON, friction=0.5, rest=rest)
    pose = Pose.from_axes([-0.08, 0.0, 3 * T], [0, 0, 1], [1, 0, 0])  # at the stack's edge, approaching +x
    held = sim.grasp(0, pose)
    layers = rest[held, 0] > 0.0
    assert layers.any() and (~layers).any()  # both layers are held (every triangle with a vertex in the box)
    for k in range(1, 13):  # up 4 cm in 8 steps, then 4 cm sideways
        offset = [0.0, 0.0, 0.005 * k] if k <= 8 else [0.01 * (k - 8), 0.0, 0.04]
        st = sim.step({0: Pose(pose.position + offset, pose.quaternion)})
        assert intersection_free(sim)
        assert st.grasp_lag < 2e-3
    lifted = sim.x[held, 2] - x[held, 2]
    assert np.median(lifted) > 0.03  # the held stack went up with the gripper


def test_held_cloth_driven_into_cloth_below_lags_and_slips_instead_of_failing():
    """The gripper presses the held stack down by one layer: the top layer's grip points go
    where the bottom layer lies. Contact holds the top layer back (it lags), it slips in the
    grip, and the step never fails (the study's rigid box would force an intersection)."""
    rest, x, f = _two_layers()
    sim = ClothSimulator(x, f, COTTON, friction=0.5, rest=rest, config=SimConfig(grasp_slip=1e-4))
    pose = Pose.from_axes([-0.08, 0.0, 3 * T], [0, 0, 1], [1, 0, 0])
    held = sim.grasp(0, pose)
    lags, slipped = [], 0
    for k in range(1, 6):
        down = Pose(pose.position - [0.0, 0.0, min(k, 2) * T], pose.quaternion)
        st = sim.step({0: down})
        assert intersection_free(sim)
        lags.append(st.grasp_lag)
        slipped += st.slipped
    assert max(lags) > 1e-4  # contact held the cloth back: it lagged behind its grip points ...
    assert slipped > 0  # ... and slipped in the grip rather than failing the step
    assert np.all(sim.x[held, 2] > T)  # nothing went through the offset above the table


def test_a_3k_triangle_fold_is_bit_for_bit_reproducible():
    """Two runs of the first steps of the default sleeve fold on 3K triangles are identical
    (threaded numba kernels, PARDISO, the persistent pattern and the broad-phase cache), and
    so is a run with PARDISO on two threads (MKL's conditional numerical reproducibility)."""
    g = make_shirt(1, max_area=2e-4)
    x0 = flat_start(g, COTTON)
    spec = fold_spec("left_sleeve", g.keypoints(x0))
    traj = FoldTrajectory(spec, 0.4462, 51.43, 4.0)
    assert len(g.triangles) > 2500

    def once(solver_threads=1):
        sim = ClothSimulator(x0, g.triangles, COTTON, 0.5, rest=x0, config=SimConfig(solver_threads=solver_threads))
        sim.grasp(0, spec.start_poses[0])
        its = 0
        for k in range(1, 9):
            its += sim.step({0: traj.poses_at(k * sim.dt)[0]}).newton_iterations
        return sim.x, its

    (a, ia), (b, ib), (c, ic) = once(), once(), once(solver_threads=2)
    assert ia > 8  # Newton actually iterated
    assert np.array_equal(a, b)
    assert np.array_equal(a, c) and ia == ic
