"""sim/scene.py: one scene builder with one set of defaults and one validity check."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from clothfold_ros.garment import DEFAULT_MAX_AREA
from clothfold_ros.materials import DEFAULT_FRICTION, material
from clothfold_ros.sim.config import SimConfig
from clothfold_ros.sim.scene import SceneSettings, build_scene

PKG = Path(__file__).resolve().parents[1] / "clothfold_ros"


def test_defaults_come_from_one_place():
    s = SceneSettings()
    assert (s.dt, s.newton_tol, s.max_newton_iterations) == (SimConfig.dt, SimConfig.newton_tol,
                                                              SimConfig.max_newton_iterations)
    assert s.friction == DEFAULT_FRICTION and s.max_area == DEFAULT_MAX_AREA


@pytest.mark.parametrize("bad, word", [
    ({"friction": math.inf}, "friction"), ({"friction": math.nan}, "friction"), ({"friction": -0.1}, "friction"),
    ({"shape": 4}, "shape"), ({"material": "silk"}, "material"), ({"max_area": 0.0}, "max_area"),
    ({"max_area": math.nan}, "max_area"), ({"dt": 0.0}, "dt"), ({"newton_tol": math.inf}, "newton_tol"),
    ({"max_newton_iterations": 0}, "max_newton_iterations"),
])
def test_bad_settings_are_refused_by_name(bad, word):
    with pytest.raises(ValueError, match=word):
        SceneSettings(**bad)


def test_scene_lies_flat_and_its_simulator_has_its_settings():
    s = SceneSettings(shape=2, max_area=5e-3, material="wool", friction=0.8, dt=0.05, newton_tol=2e-3,
                      max_newton_iterations=50)
    scene = build_scene(s)
    t = material("wool").thickness
    assert np.allclose(scene.flat[:, 2], 2 * t) and np.allclose(scene.flat[:, :2], scene.garment.vertices[:, :2])
    assert (scene.config.dt, scene.config.newton_tol, scene.config.max_newton_iterations) == (0.05, 2e-3, 50)
    sim = scene.simulator()
    assert sim.friction_coefficient == 0.8 and sim.material.name == "wool" and sim.config is scene.config
    assert np.array_equal(sim.x, scene.flat)


def test_the_three_simulator_set_ups_use_the_builder():
    for f in ("cli/simulate.py", "lookup/sweep.py", "nodes/cloth_sim_node.py"):
        src = (PKG / f).read_text()
        assert "build_scene(SceneSettings(" in src, f
        for own in ("SimConfig(", "make_shirt(", "flat_start("):  # each builds its own part of a scene
            assert own not in src, (f, own)
