"""Where the CPU time of one lookup-table run goes: cProfile of a sweep job (scenario, fan
point) with the sweep's own settings, and the share of subspace Newton directions.

    python scripts/profile_table_run.py SCENARIO POINT [--tables config/tables]
                                        [--seconds S | --steps K] [--top 25] [--out run.prof]

Reads the scenario's settings.json (and start.npz of a sequence stage) from its sweep
directory under --tables, runs the fan point as `clothfold sweep` would (one thread), and
prints the functions by own time, the Newton directions solved on a subspace and the
share of vertices those held. --seconds stops the run early (a profile of its first part);
--steps K stops it after K simulator steps, a deterministic cut. Either way the CPU seconds
and a digest (SHA-1) of the cloth's vertex positions after the last step are printed: two
checkouts whose digests agree computed the same bits, so a change meant to be exact is
checked by running the same command on both. The row is printed when the run completes;
nothing is written to the table.
"""
from __future__ import annotations

import argparse
import cProfile
import hashlib
import json
import pstats
import signal
import sys
import time
from pathlib import Path

import numpy as np

from clothfold_ros.lookup import sweep_dir as layout
from clothfold_ros.lookup.sweep import Job, run_job
from clothfold_ros.sim.simulator import ClothSimulator
from clothfold_ros.trajectory import fan


class _Stop(BaseException):
    """Ends the run early (not an Exception: run_job records those as failed simulations)."""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenario")
    ap.add_argument("point", type=int)
    ap.add_argument("--tables", default="config/tables", help="tables root holding <scenario>/settings.json")
    ap.add_argument("--seconds", type=int, default=0, help="stop after this many wall seconds (0: the whole run)")
    ap.add_argument("--steps", type=int, default=0, help="stop after this many simulator steps (0: the whole run)")
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
    state = {"steps": 0, "digest": "none"}  # simulator steps taken and the digest after the last
    step = ClothSimulator.step

    def counting(self, *a, **k):
        out = step(self, *a, **k)
        state["steps"] += 1
        state["digest"] = hashlib.sha1(np.ascontiguousarray(self.x).tobytes()).hexdigest()
        if args.steps and state["steps"] >= args.steps:
            raise _Stop
        return out

    ClothSimulator.step = counting

    def stop(*_):
        raise _Stop

    if args.seconds:
        signal.signal(signal.SIGALRM, stop)
        signal.alarm(args.seconds)
    prof = cProfile.Profile()
    cpu = time.process_time()
    prof.enable()
    try:
        row, _ = run_job(job)
        done = True
    except _Stop:
        done = False
    prof.disable()
    cpu = time.process_time() - cpu
    signal.alarm(0)
    ClothSimulator._direction, ClothSimulator.step = direction, step
    print(json.dumps(row) if done else "stopped early (a profile of the run's first part)")
    print(f"steps {state['steps']}, CPU {cpu:.1f} s (profiled), state digest {state['digest']}")
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
