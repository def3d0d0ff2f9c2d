"""Linear-solver benchmark: one Newton matrix of the default fold, factorized and solved by
PARDISO with the simulator's settings (3x3 vertex blocks, minimum degree, mixed precision:
single-precision factorization refined in double to a relative residual of 1e-8) and with
the previous ones (the same blocks factorized in double precision), in the same run; the
matrix entry by entry (CSR, double) for reference.

    python bench/bench_linear.py [--areas 2e-4 5e-5] [--steps 3] [--repeat 10] [--threads 2]

`--threads N` adds the current settings on N MKL threads (CNR mode) and checks that the
solution is bit-for-bit the one-thread solution.

For each mesh it steps the default left-sleeve fold `--steps` steps, takes the last Newton
matrix (diagonally scaled, as the simulator factorizes it), and prints per setting the
median analysis, factorization and solve times over `--repeat` repetitions, the relative
residual, and the ratios current / previous.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from clothfold_ros.folding import fold_spec  # noqa: E402
from clothfold_ros.garment import make_shirt  # noqa: E402
from clothfold_ros.loss import fold_target  # noqa: E402
from clothfold_ros.materials import material  # noqa: E402
from clothfold_ros.sim.config import SimConfig  # noqa: E402
from clothfold_ros.sim.episode import FoldEpisode  # noqa: E402
from clothfold_ros.sim.linear_solver import PardisoSPD  # noqa: E402
from clothfold_ros.sim.runner import flat_start  # noqa: E402
from clothfold_ros.sim.simulator import ClothSimulator  # noqa: E402
from clothfold_ros.trajectory import FoldTrajectory  # noqa: E402

SETTINGS = {  # name: (3x3 blocks, precision)
    "current (3x3 blocks, mixed precision)": (True, "mixed"),
    "previous (3x3 blocks, double)": (True, "double"),
    "entries (CSR, double)": (False, "double"),
}


class Capture(ClothSimulator):
    """Keeps the last scaled Newton matrix it factorized (as blocks and entry by entry) and
    its right-hand side."""

    def _direction(self, data, grad, when):
        pat = self._pattern
        scale = 1.0 / np.sqrt(data[pat.diag_slots])
        scaled = pat.scaled(data, scale)
        upper = pat.matrix(scaled)
        upper.sort_indices()
        self.captured = dict(blocks=(scaled, pat.indptr.copy(), pat.indices.copy(), pat.block),
                             entries=(upper.data, upper.indptr, upper.indices, 1), rhs=-scale * grad)
        return super()._direction(data, grad, when)


def newton_matrix(area: float, steps: int):
    cot = material("cotton")
    g = make_shirt(1, max_area=area)
    start = flat_start(g, cot)
    spec = fold_spec("left_sleeve", g.keypoints(start))
    sim = Capture(start, g.triangles, cot, 0.5, SimConfig(), rest=start)
    ep = FoldEpisode(sim, spec, fold_target(start, spec, cot.thickness), 0.2)
    traj = FoldTrajectory(spec, 0.4462, 51.43, 4.0)
    ep.grasp()
    for k in range(1, steps + 1):
        ep.advance(traj.poses_at(k * sim.dt))
    return len(g.triangles), sim.captured


def measure(matrix, full: sp.csr_matrix, rhs, repeat: int, threads: int = 1, precision: str = "mixed") -> dict:
    data, indptr, indices, block = matrix
    t_a, t_f, t_s = [], [], []
    for _ in range(repeat):
        s = PardisoSPD(threads=threads, precision=precision)
        s.set_pattern(indptr, indices, block)
        tic = time.perf_counter()
        s.factor(data)  # analysis + first factorization
        t_a.append(time.perf_counter() - tic)
        tic = time.perf_counter()
        s.factor(data)
        t_f.append(time.perf_counter() - tic)
        tic = time.perf_counter()
        x = s.solve(rhs)
        t_s.append(time.perf_counter() - tic)
    res = float(np.linalg.norm(full @ x - rhs) / np.linalg.norm(rhs))
    factor = float(np.median(t_f))
    return dict(analysis=float(np.median(t_a)) - factor, factor=factor, solve=float(np.median(t_s)),
                residual=res, x=x)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--areas", type=float, nargs="+", default=[2e-4, 5e-5])
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--threads", type=int, default=1, help="also time the current settings on this many threads")
    a = ap.parse_args(argv)
    for area in a.areas:
        tris, cap = newton_matrix(area, a.steps)
        rhs = cap["rhs"]
        upper_data, upper_indptr, upper_indices, _ = cap["entries"]
        n = len(rhs)
        upper = sp.csr_matrix((upper_data, upper_indices, upper_indptr), shape=(n, n))
        full = (upper + sp.triu(upper, k=1).T).tocsr()
        print(f"max area {area:g} m^2: {tris} triangles, {n} unknowns, {upper.nnz} upper nonzeros in "
              f"{len(cap['blocks'][2])} upper 3x3 blocks (Newton matrix of step {a.steps})")
        rows = {name: measure(cap["blocks" if blocks else "entries"], full, rhs, a.repeat, precision=precision)
                for name, (blocks, precision) in SETTINGS.items()}
        for name, r in rows.items():
            print(f"  {name:42s} analysis {r['analysis'] * 1e3:7.2f} ms  factor {r['factor'] * 1e3:7.2f} ms"
                  f"  solve {r['solve'] * 1e3:6.2f} ms  residual {r['residual']:.1e}")
        cur, prev, _ = rows.values()
        print(f"  ratio current / previous: analysis {cur['analysis'] / prev['analysis']:.2f}, factor "
              f"{cur['factor'] / prev['factor']:.2f}, solve {cur['solve'] / prev['solve']:.2f}, factor + solve (one "
              f"Newton iteration) {(cur['factor'] + cur['solve']) / (prev['factor'] + prev['solve']):.2f}")
        if a.threads > 1:
            t = measure(cap["blocks"], full, rhs, a.repeat, a.threads)
            print(f"  current on {a.threads} threads: factor {t['factor'] * 1e3:7.2f} ms  solve {t['solve'] * 1e3:6.2f} ms"
                  f"  ratio to one thread: factor {t['factor'] / cur['factor']:.2f}, solve {t['solve'] / cur['solve']:.2f}; "
                  f"solution bit-for-bit equal: {np.array_equal(t['x'], cur['x'])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
