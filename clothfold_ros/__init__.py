"""clothfold_ros: two-parameter Bezier shirt folding with an IPC cloth simulator.

The pure core (no ROS import): garment, materials, folding, trajectory, loss, sim/, lookup/,
bag/. ROS adapters live in nodes/; the `clothfold` command in cli/.
"""
__version__ = "0.1.0"
