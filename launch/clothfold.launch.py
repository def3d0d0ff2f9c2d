"""ROS 2 launch file for a real ROS install: `ros2 launch clothfold_ros clothfold.launch.py [backend:=kinematic]`.

Same nodes and parameters as the pure-Python `clothfold launch` (clothfold_ros/cli/launcher.py):
config/clothfold.yaml, the sim backend by default. The backends, their nodes and what each
needs (keypoint_node's source, /clock) come from clothfold_ros/nodes/backends.py; with
backend:=kinematic the keypoints come from the flat model shirt. On a real robot start your
driver instead of both backends (backend:=none) and a perception node publishing /keypoints
(docs/robot-interface.md).

Arguments:
  backend       a name in clothfold_ros.nodes.backends.BACKENDS: sim | kinematic | none (default sim)
  use_sim_time  true | false for keypoint_node, fold_planner_node, trajectory_node; default
                true with a simulated backend (it publishes /clock), false with backend:=none
                (a real driver publishes no /clock)
  lookahead     trajectory_node.lookahead (s): how far ahead of the clock targets are
                streamed; given, it overrides the parameters file; default: the parameters
                file's (config/clothfold.yaml: 0.2, >= the simulated backends' dt); 0 for a
                driver that executes each target on receipt
  perception    true | false (default true): false starts no keypoint_node, for your own
                perception node publishing /keypoints
  params_file   parameters YAML (default: share/clothfold_ros/config/clothfold.yaml)
"""
import os

from ament_index_python.packages import get_package_share_directory
from clothfold_ros.nodes.backends import BACKENDS, DEFAULT_BACKEND, PIPELINE
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node

PACKAGE = "clothfold_ros"
PARAMS_FILE = "clothfold.yaml"


def _by_backend(backend: LaunchConfiguration, values: dict[str, str]) -> PythonExpression:
    """An expression that picks values[backend] (a string) when the launch runs."""
    return PythonExpression([repr(values), "['", backend, "']"])


def _if_backend(backend: LaunchConfiguration, name: str, also: LaunchConfiguration | None = None) -> IfCondition:
    """True when the backend is `name` (and, given `also`, that true | false argument is true)."""
    extra = [] if also is None else [" and '", also, "' == 'true'"]
    return IfCondition(PythonExpression(["'", backend, f"' == '{name}'", *extra]))


def generate_launch_description() -> LaunchDescription:
    default_params = os.path.join(get_package_share_directory(PACKAGE), "config", PARAMS_FILE)
    backend = LaunchConfiguration("backend")
    params = LaunchConfiguration("params_file")
    sim_time = {"use_sim_time": LaunchConfiguration("use_sim_time")}
    actions = [
        DeclareLaunchArgument("backend", default_value=DEFAULT_BACKEND, choices=list(BACKENDS),
                              description=" | ".join(f"{n} ({b.help})" for n, b in BACKENDS.items())),
        DeclareLaunchArgument("use_sim_time",
                              default_value=_by_backend(backend, {n: str(b.clock).lower() for n, b in BACKENDS.items()}),
                              description="pipeline nodes on /clock (default: true where the backend publishes it)"),
        DeclareLaunchArgument("lookahead", default_value="",
                              description="trajectory_node.lookahead (s), overriding the parameters file's; "
                                          "0 for a driver executing on receipt (default: the file's)"),
        DeclareLaunchArgument("perception", default_value="true", choices=["true", "false"],
                              description="start keypoint_node (false: your own perception node publishes /keypoints)"),
        DeclareLaunchArgument("params_file", default_value=default_params, description="parameters YAML"),
    ]
    for name, b in BACKENDS.items():
        if b.node:
            actions.append(Node(package=PACKAGE, executable=b.node, name=b.node, parameters=[params], output="screen",
                                condition=_if_backend(backend, name)))
    lookahead = LaunchConfiguration("lookahead")
    perception = LaunchConfiguration("perception")
    for node in PIPELINE:
        if node == "keypoint_node":  # one per backend: its keypoint source, where it needs one
            for name, b in BACKENDS.items():
                source = [{"source": b.keypoint_source}] if b.keypoint_source else []
                actions.append(Node(package=PACKAGE, executable=node, name=node, parameters=[params, sim_time, *source],
                                    output="screen", condition=_if_backend(backend, name, perception)))
        elif node == "trajectory_node":  # lookahead only when given: else the parameters file's value stands
            for given in (True, False):
                extra = [{"lookahead": lookahead}] if given else []
                actions.append(Node(package=PACKAGE, executable=node, name=node, parameters=[params, sim_time, *extra],
                                    output="screen",
                                    condition=IfCondition(PythonExpression(["'", lookahead, f"' {'!=' if given else '=='} ''"]))))
        else:
            actions.append(Node(package=PACKAGE, executable=node, name=node, parameters=[params, sim_time],
                                output="screen"))
    return LaunchDescription(actions)
