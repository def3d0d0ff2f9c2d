"""ament_python package clothfold_ros: `ros2 run clothfold_ros <node>` after colcon build."""
import os
import runpy
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "clothfold_ros"
# the node executables, from the one list (standard library only, so it loads without the package's dependencies)
NODES = runpy.run_path(os.path.join(os.path.dirname(os.path.abspath(__file__)), PACKAGE, "nodes", "backends.py"))["NODES"]

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
    + [  # lookup tables, config/tables/<scenario>/: the tables, provenance, settings and run logs (the planner,
        # `clothfold tables`, `regret`, `plot`'s landscapes); the sweeps' final meshes (about 9 MB a table) and the
        # first coarse tables (config/tables_1k2) stay in the checkout
        (f"share/{PACKAGE}/{d}", sorted(glob(f"{d}/*.csv") + glob(f"{d}/*.json") + glob(f"{d}/*.jsonl")))
        for d in sorted(glob("config/tables/*/"))
    ],
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
