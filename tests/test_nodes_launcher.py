"""Launcher (pure Python process manager), launch file and config consistency."""
from __future__ import annotations

import ast
import sys
import time

import yaml

from clothfold_ros.launcher import DEFAULT_PARAMS, ROOT, Launcher, pipeline_nodes


def test_launch_file_names_existing_executables_and_config():
    src = (ROOT / "launch" / "clothfold.launch.py").read_text()
    compile(src, "clothfold.launch.py", "exec")
    tree = ast.parse(src)
    consts = {n.targets[0].id: ast.literal_eval(n.value) for n in tree.body
              if isinstance(n, ast.Assign) and isinstance(n.targets[0], ast.Name)}
    setup = (ROOT / "setup.py").read_text()
    for exe in consts["EXECUTABLES"]:
        assert f'"{exe}"' in setup and (ROOT / "clothfold_ros" / "nodes" / f"{exe}.py").is_file()
        assert f'executable="{exe}"' in src
    assert (ROOT / "config" / consts["PARAMS_FILE"]).is_file()


def test_config_parameters_are_declared():
    from clothfold_ros.nodes import backend, cloth_sim_node, fold_planner_node, keypoint_node, trajectory_node

    declared = {
        "keypoint_node": keypoint_node.PARAMS, "fold_planner_node": fold_planner_node.PARAMS,
        "trajectory_node": trajectory_node.PARAMS,
        "cloth_sim_node": backend.BACKEND_PARAMS + cloth_sim_node.PARAMS,
        "kinematic_robot_node": backend.BACKEND_PARAMS,
    }
    cfg = yaml.safe_load(DEFAULT_PARAMS.read_text())
    for node, ps in declared.items():
        names = {p.name for p in ps} | {"use_sim_time"}
        values = cfg[node]["ros__parameters"]
        assert set(values) <= names, (node, set(values) - names)
        for p in ps:
            if p.name in values:
                assert p.check(values[p.name]) is None, (node, p.name)


def test_pipeline_commands():
    cmds = dict(pipeline_nodes("kinematic", overrides={"trajectory_node": {"rate": 50.0}}))
    assert set(cmds) == {"kinematic_robot_node", "keypoint_node", "fold_planner_node", "trajectory_node"}
    assert "source:=model" in cmds["keypoint_node"] and "rate:=50.0" in cmds["trajectory_node"]
    assert "cloth_sim_node" in dict(pipeline_nodes("sim"))


def test_launcher_escalates_and_leaves_nothing(tmp_path):
    stubborn = ("import signal, subprocess, sys, time\n"
                "signal.signal(signal.SIGINT, signal.SIG_IGN)\n"
                "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'])\n"
                "print('child', child.pid, flush=True)\n"
                "time.sleep(60)\n")
    polite = "import time\ntry:\n    print('up', flush=True); time.sleep(60)\nexcept KeyboardInterrupt:\n    print('bye')\n"
    launcher = Launcher(domain_id=155, echo=False)
    a = launcher.start("stubborn", [sys.executable, "-c", stubborn])
    b = launcher.start("polite", [sys.executable, "-c", polite])
    child = int(launcher.wait_for(a, r"child (\d+)", 20).group(1))
    launcher.wait_for(b, "up", 20)
    tic = time.monotonic()
    codes = launcher.stop_all(timeout=1.0)
    assert time.monotonic() - tic < 10
    assert codes["polite"] == 0 and "bye" in b.lines
    assert codes["stubborn"] != 0
    import os

    time.sleep(0.2)
    try:
        os.kill(child, 0)
        alive = open(f"/proc/{child}/stat").read().split()[2] != "Z"
    except (ProcessLookupError, FileNotFoundError):
        alive = False
    assert not alive, "a grandchild survived"


def test_backend_none_runs_the_pipeline_on_wall_time():
    """A real driver publishes no /clock: backend none starts no backend and the pipeline nodes with
    use_sim_time false; the launch file has the same arguments (use_sim_time, lookahead)."""
    cmds = dict(pipeline_nodes("none"))
    assert set(cmds) == {"keypoint_node", "fold_planner_node", "trajectory_node"}
    for n in cmds:
        assert "use_sim_time:=false" in cmds[n], (n, cmds[n])
    assert "use_sim_time:=true" in dict(pipeline_nodes("sim"))["trajectory_node"]
    assert "lookahead:=0.0" in dict(pipeline_nodes("none", lookahead=0.0))["trajectory_node"]
    tree = ast.parse((ROOT / "launch" / "clothfold.launch.py").read_text())
    declared = {c.args[0].value for c in ast.walk(tree) if isinstance(c, ast.Call)
                and getattr(c.func, "id", "") == "DeclareLaunchArgument"}
    assert {"backend", "use_sim_time", "lookahead"} <= declared, declared
    src = (ROOT / "launch" / "clothfold.launch.py").read_text()
    assert "'false' if '" in src and "== 'none'" in src  # use_sim_time defaults to false with backend:=none
