#!/usr/bin/env python3
"""Per-node CPU of a launched pipeline: idle, folding, idle again (issue 39).

Starts the pipeline of --backend as separate processes (what `clothfold launch` starts) on a
private ROS domain with localhost-only discovery, waits until it is up (keypoints published,
then --settle s for the start-up work to end), and reads each node's CPU time (user + system,
the node's whole process group, from /proc) over three windows:

  idle         --idle s with nothing to do
  folding      from the /plan_fold call of each --fold to its /fold/result
  idle-after   --idle s once the folds are over

and prints CPU % of one core per node, the sum over the nodes, and the /clock messages a
subscriber received per second in each window (this script's own CPU, which includes that
subscriber and the fold client, is printed apart and not counted in the sum). With
--backend none (no driver, no /clock) only the idle window is measured.

    source .venv/clothfold_env.sh
    python scripts/measure_node_cpu.py --backend kinematic --idle 10
    python scripts/measure_node_cpu.py --backend sim --idle 10 --max-area 2e-3
    python scripts/measure_node_cpu.py --backend none --idle 10
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

TICK = os.sysconf("SC_CLK_TCK")


def group_cpu_seconds(pgid: int) -> float:
    """User + system CPU seconds of every live process in process group pgid (children's
    reaped time included through cutime/cstime)."""
    total = 0
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                stat = f.read()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()  # after "pid (comm) "
        if int(fields[2]) != pgid:  # field 5: pgrp
            continue
        total += sum(int(v) for v in fields[11:15])  # utime stime cutime cstime
    return total / TICK


def self_cpu_seconds() -> float:
    t = os.times()
    return t.user + t.system


class Window:
    """CPU seconds of each process and of this script between start() and stop()."""

    def __init__(self, name: str, procs, client) -> None:
        self.name, self.procs, self.client = name, procs, client

    def start(self) -> "Window":
        self.t0 = time.monotonic()
        self.cpu0 = {p.name: group_cpu_seconds(p.pid) for p in self.procs}
        self.self0 = self_cpu_seconds()
        self.clock0 = self.client.clock_count() if self.client else 0
        return self

    def stop(self) -> "Window":
        self.wall = time.monotonic() - self.t0
        self.cpu = {p.name: group_cpu_seconds(p.pid) - self.cpu0[p.name] for p in self.procs}
        self.self_cpu = self_cpu_seconds() - self.self0
        self.clock_rate = ((self.client.clock_count() - self.clock0) / self.wall) if self.client else 0.0
        return self

    def percent(self, name: str) -> float:
        return 100.0 * self.cpu[name] / self.wall


def report(windows: list[Window], names: list[str]) -> str:
    width = max(len(n) for n in [*names, "sum over the nodes", "this script (client)"]) + 2
    head = "".join(f"{w.name:>14}" for w in windows)
    lines = [f"{'':<{width}}{head}", f"{'window (wall s)':<{width}}" + "".join(f"{w.wall:>14.1f}" for w in windows)]
    for n in names:
        lines.append(f"{n:<{width}}" + "".join(f"{w.percent(n):>13.1f}%" for w in windows))
    lines.append(f"{'sum over the nodes':<{width}}" + "".join(
        f"{sum(w.percent(n) for n in names):>13.1f}%" for w in windows))
    lines.append(f"{'this script (client)':<{width}}" + "".join(
        f"{100 * w.self_cpu / w.wall:>13.1f}%" for w in windows))
    lines.append(f"{'/clock msgs per s':<{width}}" + "".join(f"{w.clock_rate:>14.1f}" for w in windows))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--backend", default="kinematic", choices=("kinematic", "sim", "none"))
    p.add_argument("--idle", type=float, default=10.0, help="wall seconds of each idle window (default 10)")
    p.add_argument("--settle", type=float, default=5.0,
                   help="wall seconds after start-up before measuring (default 5)")
    p.add_argument("--fold", action="append", default=None, metavar="FOLD",
                   help="fold(s) run in the folding window, in order (default left_sleeve; none with --no-fold)")
    p.add_argument("--no-fold", action="store_true", help="measure the idle window only")
    p.add_argument("--max-area", type=float, default=None, help="sim backend: mesh max triangle area (m^2)")
    p.add_argument("--domain-id", type=int, default=None, help="ROS_DOMAIN_ID (default from the process id)")
    p.add_argument("-p", "--param", action="append", default=[], metavar="NODE:NAME:=VALUE",
                   help="parameter override (repeatable), as for clothfold launch")
    p.add_argument("--json", type=Path, default=None, metavar="FILE",
                   help="also write the figures as JSON: {window: {wall, nodes: {name: percent}, sum, clock_rate}}")
    args = p.parse_args(argv)

    from clothfold_ros.cli.launch import parse_overrides
    from clothfold_ros.cli.launcher import Launcher

    domain = args.domain_id if args.domain_id is not None else 200 + os.getpid() % 30
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    overrides = parse_overrides(args.param)
    if args.backend == "sim" and args.max_area is not None:
        overrides.setdefault("cloth_sim_node", {})["max_area"] = args.max_area
    folds = [] if args.no_fold or args.backend == "none" else (args.fold or ["left_sleeve"])
    from clothfold_ros.nodes.pipeline_client import PipelineClient

    with Launcher(domain_id=domain, echo=False) as launcher:
        launcher.start_pipeline(args.backend, overrides=overrides)
        names = [pr.name for pr in launcher.procs]
        print(f"backend {args.backend}, ROS_DOMAIN_ID {domain}: {', '.join(names)}", flush=True)
        with PipelineClient("measure_node_cpu") as client:
            if args.backend != "none":
                client.wait_keypoints(180)
            time.sleep(args.settle)
            launcher.check_alive()
            windows = [Window("idle", launcher.procs, client).start()]
            time.sleep(args.idle)
            windows[-1].stop()
            if folds:
                w = Window("folding", launcher.procs, client).start()
                for fold in folds:
                    before = client.result_count()
                    r = client.plan(fold, execute=True, timeout=120, retry_refused=10.0)
                    if not r.success:
                        print(f"{fold}: refused: {r.message}", file=sys.stderr)
                        return 1
                    res = client.wait_result(fold, 900, after=before)
                    print(f"{fold}: {'success' if res.success else 'FAILED ' + res.reason}, {res.steps} steps",
                          flush=True)
                windows.append(w.stop())
                after = Window("idle-after", launcher.procs, client).start()
                time.sleep(args.idle)
                windows.append(after.stop())
            launcher.check_alive()
        print(report(windows, names), flush=True)
    if args.json is not None:
        import json

        args.json.write_text(json.dumps({w.name: {
            "wall": w.wall, "nodes": {n: w.percent(n) for n in names}, "sum": sum(w.percent(n) for n in names),
            "client": 100 * w.self_cpu / w.wall, "clock_rate": w.clock_rate} for w in windows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
