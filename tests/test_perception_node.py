"""keypoint_node as its own process, fed point clouds and cloth states (isolated ROS domain,
localhost discovery): good, noisy and broken clouds, a camera frame, folds learnt from
/fold/active + /fold/result, folded-state keypoints from the cloth state."""
from __future__ import annotations

import time

import numpy as np
import pytest
from clothfold_msgs.msg import FoldResult, FoldSpec as FoldSpecMsg
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import Marker

from clothfold_ros.nodes import conversions as rc
from clothfold_ros.folding import fold_spec
from clothfold_ros.garment import KEYPOINT_NAMES, make_shirt
from clothfold_ros.cli.launcher import Launcher, node_command
from clothfold_ros.loss import fold_target
from clothfold_ros.nodes import common
from clothfold_ros.nodes.keypoint_node import OUTLINE_TOPIC, cloud_from_msg
from clothfold_ros.perception.camera import DepthCamera
from clothfold_ros.perception.visible import visible_keypoints

DOMAIN_POINTS = 171
DOMAIN_COLOUR = 162
DOMAIN_CAMERA = 172
DOMAIN_STATE = 173
T = 3e-4
S = 1_000_000_000


@pytest.fixture
def env(monkeypatch):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    return monkeypatch


class Feeder:
    """PipelineClient plus publishers of clouds and fold announcements, and the outline marker."""

    def __init__(self, name: str):
        from clothfold_ros.nodes.pipeline_client import PipelineClient

        self.client = PipelineClient(name)
        node = self.client.node
        self.cloud_pub = node.create_publisher(PointCloud2, common.CLOTH_POINTS, common.LATCHED)
        self.active_pub = node.create_publisher(FoldSpecMsg, common.FOLD_ACTIVE, common.LATCHED)
        self.result_pub = node.create_publisher(FoldResult, common.FOLD_RESULT, common.RESULTS)
        self.markers: list[Marker] = []
        node.create_subscription(Marker, OUTLINE_TOPIC, self.markers.append, common.LATCHED)

    def cloud(self, pts: np.ndarray, stamp_ns: int, frame: str = "table", rgb: np.ndarray | None = None) -> None:
        self.cloud_pub.publish(rc.mesh_points(pts, stamp_ns, frame, rgb=rgb))

    def matched(self, timeout: float = 30.0) -> None:
        """Wait until keypoint_node subscribes to the fold announcements: /fold/result is volatile, so a
        result published before discovery completes is lost (the suite loads both cores)."""
        deadline = time.monotonic() + timeout
        while min(self.active_pub.get_subscription_count(), self.result_pub.get_subscription_count()) < 1:
            if time.monotonic() > deadline:
                raise TimeoutError(f"keypoint_node did not subscribe to the fold topics within {timeout:g} s")
            time.sleep(0.05)

    def fold(self, spec, t0_ns: int, success: bool = True) -> None:
        self.matched()
        self.active_pub.publish(rc.fold_spec_to_msg(rc.PlannedFold(spec, 0.5, 30.0, 4.0, 0.2, 0, t0_ns)))
        time.sleep(0.5)
        self.result_pub.publish(FoldResult(header=rc.header(t0_ns + 5 * S), fold_name=spec.name, success=success,
                                           loss=0.005))

    def keypoints(self, newer_than_ns: int, timeout: float = 60.0):
        return rc.keypoints_from_msg(self.client.wait_keypoints(timeout, newer_than_ns=newer_than_ns))

    def close(self):
        self.client.close()


def err_mm(kp: dict, truth: dict) -> np.ndarray:
    return np.array([np.linalg.norm((kp[n] - truth[n])[:2]) for n in KEYPOINT_NAMES]) * 1e3


def test_points_good_bad_and_folded_clouds(env):
    env.setenv("ROS_DOMAIN_ID", str(DOMAIN_POINTS))
    g = make_shirt(1, max_area=5e-4)
    cam = DepthCamera()
    with Launcher(domain_id=DOMAIN_POINTS, echo=False) as launcher:
        node = launcher.start("keypoint_node", node_command(
            "keypoint_node", params={"source": "points", "use_sim_time": True}))  # no /clock: the stamps decide
        launcher.wait_for(node, "estimated from the point cloud", 60)
        feed = Feeder("test_perception_node")
        try:
            feed.cloud(cam.cloud(g.vertices, g.triangles, rng=0), 1 * S)
            kp, ids = feed.keypoints(0)
            assert np.median(err_mm(kp, g.keypoints())) < 10.0
            assert set(ids.values()) == {-1}
            assert rc.keypoint_folds_from_msg(feed.client.keypoints) == []  # the flat shirt's
            launcher.wait_for(node, "residual", 20)
            # broken clouds: logged with the reason, the last good keypoints stay
            feed.cloud(np.zeros((0, 3)), 2 * S)
            launcher.wait_for(node, "BadCloudError: cloud is empty", 20)
            feed.cloud(np.full((2000, 3), np.nan), 3 * S)
            launcher.wait_for(node, "are NaN", 20)
            good = cam.cloud(g.vertices, g.triangles, rng=1)
            feed.cloud(np.vstack([good, good + [1.8, 0.0, 0.0]]), 4 * S)
            launcher.wait_for(node, "MultipleBlobsError", 40)
            rng = np.random.default_rng(0)
            r, a = 0.35 * np.sqrt(rng.random(20000)), rng.uniform(0, 2 * np.pi, 20000)
            feed.cloud(np.column_stack([r * np.cos(a), r * np.sin(a), np.full(20000, 1e-3)]), 5 * S)
            launcher.wait_for(node, "keypoint fit rejected", 40)
            launcher.wait_for(node, "exceeds max_residual", 5)
            feed.cloud(good, 6 * S, frame="camera")
            launcher.wait_for(node, "points_frame", 20)
            for k in range(20):  # a camera in the wrong frame at full rate: every cloud counted, few lines
                feed.cloud(good, 7 * S + k, frame="camera")
                time.sleep(0.02)
            launcher.wait_for(node, r"errors not logged individually: \d+ x \[cloud: .*points_frame"
                                    r"|points_frame.*\(#\d+ of this kind; \d+ more not logged", 15)
            assert sum("cloud frame is" in line for line in node.lines) <= 4, node.lines[-10:]
            deadline = time.monotonic() + 20
            while not any(m.ns == "rejected" for m in feed.markers) and time.monotonic() < deadline:
                time.sleep(0.1)
            assert any(m.ns == "rejected" for m in feed.markers)
            assert any(m.ns == "fitted" and m.type == Marker.LINE_LIST and len(m.points) > 100 for m in feed.markers)
            assert rc.time_to_ns(feed.client.keypoints.header.stamp) == 1 * S  # nothing bad was published
            # a fold: clouds while it runs are not used; after its result the folded state is fitted
            spec = fold_spec("left_sleeve", g.keypoints())
            v = fold_target(g.vertices, spec, T)
            feed.active_pub.publish(rc.fold_spec_to_msg(rc.PlannedFold(spec, 0.5, 30.0, 4.0, 0.2, 0, 10 * S)))
            time.sleep(0.5)
            feed.cloud(cam.cloud(v, g.triangles, rng=2), 12 * S)  # during the fold: kept for later
            time.sleep(1.0)
            assert rc.time_to_ns(feed.client.keypoints.header.stamp) == 1 * S
            feed.result_pub.publish(FoldResult(header=rc.header(15 * S), fold_name="left_sleeve", success=True))
            kp, _ = feed.keypoints(1 * S)  # the cloud taken during the fold, handled after the result
            launcher.wait_for(node, "fold left_sleeve done", 20)
            truth = visible_keypoints(g, v, [spec])
            assert np.median(err_mm(kp, truth)) < 10.0
            assert rc.keypoint_folds_from_msg(feed.client.keypoints) == ["left_sleeve"]
            assert np.linalg.norm((kp["sleeve_top_left"] - truth["sleeve_top_left"])[:2]) < 0.02
            launcher.check_alive()
        finally:
            feed.close()


def test_points_in_a_camera_frame(env):
    """A camera 1 m above the table looking down (x kept, y and z flipped), its fixed transform a parameter."""
    env.setenv("ROS_DOMAIN_ID", str(DOMAIN_CAMERA))
    g = make_shirt(2, max_area=5e-4)
    t = np.array([0.1, -0.05, 1.0])
    table = DepthCamera().cloud(g.vertices, g.triangles, rng=3)
    in_camera = (table - t) * [1.0, -1.0, -1.0]  # R = 180 deg about x: R^T (p - t)
    with Launcher(domain_id=DOMAIN_CAMERA, echo=False) as launcher:
        node = launcher.start("keypoint_node", node_command(
            "keypoint_node", params={"source": "points", "use_sim_time": False, "points_frame": "camera",
                                     "table_from_camera": [*t.tolist(), 1.0, 0.0, 0.0, 0.0]}))
        launcher.wait_for(node, "estimated from the point cloud", 60)
        feed = Feeder("test_perception_camera")
        try:
            feed.cloud(in_camera, 1 * S, frame="camera")
            kp, _ = feed.keypoints(0)
            assert np.median(err_mm(kp, g.keypoints())) < 10.0
            assert all(abs(p[2]) < 0.01 for p in kp.values())  # on the table, not 1 m away
        finally:
            feed.close()


def test_cloth_state_source_reports_visible_keypoints(env):
    env.setenv("ROS_DOMAIN_ID", str(DOMAIN_STATE))
    g = make_shirt(1, max_area=2e-3)
    with Launcher(domain_id=DOMAIN_STATE, echo=False) as launcher:
        node = launcher.start("keypoint_node", node_command(
            "keypoint_node", params={"source": "cloth_state", "use_sim_time": True, "max_area": 2e-3}))  # clock 0
        launcher.wait_for(node, "publishing keypoints of the cloth", 60)
        feed = Feeder("test_perception_state")
        try:
            sides = []
            v = g.vertices.copy()
            for k, name in enumerate(("left_sleeve", "right_sleeve", "left_side", "right_side")):
                spec = fold_spec(name, visible_keypoints(g, v, sides), folds_done=[s.name for s in sides])
                feed.fold(spec, (10 * k + 10) * S)
                launcher.wait_for(node, f"fold {name} done", 60)  # generous: the suite loads both cores
                sides.append(spec)
                v = fold_target(v, spec, T)
            stamp = 100 * S
            feed.client.state_pub.publish(rc.cloth_state_to_msg(v, g.triangles, g.keypoint_ids, T, stamp))
            kp, ids = feed.keypoints(stamp - 1)
            assert rc.keypoint_folds_from_msg(feed.client.keypoints) == [s.name for s in sides]
            truth = visible_keypoints(g, v, sides)
            for n in KEYPOINT_NAMES:
                np.testing.assert_allclose(kp[n], truth[n], atol=1e-6)  # float32 positions in the message
            w = g.shape.bottom_width * g.shape.scale
            assert kp["bottom_left"][0] == pytest.approx(-w / 4, abs=1e-6)  # the folded outline's corner
            assert ids["bottom_left"] == -1 and ids["neck_middle"] == g.keypoint_ids["neck_middle"]
            # the planner can now plan the middle fold where the study grasped
            mid = fold_spec("middle", kp, folds_done=[s.name for s in sides])
            for a, b in zip(mid.start_poses, fold_spec("middle", g.keypoints()).start_poses):
                np.testing.assert_allclose(a.position[:2], b.position[:2], atol=1e-5)
            launcher.check_alive()
        finally:
            feed.close()


def test_cloud_from_msg_round_trip_and_errors():
    pts = np.random.default_rng(0).normal(size=(50, 3))
    np.testing.assert_allclose(cloud_from_msg(rc.mesh_points(pts, 0)), pts.astype(np.float32))
    m = rc.mesh_points(pts, 0)
    m.fields = m.fields[:2]
    with pytest.raises(ValueError, match="no field"):
        cloud_from_msg(m)
    m = rc.mesh_points(pts, 0)
    m.data = m.data[:100]
    with pytest.raises(ValueError, match="bytes"):
        cloud_from_msg(m)



def test_cloud_from_msg_reads_organised_clouds_with_padded_rows():
    """An organised cloud (height 5, width 10) whose rows are padded to row_step (as camera
    drivers align them): every row's points, not the bytes after the first row read as points."""
    pts = np.random.default_rng(1).normal(size=(50, 3))
    m = rc.mesh_points(pts, 0)
    step, pad = m.point_step, 24
    rows = bytes(m.data)
    m.height, m.width, m.row_step = 5, 10, 10 * step + pad
    m.data = b"".join(rows[r * 10 * step:(r + 1) * 10 * step] + bytes(pad) for r in range(5))
    np.testing.assert_allclose(cloud_from_msg(m), pts.astype(np.float32))
    m.row_step = 10 * step - 1
    with pytest.raises(ValueError, match="row_step"):
        cloud_from_msg(m)
    m = rc.mesh_points(pts, 0)
    m.fields[2].offset = m.point_step - 2
    with pytest.raises(ValueError, match="does not fit"):
        cloud_from_msg(m)


def test_a_replayed_mid_fold_state_never_replaces_newer_keypoints(monkeypatch):
    """The fold's final cloth state may be handled between its result and the replay of the
    state skipped mid-fold; the replay must then be dropped, or the latest /keypoints would be
    older than the fold (and a client waiting for keypoints after the fold waits forever)."""
    import rclpy
    from rclpy.parameter import Parameter

    from clothfold_ros.nodes.keypoint_node import KeypointNode

    g = make_shirt(1, max_area=2e-3)
    ctx = rclpy.Context()
    # use_sim_time without /clock: the node's clock reads 0, so the test's stamps alone decide (a fold
    # over by the node's clock would be taken as done at once)
    rclpy.init(args=["--ros-args", "-p", "source:=cloth_state", "-p", "max_area:=0.002", "-p", "use_sim_time:=true"],
               context=ctx, domain_id=191)
    try:
        monkeypatch.setattr(rclpy.node.Node, "__init__", _with_context(rclpy.node.Node.__init__, ctx))
        node = KeypointNode()
        published, later = [], []
        monkeypatch.setattr(node.pub, "publish", published.append)
        monkeypatch.setattr(node, "call_later", later.append)
        spec = fold_spec("left_sleeve", g.keypoints())
        node.on_active(rc.fold_spec_to_msg(rc.PlannedFold(spec, 0.5, 30.0, 4.0, 0.2, 0, 10 * S)))
        state = lambda t: rc.cloth_state_to_msg(g.vertices, g.triangles, g.keypoint_ids, T, t)  # noqa: E731
        node.on_state(state(12 * S))  # mid-fold: skipped
        assert published == []
        node.on_result(FoldResult(header=rc.header(14 * S), fold_name=spec.name, success=True, loss=0.005))
        node.on_state(state(14 * S))  # the final state, handled before the replay
        assert len(later) == 1  # the replay of the held mid-fold state was scheduled: the race happens
        for callback, arg in later:
            callback(arg)
        assert [rc.time_to_ns(m.header.stamp) for m in published] == [14 * S]
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


def _with_context(init, ctx):
    def wrapped(self, *args, **kwargs):
        kwargs.setdefault("context", ctx)
        return init(self, *args, **kwargs)
    return wrapped


def test_one_far_return_in_a_cloud_is_a_clear_error():
    """A single finite but absurd coordinate (1e30 m) once overflowed the raster index and killed the node."""
    from clothfold_ros.perception.estimator import BadCloudError, top_view

    rng = np.random.default_rng(1)
    cloth = np.column_stack([rng.uniform(-0.2, 0.2, (20000, 2)), np.full(20000, 0.001)])
    top_view(cloth)
    for far in (1e30, 1e6, np.finfo(np.float32).max):
        with pytest.raises(BadCloudError, match="not a shirt on a table"):
            top_view(np.vstack([cloth, [[far, 0.0, 0.001]]]))


def test_keypoint_node_survives_bad_stamps_names_and_durations(monkeypatch):
    """Messages that once killed keypoint_node: a negative stamp, a keypoint name the model lacks
    (after a fold), a fold duration that overflows nanoseconds. Each is logged and skipped."""
    import math

    import rclpy

    from clothfold_ros.nodes.keypoint_node import KeypointNode

    g = make_shirt(1, max_area=2e-3)
    ctx = rclpy.Context()
    rclpy.init(args=["--ros-args", "-p", "source:=cloth_state", "-p", "max_area:=0.002", "-p", "use_sim_time:=true"],
               context=ctx, domain_id=175)  # clock 0 (no /clock): the test's stamps decide
    try:
        monkeypatch.setattr(rclpy.node.Node, "__init__", _with_context(rclpy.node.Node.__init__, ctx))
        node = KeypointNode()
        published, errors = [], []
        monkeypatch.setattr(node.pub, "publish", published.append)
        monkeypatch.setattr(node, "call_later", lambda call: call[0](call[1]))
        logger = node.get_logger()
        monkeypatch.setattr(type(logger), "error", lambda self, msg, **kw: errors.append(msg))
        state = lambda t: rc.cloth_state_to_msg(g.vertices, g.triangles, g.keypoint_ids, T, t)  # noqa: E731

        negative = state(1 * S)
        negative.header.stamp.sec = -1
        node.on_state(negative)
        assert published == [] and "stamp is negative" in errors[-1]

        spec = fold_spec("left_sleeve", g.keypoints())
        huge = rc.fold_spec_to_msg(rc.PlannedFold(spec, 0.5, 30.0, 4.0, 0.2, 0, 2 * S))
        huge.duration = 1e300
        node.on_active(huge)
        assert node.active is None and "duration" in errors[-1]
        node.on_state(state(3 * S))  # no fold running: published
        assert len(published) == 1

        node.on_active(rc.fold_spec_to_msg(rc.PlannedFold(spec, 0.5, 30.0, 4.0, 0.2, 0, 4 * S)))
        node.on_result(FoldResult(header=rc.header(9 * S), fold_name=spec.name, success=True, loss=0.005))
        extra = state(10 * S)
        extra.keypoint_names = list(extra.keypoint_names) + ["extra_marker"]
        extra.keypoint_vertex_ids = list(extra.keypoint_vertex_ids) + [0]
        node.on_state(extra)
        assert "extra_marker" in errors[-1] and len(published) == 1
        node.on_state(state(11 * S))  # a good state after all that: published
        assert len(published) == 2 and rc.time_to_ns(published[-1].header.stamp) == 11 * S
        with pytest.raises(ValueError, match="finite"):
            rc.seconds_to_ns(1e300)
        assert rc.seconds_to_ns(4.0) == 4 * S
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)


class _SimClock:
    """A KeypointNode in its own context with use_sim_time, its /clock published by the test,
    its keypoints captured, spun by a single-threaded executor (timers and call_later run)."""

    def __init__(self, monkeypatch, domain_id: int, *params: str):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rosgraph_msgs.msg import Clock

        from clothfold_ros.nodes.keypoint_node import KeypointNode

        monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        self.ctx = rclpy.Context()
        args = ["--ros-args", "-p", "use_sim_time:=true", *[a for p in params for a in ("-p", p)]]
        rclpy.init(args=args, context=self.ctx, domain_id=domain_id)
        monkeypatch.setattr(rclpy.node.Node, "__init__", _with_context(rclpy.node.Node.__init__, self.ctx))
        self.node = KeypointNode()
        self.published = []
        monkeypatch.setattr(self.node.pub, "publish", self.published.append)
        self.clock_node = rclpy.node.Node("test_clock")
        self.clock_pub = self.clock_node.create_publisher(Clock, common.CLOCK, common.CLOCK_QOS)
        self.clock_msg = Clock
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)

    def stamps(self) -> list[int]:
        return [rc.time_to_ns(m.header.stamp) for m in self.published]

    def set_clock(self, t_ns: int, timeout: float = 20.0) -> None:
        """Publish /clock = t_ns until the node's clock reads it (discovery takes a moment)."""
        deadline = time.monotonic() + timeout
        while self.node.get_clock().now().nanoseconds != t_ns:
            assert time.monotonic() < deadline, f"the node's clock did not follow /clock within {timeout:g} s"
            self.clock_pub.publish(self.clock_msg(clock=rc.header(t_ns).stamp))
            self.executor.spin_once(timeout_sec=0.05)

    def spin(self, seconds: float, until=lambda: False) -> None:
        deadline = time.monotonic() + seconds
        while not until() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        self.clock_node.destroy_node()
        rclpy.shutdown(context=self.ctx)


def _planned(spec, t0_ns: int) -> FoldSpecMsg:
    return rc.fold_spec_to_msg(rc.PlannedFold(spec, 0.5, 30.0, 4.0, 0.2, 0, t0_ns))  # ends t0 + 4.2 s


def test_a_node_started_after_a_fold_publishes_the_final_state(monkeypatch):
    """A keypoint_node (re)started after a fold receives the fold's latched /fold/active but never its
    volatile /fold/result, and the sim's latched final /cloth/state is the last state sent. A fold over by
    the node's clock is taken at once as done with an unknown outcome; a fold still running holds its
    states until its result."""
    g = make_shirt(1, max_area=2e-3)
    sim = _SimClock(monkeypatch, 176, "source:=cloth_state", "max_area:=0.002")
    try:
        node = sim.node
        spec = fold_spec("left_sleeve", g.keypoints())
        state = lambda t: rc.cloth_state_to_msg(g.vertices, g.triangles, g.keypoint_ids, T, t)  # noqa: E731
        sim.set_clock(20 * S)
        node.on_active(_planned(spec, 10 * S))  # ended at 14.2 s, before the node's 20 s
        assert node.active is None and node.failed.name == spec.name
        node.on_state(state(14_200_000_000))  # the fold's final state
        assert sim.stamps() == [14_200_000_000]
        # a fold really in progress: its states are held until its result
        node.on_active(_planned(spec, 18 * S))  # ends at 22.2 s
        node.on_state(state(19 * S))
        sim.spin(1.5)
        assert node.active is not None and sim.stamps() == [14_200_000_000]
        node.on_result(FoldResult(header=rc.header(22 * S), fold_name=spec.name, success=True, loss=0.005))
        sim.spin(5.0, until=lambda: len(sim.published) == 2)
        assert sim.stamps() == [14_200_000_000, 19 * S] and node.fold_names() == [spec.name]
    finally:
        sim.close()


def test_a_fold_without_result_is_given_up_by_the_clock(monkeypatch):
    """Before the first /clock the node cannot tell whether a fold is over and holds its states; once
    its clock passes the fold's end + STALE_AFTER the fold is given up and the held state handled,
    though no further cloth message comes (the sim publishes states only while the cloth moves)."""
    from clothfold_ros.nodes.keypoint_node import STALE_AFTER

    g = make_shirt(1, max_area=2e-3)
    sim = _SimClock(monkeypatch, 177, "source:=cloth_state", "max_area:=0.002")
    try:
        node = sim.node
        spec = fold_spec("left_sleeve", g.keypoints())
        assert node.get_clock().now().nanoseconds == 0
        node.on_active(_planned(spec, 10 * S))  # clock 0: not decided
        node.on_state(rc.cloth_state_to_msg(g.vertices, g.triangles, g.keypoint_ids, T, 14_200_000_000))
        assert node.active is not None and sim.published == []
        sim.set_clock(14 * S + int(STALE_AFTER * S))  # before the limit (14.2 s + STALE_AFTER)
        sim.spin(1.5)
        assert node.active is not None and sim.published == []
        sim.set_clock(15 * S + int(STALE_AFTER * S))  # past it
        sim.spin(5.0, until=lambda: len(sim.published) == 1)
        assert sim.stamps() == [14_200_000_000]
        assert node.active is None and node.failed.name == spec.name
        # its result comes late after all (a real robot's, more than STALE_AFTER late): the outcome is known
        node.on_result(FoldResult(header=rc.header(16 * S + int(STALE_AFTER * S)), fold_name=spec.name,
                                  success=True, loss=0.004))
        assert [f.name for f in node.folds] == [spec.name] and node.failed is None
    finally:
        sim.close()


def test_a_late_result_of_another_fold_leaves_the_running_fold_active(monkeypatch):
    """A /fold/result of an earlier fold arriving while the next one runs does not end the running
    fold: its states stay held until its own result, which then completes it."""
    g = make_shirt(1, max_area=2e-3)
    sim = _SimClock(monkeypatch, 181, "source:=cloth_state", "max_area:=0.002")
    try:
        node = sim.node
        left = fold_spec("left_sleeve", g.keypoints())
        right = fold_spec("right_sleeve", g.keypoints())
        sim.set_clock(11 * S)
        node.on_active(_planned(right, 10 * S))  # runs until 14.2 s
        node.on_state(rc.cloth_state_to_msg(g.vertices, g.triangles, g.keypoint_ids, T, 12 * S))
        node.on_result(FoldResult(header=rc.header(12 * S), fold_name=left.name, success=True, loss=0.004))
        sim.spin(1.5)
        assert node.active is not None and node.active.spec.name == right.name and sim.published == []
        assert node.folds == []  # the late result without its announcement changes nothing
        node.on_result(FoldResult(header=rc.header(14 * S), fold_name=right.name, success=True, loss=0.005))
        sim.spin(5.0, until=lambda: len(sim.published) == 1)
        assert sim.stamps() == [12 * S] and node.fold_names() == [right.name]
    finally:
        sim.close()


def test_reset_forgets_the_folds_and_the_shirt(monkeypatch):
    """~/reset (`clothfold reset`): the folds done, a failed fold, the running fold, the last
    estimate and the flat shirt's area are forgotten (a new, flat shirt)."""
    from std_srvs.srv import Trigger

    g = make_shirt(1, max_area=2e-3)
    sim = _SimClock(monkeypatch, 195, "source:=cloth_state", "max_area:=0.002")
    try:
        node = sim.node
        left, right = fold_spec("left_sleeve", g.keypoints()), fold_spec("right_sleeve", g.keypoints())
        sim.set_clock(11 * S)
        node.on_active(_planned(left, 10 * S))
        node.on_result(FoldResult(header=rc.header(14 * S), fold_name=left.name, success=True, loss=0.004))
        node.on_active(_planned(right, 15 * S))
        node.on_result(FoldResult(header=rc.header(19 * S), fold_name=right.name, success=False, reason="x"))
        node.on_active(_planned(left, 20 * S))
        node.prior, node.flat_area = object(), 0.3
        assert node.fold_names() == [left.name] and node.failed.name == right.name and node.active is not None
        resp = node.on_reset(None, Trigger.Response())
        assert resp.success and "fold history cleared" in resp.message
        assert (node.folds, node.failed, node.active, node.prior, node.flat_area) == ([], None, None, None, None)
    finally:
        sim.close()


def test_points_qos_parameter(monkeypatch):
    """points_qos picks the cloud subscription's QoS: latched (the sim's camera) or sensor_data (best
    effort, volatile: what camera drivers publish, which a latched subscription never receives)."""
    import rclpy
    from rclpy.exceptions import InvalidParameterValueException
    from rclpy.qos import (DurabilityPolicy, QoSCompatibility, ReliabilityPolicy, qos_check_compatible,
                           qos_profile_sensor_data)

    from clothfold_ros.nodes.keypoint_node import KeypointNode

    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    for value, reliability, durability in (
            (None, ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL),
            ("sensor_data", ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE),
            ("latched", ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)):
        ctx = rclpy.Context()
        args = ["--ros-args", "-p", "source:=points", "-p", "points_topic:=/camera/points"]
        rclpy.init(args=args + (["-p", f"points_qos:={value}"] if value else []), context=ctx, domain_id=178)
        try:
            monkeypatch.setattr(rclpy.node.Node, "__init__", _with_context(rclpy.node.Node.__init__, ctx))
            node = KeypointNode()
            (sub,) = [s for s in node.subscriptions if s.topic_name == "/camera/points"]
            assert (sub.qos_profile.reliability, sub.qos_profile.durability) == (reliability, durability), value
            camera, sim = (qos_check_compatible(pub, sub.qos_profile)[0] for pub in (qos_profile_sensor_data,
                                                                                      common.LATCHED))
            assert (camera != QoSCompatibility.ERROR) == (value == "sensor_data") and sim != QoSCompatibility.ERROR
            node.destroy_node()
        finally:
            rclpy.shutdown(context=ctx)
    ctx = rclpy.Context()
    rclpy.init(args=["--ros-args", "-p", "source:=points", "-p", "points_qos:=best_effort"], context=ctx,
               domain_id=178)
    try:
        monkeypatch.setattr(rclpy.node.Node, "__init__", _with_context(rclpy.node.Node.__init__, ctx))
        with pytest.raises(InvalidParameterValueException, match="points_qos must be one of latched, sensor_data"):
            KeypointNode()
    finally:
        rclpy.shutdown(context=ctx)


def test_an_rgbd_cloud_with_the_table_is_fitted_with_table_color(env):
    """A real camera's cloud holds the table: with `table_color` the node drops its points by
    colour and fits the shirt; a cloud without colours is refused with the reason."""
    env.setenv("ROS_DOMAIN_ID", str(DOMAIN_COLOUR))
    g = make_shirt(1, max_area=5e-4)
    cam = DepthCamera(table=True)
    pts, rgb = cam.colour_cloud(g.vertices, g.triangles, rng=4)
    with Launcher(domain_id=DOMAIN_COLOUR, echo=False) as launcher:
        node = launcher.start("keypoint_node", node_command(
            "keypoint_node", params={"source": "points", "use_sim_time": False,
                                     "table_color": [float(c) for c in cam.table_rgb]}))
        launcher.wait_for(node, "estimated from the point cloud", 60)
        feed = Feeder("test_perception_colour")
        try:
            feed.cloud(pts, 1 * S, rgb=rgb)
            kp, _ = feed.keypoints(0)
            assert np.median(err_mm(kp, g.keypoints())) < 10.0
            feed.cloud(pts, 2 * S)  # no colour field
            launcher.wait_for(node, "no rgb/rgba field", 20)
            launcher.check_alive()
        finally:
            feed.close()
