"""The "On a real ROS 2 install" section of README.md, executed: a colcon build of this checkout
(clothfold_msgs from msg_defs/ and clothfold_ros) into a temporary workspace, then the installed
`clothfold demo --backend kinematic`, which starts every node from that install and resolves its
parameters and lookup tables through the ament index. Here the venv plays the ROS install
(`source /opt/ros/jazzy/setup.bash` sources a file that points at it), a copy of the working
tree plays the clone, `rosdep` is skipped and `ros2 run clothfold_ros X` runs
install/clothfold_ros/lib/clothfold_ros/X (what ros2 run executes). Also: package.xml names
every ROS package the code imports, and the Python ones have a rosdep key or are in the pip line."""
from __future__ import annotations

import ast
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
VENV = Path(sys.prefix)
DOMAIN = 158
ROSDEP_KEYS = {"numpy": "python3-numpy", "scipy": "python3-scipy", "yaml": "python3-yaml",
               "matplotlib": "python3-matplotlib", "shapely": "python3-shapely", "cv2": "python3-opencv"}


def readme_block() -> list[str]:
    text = (ROOT / "README.md").read_text()
    section = text[text.index("### On a real ROS 2 install"):]
    block = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    return [ln for ln in block.splitlines() if ln.strip()]


def translate(line: str, setup: Path, clone: Path) -> str:
    """The README line as run on this machine (see the module docstring)."""
    if line.startswith("source /opt/ros/"):
        return f"source {setup}"
    if line.startswith("git clone "):
        return f"cp -r {clone} {line.split()[-1]}"
    if line.startswith("rosdep "):
        return ": rosdep skipped"
    return re.sub(r"\bros2 run (\w+) ", r"install/\1/lib/\1/", line)


@pytest.fixture(scope="module")
def install_run(tmp_path_factory):
    if shutil.which("colcon") is None:
        pytest.fail("colcon is not installed: pip install colcon-common-extensions (.ci/run does)")
    tmp = tmp_path_factory.mktemp("install")
    clone = tmp / "clone"
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT, check=True,
                           capture_output=True).stdout.decode().split("\0")
    for f in filter(None, files):
        if (ROOT / f).is_file():
            (clone / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / f, clone / f)
    setup = tmp / "ros_setup.bash"
    setup.write_text(f"""# the venv as a ROS 2 Jazzy install (what /opt/ros/jazzy/setup.bash provides)
export AMENT_PREFIX_PATH={VENV}
export PATH={VENV}/bin:$PATH
export LD_LIBRARY_PATH={VENV}/lib
unset PYTHONPATH CLOTHFOLD_ROOT COLCON_PREFIX_PATH
export ROS_DOMAIN_ID={DOMAIN} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST RMW_IMPLEMENTATION=rmw_fastrtps_cpp
""")
    script = "set -eo pipefail\n" + "\n".join(translate(ln, setup, clone) for ln in readme_block()) + "\n"
    (tmp / "readme.sh").write_text(script)
    proc = subprocess.run(["bash", str(tmp / "readme.sh")], cwd=tmp, capture_output=True, text=True, timeout=1200,
                          env={"HOME": str(tmp), "PATH": "/usr/bin:/bin", "LANG": "C.UTF-8"})
    return tmp / "clothfold_ws", proc


def test_readme_install_commands_build_and_fold(install_run):
    ws, proc = install_run
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-6000:]
    assert "Summary: 2 packages finished" in out, out[-3000:]
    share = ws / "install" / "clothfold_ros" / "share" / "clothfold_ros"
    assert f"[demo] parameters {share / 'config' / 'clothfold.yaml'}" in out, out[-3000:]
    assert "left_sleeve: success" in out and "bag closed" in out, out[-3000:]
    assert (ws / "bags" / "install-check.mcap").is_file()
    lib = ws / "install" / "clothfold_ros" / "lib" / "clothfold_ros"
    for exe in ("player_node", "recorder_node", "trajectory_node", "kinematic_robot_node", "clothfold"):
        assert (lib / exe).is_file(), exe
    assert (share / "config" / "tables" / "middle" / "table.csv").is_file()
    assert (share / "config" / "tables" / "shape1" / "table.csv").is_file()
    assert not (share / "config" / "tables_1k2").exists()  # the first coarse tables stay in the checkout
    assert (share / "config" / "tables" / "shape1" / "runs.jsonl").is_file()  # `clothfold tables` reads the run logs
    assert not (share / "config" / "tables" / "shape1" / "finals.npz").exists()  # sweep data stay in the checkout
    from clothfold_ros.nodes.resources import table_data_files  # the list the installed-tables fixture copies
    wanted = {f"{dest}/{Path(f).name}" for dest, files in table_data_files(ROOT) for f in files}
    got = {str(p.relative_to(share.parents[1])) for p in (share / "config" / "tables").rglob("*") if p.is_file()}
    assert got == wanted, (got ^ wanted)


def test_installed_resources_resolve_through_the_ament_index(install_run):
    ws, proc = install_run
    install = ws / "install"
    site = install / "clothfold_ros" / "lib" / "python3.11" / "site-packages"
    code = ("from clothfold_ros.nodes import resources as r\n"  # what fold_planner_node.resolve_dirs uses for table_dir
            "print(r.SOURCE_CHECKOUT, r.__file__, r.resource('config/tables'), r.work_dir())\n")
    env = {"PATH": f"{VENV}/bin:/usr/bin:/bin", "AMENT_PREFIX_PATH": f"{install / 'clothfold_ros'}:"
           f"{install / 'clothfold_msgs'}:{VENV}", "PYTHONPATH": str(site), "HOME": str(ws)}
    out = subprocess.run([sys.executable, "-c", code], cwd=ws, env=env, capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    checkout, module, tables, work = out.stdout.split()
    assert checkout == "False" and module.startswith(str(site))
    assert tables == str(install / "clothfold_ros" / "share" / "clothfold_ros" / "config" / "tables")
    assert work == str(ws)


def _imports() -> set[str]:
    names = set()
    for path in (ROOT / "clothfold_ros").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
    return names


def test_package_xml_names_every_dependency():
    deps = {e.text for e in ET.parse(ROOT / "package.xml").getroot() if e.tag.endswith("depend")}
    index = VENV / "share" / "ament_index" / "resource_index" / "packages"
    ros = {n for n in _imports() if (index / n).exists() or n == "clothfold_msgs"} - {"clothfold_ros"}
    assert ros, "no ROS imports found"
    assert not ros - deps, f"ROS packages imported but not in package.xml: {sorted(ros - deps)}"
    pip_line = next(ln for ln in readme_block() if "pip install" in ln).split()
    third = {n for n in _imports() - ros - set(sys.stdlib_module_names) - {"clothfold_ros", "clothfold_msgs"}}
    missing = sorted(n for n in third if ROSDEP_KEYS.get(n) not in deps and n not in pip_line)
    assert not missing, f"Python packages with neither a rosdep key in package.xml nor the README pip line: {missing}"
