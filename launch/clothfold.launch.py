"""ROS 2 launch file for a real ROS install: `ros2 launch clothfold_ros clothfold.launch.py [backend:=kinematic]`.

Same nodes and parameters as the pure-Python `clothfold launch` (clothfold_ros/launcher.py):
config/clothfold.yaml, the sim backend by default; with backend:=kinematic the keypoints come
from the flat model shirt. On a real robot start your driver instead of both backends
(backend:=none) and a perception node publishing /keypoints (docs/robot-interface.md).

Arguments:
  backend       sim | kinematic | none (default sim)
  use_sim_time  true | false for keypoint_node, fold_planner_node, trajectory_node; default
                true with a simulated backend (it publishes /clock), false with backend:=none
                (a real driver publishes no /clock)
  lookahead     trajectory_node.lookahead (s): how far ahead of the clock targets are
                streamed; default 0.2 (>= the simulated backends' dt); 0 for a driver that
                executes each target on receipt
  params_file   parameters YAML (default: share/clothfold_ros/config/clothfold.yaml)
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node

PACKAGE = "clothfold_ros"
EXECUTABLES = ("cloth_sim_node", "kinematic_robot_node", "keypoint_node", "fold_planner_node", "trajectory_node")
PARAMS_FILE = "clothfold.yaml"
BACKENDS = ("sim", "kinematic", "none")


def generate_launch_description() -> LaunchDescription:
    default_params = os.path.join(get_package_share_directory(PACKAGE), "config", PARAMS_FILE)
    backend = LaunchConfiguration("backend")
    params = LaunchConfiguration("params_file")
    sim_time = {"use_sim_time": LaunchConfiguration("use_sim_time")}
    is_sim = PythonExpression(["'", backend, "' == 'sim'"])
    is_kinematic = PythonExpression(["'", backend, "' == 'kinematic'"])
    return LaunchDescription([
        DeclareLaunchArgument("backend", default_value="sim", choices=list(BACKENDS),
                              description="sim | kinematic | none (a real driver)"),
        DeclareLaunchArgument("use_sim_time",
                              default_value=PythonExpression(["'false' if '", backend, "' == 'none' else 'true'"]),
                              description="pipeline nodes on /clock (default: true unless backend:=none)"),
        DeclareLaunchArgument("lookahead", default_value="0.2",
                              description="trajectory_node.lookahead (s); 0 for a driver executing on receipt"),
        DeclareLaunchArgument("params_file", default_value=default_params, description="parameters YAML"),
        Node(package=PACKAGE, executable="cloth_sim_node", name="cloth_sim_node", parameters=[params],
             output="screen", condition=IfCondition(is_sim)),
        Node(package=PACKAGE, executable="kinematic_robot_node", name="kinematic_robot_node", parameters=[params],
             output="screen", condition=IfCondition(is_kinematic)),
        Node(package=PACKAGE, executable="keypoint_node", name="keypoint_node",
             parameters=[params, sim_time, {"source": PythonExpression(["'model' if '", backend,
                                                                        "' == 'kinematic' else 'cloth_state'"])}],
             output="screen"),
        Node(package=PACKAGE, executable="fold_planner_node", name="fold_planner_node", parameters=[params, sim_time],
             output="screen"),
        Node(package=PACKAGE, executable="trajectory_node", name="trajectory_node",
             parameters=[params, sim_time, {"lookahead": LaunchConfiguration("lookahead")}], output="screen"),
    ])
