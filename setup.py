"""ament_python package clothfold_ros: `ros2 run clothfold_ros <node>` after colcon build."""
import os
import runpy
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "clothfold_ros"
HERE = os.path.dirname(os.path.abspath(__file__))
# the node executables, from the one list (standard library only, so it loads without the package's dependencies)
NODES = runpy.run_path(os.path.join(HERE, PACKAGE, "nodes", "backends.py"))["NODES"]
# the lookup-table files an install carries, from the same list the tests read
RESOURCES = runpy.run_path(os.path.join(HERE, PACKAGE, "nodes", "resources.py"))

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch", glob("launch/*.py")),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.csv")),
    ]
    + RESOURCES["table_data_files"](),  # config/tables/<scenario>/ without the final meshes; config/tables_1k2
    # (the first coarse tables, for comparison) stays in the checkout
    package_data={PACKAGE: ["py.typed"]},
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="clothfold maintainers",
    maintainer_email="maintainers@clothfold.dev",
    description="Two-parameter Bezier shirt folding on ROS 2 with an IPC cloth simulator.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [f"{n} = {PACKAGE}.nodes.{n}:main" for n in NODES]
        + [f"clothfold = {PACKAGE}.cli:main"],
    },
)
