"""The five-fold sequence headless on a coarse mesh: every stage, side and middle folds from
folded states included, completes; each is planned from the visible keypoints of the cloth.
(At 2e-3 m^2 the folds are crude; the test is about completing, not about the losses.)"""
from __future__ import annotations

import math

import numpy as np

from clothfold_ros.sim.scene import SceneSettings, build_scene
from clothfold_ros.sim.sequence import run_sequence

CHOICES = {"left_sleeve": (0.723, 30.0), "right_sleeve": (1.0, 17.6), "left_side": (0.45, 0.0),
           "right_side": (0.45, 0.0), "middle": (0.45, 0.0)}


def test_the_five_folds_complete_from_the_cloth_as_it_is():
    scene = build_scene(SceneSettings(max_area=2e-3))
    results = run_sequence(scene, CHOICES)
    assert [r.fold for r in results] == list(CHOICES)
    for r in results:
        assert r.outcome.success, (r.fold, r.outcome.reason)
        assert math.isfinite(r.outcome.loss)
    # both middle grippers grasp cloth that lies inside the flat hem (the side folds moved the
    # hem corners in); where exactly is tested on ideally folded shirts
    # (tests/test_perception_visible.py): this mesh folds too coarsely for that
    flat_kp = scene.garment.keypoints(scene.flat)
    half = abs(flat_kp["bottom_right"][0] - flat_kp["bottom_left"][0]) / 2
    grips = np.array([p.position[0] for p in results[-1].spec.start_poses])
    assert np.all(np.abs(grips) < half), grips
    # later stages start from where the previous one ended
    assert not np.allclose(results[2].outcome.vertices, scene.flat)
