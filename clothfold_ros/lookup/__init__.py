"""Lookup tables over the 134-point trajectory fan (docs/method.md sections 6, 8, 9).

- `scenario`: the 13 study scenarios and the scenario features (shared with run time)
- `sweep_dir`: the sweep directory's file layout (the only module that knows it)
- `sweep`: the resumable sweep engine (local process pool or Ray); `finish` writes the table
- `table`: tidy CSV tables with provenance
- `select`: robust (neighbourhood-smoothed) choice from the nearest scenario(s)
- `regret`: leave-one-scenario-out evaluation of the selection
- `plot`: loss landscape in the fan layout and best / worst final states
- `planner_selector`: the selector the ROS fold planner plugs in

Pure Python: never imports rclpy. See docs/lookup.md.
"""
