"""Where the CPU time of one lookup-table run goes: cProfile of a sweep job (scenario, fan
point) with the sweep's own settings, and the share of subspace Newton directions.

    python scripts/profile_table_run.py SCENARIO POINT [--tables config/tables_12k]
                                        [--seconds S] [--top 25] [--out run.prof]

Reads the scenario's settings.json (and start.npz of a sequence stage) from its sweep
directory under --tables, runs the fan point as `clothfold sweep` would (one thread), and
prints the functions by own time, the Newton directions solved on a subspace and the
share of vertices those held. --seconds stops the run early (a profile of its first part).
The row is printed when the run completes; nothing is written to the table.
"""
from __future__ import annotations

import argparse
import cProfile
import json
import pstats
import signal
import sys
from pathlib import Path

import numpy as np

from clothfold_ros.lookup import sweep_dir as layout
from clothfold_ros.lookup.sweep import Job, run_job
from clothfold_ros.sim.simulator import ClothSimulator
from clothfold_ros.trajectory import fan


class _Stop(Exception):
    pass


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenario")
    ap.add_argument("point", type=int)
    ap.add_argument("--tables", default="config/tables_12k", help="tables root holding <scenario>/settings.json")
    ap.add_argument("--seconds", type=int, default=0, help="stop after this many wall seconds (0: the whole run)")
    ap.add_argument("--top", type=int, default=25)
    ap.add_argument("--out", help="also write the cProfile data here")
    args = ap.parse_args()
    d = Path(args.tables) / args.scenario
    if not (d / layout.SETTINGS).exists():
        print(f"no sweep settings in {d}", file=sys.stderr)
        return 2
    settings = layout.read_settings(d)
    f = fan()
    start = layout.start_file(d)
    job = Job(settings, args.point, float(f[args.point, 0]), float(f[args.point, 1]),
              None if start is None else str(start))

    shares: list[float | None] = []  # per Newton direction: subspace vertex share, None = full
    direction = ClothSimulator._direction

    def recording(self, data, grad, when, sub=None):
        shares.append(None if sub is None else float(sub.active.mean()))
        return direction(self, data, grad, when, sub)

    ClothSimulator._direction = recording

    def stop(*_):
        raise _Stop

    if args.seconds:
        signal.signal(signal.SIGALRM, stop)
        signal.alarm(args.seconds)
    prof = cProfile.Profile()
    prof.enable()
    try:
        row, _ = run_job(job)
        done = True
    except _Stop:
        done = False
    prof.disable()
    signal.alarm(0)
    ClothSimulator._direction = direction
    print(json.dumps(row) if done else f"stopped after {args.seconds} s (a profile of the run's first part)")
    sub = [s for s in shares if s is not None]
    print(f"Newton directions {len(shares)}, on a subspace {len(sub)}"
          + (f" (vertex share median {np.median(sub):.2f}, 10-90 % {np.quantile(sub, 0.1):.2f}-"
             f"{np.quantile(sub, 0.9):.2f})" if sub else ""))
    if args.out:
        prof.dump_stats(args.out)
    pstats.Stats(prof).sort_stats("tottime").print_stats(args.top)
    return 0


if __name__ == "__main__":
    sys.exit(main())
