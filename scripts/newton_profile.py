"""Where the Newton iterations of a fold go: per-step iterations and, for the converging tail
(iterations whose step is below --tail m/s), which cloth carries the remaining Newton step.

    python scripts/newton_profile.py [--area 2e-4] [--steps 40 70] [--h 0.4462 --tilt 51.43]
                                     [--mu 0.5] [--material cotton] [--config '{"eps_v": 1e-2}'] [--history]

Prints the total iterations over steps 1..B, per step A..B its iterations (and with --history
the residual RMS(|dx|)/dt of every iteration), and the share of the squared Newton step in
the tail on held vertices, free vertices in the air (z > 4 t) and vertices low on the table
or the cloth. A step that fails is reported with its last residuals. Default fold otherwise
(shape 1, cotton, left sleeve, T 4 s, dt 0.04 s).
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict

import numpy as np

from clothfold_ros.folding import fold_spec
from clothfold_ros.garment import make_shirt
from clothfold_ros.loss import fold_target
from clothfold_ros.materials import material
from clothfold_ros.sim.config import SimConfig
from clothfold_ros.sim.episode import FoldEpisode
from clothfold_ros.sim.runner import flat_start
from clothfold_ros.sim.simulator import ClothSimulator, SimulationFailure
from clothfold_ros.trajectory import FoldTrajectory


class ProfiledSimulator(ClothSimulator):
    """Records the residual of every Newton direction and, in the tail, where the step lies."""

    def __init__(self, *args, tail: float = 5e-3, **kwargs):
        super().__init__(*args, **kwargs)
        self.tail, self.history, self.share, self.tail_iterations = tail, [], defaultdict(float), 0
        self.thickness = kwargs.get("material", args[2]).thickness

    def _direction(self, data, grad, when, sub=None):
        p = super()._direction(data, grad, when, sub)
        n2 = np.sum(p**2, axis=1)
        r = float(np.sqrt(n2.mean())) / self.dt
        self.history.append(r)
        if r < self.tail and n2.sum() > 0:
            held = np.zeros(len(p), bool)
            held[self.grasped_vertex_ids()] = True
            air = ~held & (self.x[:, 2] > 4 * self.thickness)
            for name, mask in (("held", held), ("air", air), ("low", ~held & ~air)):
                self.share[name] += n2[mask].sum() / n2.sum()
            self.tail_iterations += 1
        return p


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--area", type=float, default=2e-4)
    ap.add_argument("--steps", type=int, nargs=2, default=(40, 70), metavar=("A", "B"))
    ap.add_argument("--h", type=float, default=0.4462)
    ap.add_argument("--tilt", type=float, default=51.43)
    ap.add_argument("--mu", type=float, default=0.5)
    ap.add_argument("--material", default="cotton", help="material preset (materials.MATERIALS)")
    ap.add_argument("--config", default="{}", help="SimConfig overrides as JSON")
    ap.add_argument("--tail", type=float, default=5e-3, help="tail: Newton steps below this (m/s)")
    ap.add_argument("--history", action="store_true")
    a = ap.parse_args(argv)
    cot = material(a.material)
    g = make_shirt(1, max_area=a.area)
    start = flat_start(g, cot)
    spec = fold_spec("left_sleeve", g.keypoints(start))
    sim = ProfiledSimulator(start, g.triangles, cot, a.mu, SimConfig(**json.loads(a.config)), rest=start, tail=a.tail)
    episode = FoldEpisode(sim, spec, fold_target(start, spec, cot.thickness), 0.2)
    trajectory = FoldTrajectory(spec, a.h, a.tilt, 4.0)
    print(f"{len(g.triangles)} triangles, {cot.name}, h {a.h}, tilt {a.tilt}, mu {a.mu}, config {a.config}")
    episode.grasp()
    total = 0
    for k in range(1, a.steps[1] + 1):
        if k == a.steps[0]:
            sim.share.clear()
            sim.tail_iterations = 0
        sim.history.clear()
        try:
            stats = episode.advance(trajectory.poses_at(k * sim.dt))
        except SimulationFailure as err:
            print(f"step {k} FAILED: {err}; last residuals: " + " ".join(f"{r:.1e}" for r in sim.history[-12:]))
            break
        total += stats.newton_iterations
        if k >= a.steps[0]:
            line = (f"step {k}: {stats.newton_iterations} iterations, {stats.line_search_halvings} halvings, "
                    f"{stats.contacts} contacts, kappa {stats.kappa:.3g}")
            if a.history:
                line += ": " + " ".join(f"{r:.1e}" for r in sim.history)
            print(line)
    print(f"total Newton iterations, steps 1..{k}: {total}")
    if sim.tail_iterations:
        shares = {n: round(float(v) / sim.tail_iterations, 3) for n, v in sim.share.items()}
        print(f"tail (steps {a.steps[0]}..{k}, {sim.tail_iterations} iterations below {a.tail:g} m/s): share of "
              f"the squared Newton step {shares}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
