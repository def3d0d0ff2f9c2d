"""A small process manager for the clothfold nodes (what `ros2 launch` does; no rclpy here).

Each node runs as its own process (`python -m clothfold_ros.nodes.<node> --ros-args
--params-file ... -p name:=value`) in its own process group, with ROS_DOMAIN_ID and
ROS_AUTOMATIC_DISCOVERY_RANGE set. Output lines are prefixed with the node name and kept
for `wait_for`. `stop_all` sends SIGINT to every group, then SIGTERM and SIGKILL after
timeouts, so nothing is left behind; `Launcher` is a context manager that always stops
everything, also on errors and Ctrl-C.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Sequence

from ..nodes.backends import NODES, PIPELINE, backend as get_backend
from ..nodes.resources import DEFAULT_PARAMS, work_dir
from ..nodes.waiting import wait_until


def _fmt(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    return str(value)


def node_command(node: str, params_file: str | Path | None = None, params: dict | None = None,
                 args: Sequence[str] = ()) -> list[str]:
    """Command line of one node: its module under this interpreter, node arguments, then
    --ros-args with the params file and `-p name:=value` overrides.

    A relative params_file is made absolute against the current directory here: the node runs
    in another one (`Launcher.start`: the checkout from source), where it would name another
    file or none."""
    cmd = [sys.executable, "-m", f"clothfold_ros.nodes.{node}", *args]
    ros = []
    if params_file:
        ros += ["--params-file", str(Path(params_file).expanduser().absolute())]
    for k, v in (params or {}).items():
        ros += ["-p", f"{k}:={_fmt(v)}"]
    return cmd + (["--ros-args", *ros] if ros else [])


def pipeline_nodes(backend: str = "sim", params_file: str | Path | None = DEFAULT_PARAMS,
                   overrides: dict[str, dict] | None = None, use_sim_time: bool | None = None,
                   lookahead: float | None = None, perception: bool = True) -> list[tuple[str, list[str]]]:
    """(name, command) of every pipeline node for a backend (nodes/backends.BACKENDS).

    overrides: node name -> {parameter: value}. A backend without cloth (kinematic) sets
    keypoint_node's source (model: the flat model shirt's keypoints). Backend "none" starts
    no backend (a real driver runs instead); a backend that publishes no /clock runs the
    pipeline nodes on wall time (use_sim_time false). use_sim_time / lookahead (s) given
    here set those parameters of the pipeline nodes / trajectory_node (what the launch file's
    arguments of the same names do). perception False leaves keypoint_node out: your own
    perception node publishes /keypoints (docs/robot-interface.md).
    """
    b = get_backend(backend)
    overrides = {k: dict(v) for k, v in (overrides or {}).items()}
    if not perception and overrides.get("keypoint_node"):  # they would be dropped without a word
        raise ValueError("parameters given for keypoint_node, which is not started without perception "
                         "(your own perception node publishes /keypoints)")
    if b.keypoint_source is not None:
        overrides.setdefault("keypoint_node", {}).setdefault("source", b.keypoint_source)
    if use_sim_time is None:
        use_sim_time = b.clock
    for n in PIPELINE:
        overrides.setdefault(n, {}).setdefault("use_sim_time", bool(use_sim_time))
    if lookahead is not None:
        overrides.setdefault("trajectory_node", {})["lookahead"] = float(lookahead)
    names = [n for n in (b.node, *PIPELINE) if n and (perception or n != "keypoint_node")]
    unknown = sorted(set(overrides) - set(NODES))
    if unknown:  # a misspelt node name would otherwise drop its parameters silently (another backend's node:
        # its parameters simply wait, as a shared parameter file's do)
        raise ValueError(f"parameters given for unknown node(s) {', '.join(unknown)}; nodes: {', '.join(NODES)}")
    return [(n, node_command(n, params_file, overrides.get(n))) for n in names]


@dataclass
class Process:
    name: str
    cmd: list[str]
    popen: subprocess.Popen
    lines: list[str] = field(default_factory=list)
    cond: threading.Condition = field(default_factory=threading.Condition)
    reader: threading.Thread | None = None

    @property
    def pid(self) -> int:
        return self.popen.pid

    def alive(self) -> bool:
        return self.popen.poll() is None


class Launcher:
    """Start, watch and stop node processes. Use as a context manager."""

    def __init__(self, domain_id: int | None = None, localhost: bool = True, echo: bool = True,
                 out: IO[str] | None = None, env: dict[str, str] | None = None) -> None:
        if domain_id is not None and not 0 <= int(domain_id) <= 232:
            raise ValueError(f"ROS_DOMAIN_ID must be in 0..232, got {domain_id}")
        self.env = dict(os.environ)
        self.env.update(env or {})
        self.env["PYTHONUNBUFFERED"] = "1"
        if domain_id is not None:
            self.env["ROS_DOMAIN_ID"] = str(int(domain_id))
        if localhost:
            self.env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        self.echo = echo
        self.out = out or sys.stdout
        self._out_lock = threading.Lock()
        self.procs: list[Process] = []

    # -- starting -----------------------------------------------------------------------
    def start(self, name: str, cmd: Sequence[str], cwd: str | Path | None = None) -> Process:
        """Start one process in cwd (default `work_dir()`, not the caller's directory: paths in
        cmd must be absolute unless meant relative to that; node_command makes its params file so)."""
        popen = subprocess.Popen(list(cmd), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                 env=self.env, cwd=str(cwd or work_dir()), start_new_session=True, text=True, bufsize=1,
                                 errors="replace")
        proc = Process(name, list(cmd), popen)
        proc.reader = threading.Thread(target=self._read, args=(proc,), daemon=True, name=f"read-{name}")
        proc.reader.start()
        self.procs.append(proc)
        return proc

    def start_pipeline(self, backend: str = "sim", params_file: str | Path | None = DEFAULT_PARAMS,
                       overrides: dict[str, dict] | None = None, use_sim_time: bool | None = None,
                       lookahead: float | None = None, perception: bool = True) -> list[Process]:
        return [self.start(n, c) for n, c in pipeline_nodes(backend, params_file, overrides, use_sim_time, lookahead,
                                                            perception)]

    def _read(self, proc: Process) -> None:
        assert proc.popen.stdout is not None
        for line in proc.popen.stdout:
            line = line.rstrip("\n")
            with proc.cond:
                proc.lines.append(line)
                proc.cond.notify_all()
            if self.echo:
                with self._out_lock:
                    print(f"[{proc.name}] {line}", file=self.out, flush=True)
        with proc.cond:
            proc.cond.notify_all()

    # -- watching ------------------------------------------------------------------------------
    def wait_for(self, proc: Process, pattern: str, timeout: float) -> re.Match:
        """Wait until a line of proc's output matches the regex; RuntimeError on timeout or exit."""
        rx = re.compile(pattern)
        seen = 0

        def probe() -> re.Match | None:
            nonlocal seen
            for line in proc.lines[seen:]:
                m = rx.search(line)
                if m:
                    return m
            seen = len(proc.lines)
            if not proc.alive() and not (proc.reader and proc.reader.is_alive()):
                raise RuntimeError(f"{proc.name} exited with code {proc.popen.returncode} before printing "
                                   f"{pattern!r}; last output: {proc.lines[-5:]}")
            return None

        m = wait_until(proc.cond, probe, timeout, poll=0.2)
        if m is None:
            raise RuntimeError(f"{proc.name} did not print {pattern!r} within {timeout:g} s")
        return m

    def check_alive(self) -> None:
        """RuntimeError naming every process that has exited."""
        dead = [f"{p.name} (exit code {p.popen.returncode})" for p in self.procs if not p.alive()]
        if dead:
            raise RuntimeError("process exited: " + ", ".join(dead))

    # -- stopping ----------------------------------------------------------------------------------
    @staticmethod
    def _signal(proc: Process, sig: int) -> None:
        try:
            os.killpg(proc.popen.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass

    def stop(self, proc: Process, timeout: float = 10.0, interrupted: bool = False) -> int | None:
        """SIGINT the process group (unless `interrupted`: it has had its SIGINT already), then
        SIGTERM, then SIGKILL; returns the exit code. One SIGINT only: a second one while the
        process runs its shutdown (a recorder closing its bag) would cut that short."""
        for sig, wait in ((signal.SIGINT, timeout), (signal.SIGTERM, 3.0), (signal.SIGKILL, 3.0)):
            if proc.popen.poll() is not None:
                break
            if not (sig == signal.SIGINT and interrupted):
                self._signal(proc, sig)
            try:
                proc.popen.wait(wait)
            except subprocess.TimeoutExpired:
                if sig != signal.SIGKILL:
                    print(f"[launcher] {proc.name} ignored {signal.Signals(sig).name} for {wait:g} s",
                          file=self.out, flush=True)
        self._signal(proc, signal.SIGKILL)  # leftover children in the group
        if proc.reader:
            proc.reader.join(2.0)
        return proc.popen.returncode

    def stop_all(self, timeout: float = 10.0) -> dict[str, int | None]:
        """Stop every process (SIGINT to all at once, then escalate per process)."""
        for p in self.procs:
            if p.alive():
                self._signal(p, signal.SIGINT)
        deadline = time.monotonic() + timeout
        codes = {}
        for p in reversed(self.procs):
            codes[p.name] = self.stop(p, max(0.1, deadline - time.monotonic()), interrupted=True)
        return codes

    def __enter__(self) -> "Launcher":
        return self

    def __exit__(self, *exc) -> None:
        self.stop_all()


class StopSignals:
    """SIGINT and SIGTERM of a command that starts or waits on processes (`launch`, `demo`, `fold`,
    `run`): both raise KeyboardInterrupt in the main thread, and the first one received decides the
    exit status, 128 + its number (130 for SIGINT, 143 for SIGTERM), as a shell reports a process
    those signals killed.

    `install` also undoes an inherited "SIGINT ignored": a non-interactive shell starts its
    background jobs (`clothfold launch ... &` in a script) with SIGINT ignored, so `kill -INT` did
    nothing; and processes started after it inherit the default disposition instead (a handler is
    reset to the default across exec, an ignored signal stays ignored). `ignore` holds both signals
    off while the command cleans up (every stop in it is bounded), `restore` puts back what was there."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.received: int | None = None
        self._old: dict[int, object] = {}

    def install(self) -> "StopSignals":
        for sig in self.SIGNALS:
            old = signal.signal(sig, self._handler)
            self._old.setdefault(sig, signal.default_int_handler if old == signal.SIG_IGN and sig == signal.SIGINT
                                 else old)
        return self

    def _handler(self, signum: int, _frame) -> None:
        if self.received is None:
            self.received = signum
        raise KeyboardInterrupt(signal.Signals(signum).name)

    def ignore(self) -> None:
        for sig in self.SIGNALS:
            signal.signal(sig, signal.SIG_IGN)

    def restore(self) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old if old is not None else signal.SIG_DFL)

    @property
    def name(self) -> str:
        return signal.Signals(self.received).name if self.received else "SIGINT"

    def exit_code(self, code: int) -> int:
        """128 + the signal's number once one was received, else code."""
        return 128 + int(self.received) if self.received else code


def run_until_interrupted(launcher: Launcher, signals: StopSignals | None = None) -> int:
    """Block until SIGINT/SIGTERM or until a process exits; then stop everything. Exit status 130
    after SIGINT, 143 after SIGTERM (StopSignals), 1 when a process exited by itself."""
    signals = signals or StopSignals().install()
    code = 0
    try:
        while True:
            dead = [p for p in launcher.procs if not p.alive()]
            if dead:
                print(f"[launcher] {dead[0].name} exited with code {dead[0].popen.returncode}; stopping all",
                      file=launcher.out, flush=True)
                code = 1
                break
            time.sleep(0.2)
    except KeyboardInterrupt:
        print(f"[launcher] {signals.name}: stopping every process", file=launcher.out, flush=True)
    finally:
        signals.ignore()  # a second Ctrl-C must not cut the clean-up short (every stop in it is bounded)
        try:
            launcher.stop_all()
        finally:
            signals.restore()
    return signals.exit_code(code)
