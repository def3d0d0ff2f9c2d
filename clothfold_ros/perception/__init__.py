"""Perception core (no rclpy): folded-state keypoint semantics (`visible`), a down-looking
depth camera model (`camera`) and the point-cloud keypoint estimator (`estimator`)."""
