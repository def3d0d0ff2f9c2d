"""ROS 2 launch file for a real ROS install: `ros2 launch clothfold_ros clothfold.launch.py [backend:=kinematic]`.

Same nodes and parameters as the pure-Python `clothfold launch` (clothfold_ros/launcher.py):
config/clothfold.yaml, the sim backend by default; with backend:=kinematic the keypoints come
from the flat model shirt. On a real robot start your driver instead of both backends
(backend:=none) and a perception node publishing /keypoints (docs/robot-interface.md).
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


def generate_launch_description() -> LaunchDescription:
    params = os.path.join(get_package_share_directory(PACKAGE), "config", PARAMS_FILE)
    backend = LaunchConfiguration("backend")
    is_sim = PythonExpression(["'", backend, "' == 'sim'"])
    is_kinematic = PythonExpression(["'", backend, "' == 'kinematic'"])
    return LaunchDescription([
        DeclareLaunchArgument("backend", default_value="sim", description="sim | kinematic | none"),
        Node(package=PACKAGE, executable="cloth_sim_node", name="cloth_sim_node", parameters=[params],
             output="screen", condition=IfCondition(is_sim)),
        Node(package=PACKAGE, executable="kinematic_robot_node", name="kinematic_robot_node", parameters=[params],
             output="screen", condition=IfCondition(is_kinematic)),
        Node(package=PACKAGE, executable="keypoint_node", name="keypoint_node",
             parameters=[params, {"source": PythonExpression(["'model' if '", backend,
                                                              "' == 'kinematic' else 'cloth_state'"])}],
             output="screen"),
        Node(package=PACKAGE, executable="fold_planner_node", name="fold_planner_node", parameters=[params],
             output="screen"),
        Node(package=PACKAGE, executable="trajectory_node", name="trajectory_node", parameters=[params],
             output="screen"),
    ])
