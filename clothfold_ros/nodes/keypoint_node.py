"""keypoint_node: the shirt's semantic keypoints on /keypoints (clothfold_msgs/Keypoints, latched).

Keypoints have the folded-state semantics of `clothfold_ros.perception.visible`: what a
camera looking down sees on the cloth as it lies now (after both side folds the hem
corners are the folded outline's corners). The folds done are learnt from the pipeline:
/fold/active names the fold being executed, a successful /fold/result completes it;
~/reset (std_srvs/Trigger) forgets them (a cloth laid flat again).

source = "points" (a real robot's camera, or the sim's /cloth/points): every cloud on
`points_topic` (sensor_msgs/PointCloud2, float x, y, z) in frame `points_frame` is moved
into the table frame by the fixed `table_from_camera` transform (with `table_color` set, the
points of the table's colour are dropped first: an RGB-D cloud that holds the table, packed
`rgb`/`rgba` field) and fitted with the shirt model (`perception.tracking.estimate_state`: the folds done, from the previous estimate's
lines, then its shape with every line refitted, then afresh; a fold reported failed and the
shirt laid flat again are tried too). Publishes /keypoints (vertex ids -1) and the fitted outline as a
visualization_msgs/Marker LINE_LIST on /keypoints/outline. Clouds arriving while a fold
is executing are held (the cloth moves, the grippers are in view): the last is handled after
the fold's result, the others are left out and counted in the log. `points_qos` is the
subscription's QoS: "latched" for the sim's camera, "sensor_data" (best effort, volatile) for a
camera driver's sensor-data publisher, which a latched subscription never receives. A bad cloud (empty,
NaN, no cloth, two blobs, no convergence) is logged with the reason and skipped; a fit
whose residual exceeds `max_residual` is logged as such and its outline published in
red (namespace "rejected"), not its keypoints. The last good keypoints stay published. Every
skipped input is counted; repeats of one kind are logged at most once a second with their
count, and what a burst left unlogged is reported within 5 s (a camera in the wrong frame at
30 Hz costs a line a second, not 30).

source = "cloth_state": subscribes /cloth/state and publishes the visible keypoints of
the current mesh (material keypoint vertices while flat; vertex id -1 for keypoints that
are not a vertex); the flat mesh must be the sim's (parameters shape, max_area).

source = "model": the flat shirt's keypoints every `model_period` wall seconds and after each
/fold/result (stamped no earlier than it), for backends without a cloth.

Sources points and cloth_state: a cloth message stamped while a fold executes is held and
handled after the fold's result. A fold whose result this node cannot see (it started after
the fold: /fold/active is latched, /fold/result is not) is taken as over with an unknown
outcome when its /fold/active arrives after its end by the node's clock, or STALE_AFTER s
after its end (a once-a-second check by the clock, or a later cloth message's stamp); the
held message is then handled. The node decides nothing by its clock while it reads 0
(use_sim_time before the first /clock).
"""
from __future__ import annotations

import sys

import numpy as np
from clothfold_msgs.msg import ClothState, FoldResult, FoldSpec as FoldSpecMsg, Keypoints
from geometry_msgs.msg import Point
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import ColorRGBA
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker

from ..garment import KEYPOINT_NAMES
from . import conversions as rc
from . import common, params
from .errorlog import ErrorLog
from .params import Param

OUTLINE_TOPIC = "/keypoints/outline"
STALE_AFTER = 30.0  # s past a fold's end without its result: the fold is no longer taken as executing
POINTS_QOS = {"latched": common.LATCHED, "sensor_data": qos_profile_sensor_data}

PARAMS = [
    Param("source", "points", "where keypoints come from: a point cloud, the cloth state topic or the flat "
          "shirt model", choices=("points", "cloth_state", "model"), read_only=True),
    params.SHAPE,
    Param("max_area", 5e-4, "mesh max triangle area (m^2) of the model shirt (source = model; cloth_state: the sim's)",
          range=(1e-5, 1e-2), read_only=True),
    Param("model_period", 1.0, "republish period of the model keypoints (wall s)", range=(0.05, 60.0), read_only=True),
    Param("points_topic", "/cloth/points", "sensor_msgs/PointCloud2 topic (source = points)", read_only=True),
    Param("points_qos", "latched", "QoS of the points_topic subscription: latched (reliable, transient local: the "
          "sim's /cloth/points) or sensor_data (best effort, volatile: a camera driver's; receives from any "
          "publisher)", choices=tuple(POINTS_QOS), read_only=True),
    Param("points_frame", "table", "frame_id the clouds must have; table_from_camera maps it to the table frame",
          read_only=True),
    Param("table_from_camera", [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
          "fixed transform of cloud points into the table frame: x y z (m), qx qy qz qw", length=7, read_only=True),
    Param("min_height", -0.01, "cloth points lie above this height over the table (m)", range=(-1.0, 1.0),
          read_only=True),
    Param("max_height", 0.25, "and at most this high (m): higher points (grippers, arm) are ignored",
          range=(0.0, 2.0), read_only=True),
    Param("pixel", 0.005, "top-view raster size (m)", range=(0.001, 0.05), read_only=True),
    Param("max_residual", 0.01, "a fit with a larger RMS outline residual (m) is rejected", range=(0.0005, 0.5),
          read_only=True),
    Param("table_color", [-1.0, -1.0, -1.0], "RGB (0-255) of the table top: points within table_color_distance of "
          "it are dropped before the fit (a cloud that holds the table: an RGB-D camera's); -1 -1 -1 = off",
          range=(-1.0, 255.0), length=3),
    Param("table_color_distance", 60.0, "RGB distance (0-255 cube) within which a point is the table's",
          range=(1.0, 441.0)),
]  # the estimator's settings are read once, at start: read-only rather than changed without effect


def _cross_check(values: dict, changed: list[str]) -> str | None:
    """Cross checks: the cloud's height band (m); a table colour is three values 0-255 or off."""
    if not values["min_height"] < values["max_height"]:
        return f"min_height ({values['min_height']:g} m) must be below max_height ({values['max_height']:g} m)"
    rgb = list(values["table_color"])
    if any(v < 0 for v in rgb) and not all(v < 0 for v in rgb):
        return f"table_color {rgb} must be three values in 0..255, or -1 -1 -1 (off)"
    return None


def cloud_from_msg(m: PointCloud2) -> np.ndarray:
    """(N, 3) float64 x, y, z of a PointCloud2 (float32/float64 fields, any point_step,
    organised or not, rows padded to row_step or not; NaN points kept). ValueError for a
    malformed message."""
    by_name = {f.name: f for f in m.fields}
    missing = [c for c in "xyz" if c not in by_name]
    if missing:
        raise ValueError(f"cloud has no field(s) {', '.join(missing)} (fields: {[f.name for f in m.fields]})")
    types = {PointField.FLOAT32: "f4", PointField.FLOAT64: "f8"}
    data, n = _point_bytes(m)
    if n == 0:
        return np.zeros((0, 3))
    cols = []
    for c in "xyz":
        f = by_name[c]
        if f.datatype not in types:
            raise ValueError(f"cloud field {c} has datatype {f.datatype}; only FLOAT32/FLOAT64 are supported")
        cols.append(_column(m, data, n, f, types[f.datatype]).astype(float))
    return np.column_stack(cols)


def cloud_colours(m: PointCloud2) -> np.ndarray:
    """(N, 3) uint8 RGB of each point of a PointCloud2, from PCL's packed `rgb` or `rgba` field
    (FLOAT32, UINT32 or INT32: 0x00RRGGBB in the field's 32 bits). ValueError when the cloud has
    neither or it is malformed."""
    from ..perception.colour import unpack_rgb

    f = next((f for f in m.fields if f.name in ("rgb", "rgba")), None)
    if f is None:
        raise ValueError(f"cloud has no rgb/rgba field (fields: {[f.name for f in m.fields]}): table_color needs "
                         "an RGB-D cloud")
    if f.datatype not in (PointField.FLOAT32, PointField.UINT32, PointField.INT32):
        raise ValueError(f"cloud field {f.name} has datatype {f.datatype}; packed colour is FLOAT32, UINT32 or INT32")
    data, n = _point_bytes(m)
    if n == 0:
        return np.zeros((0, 3), dtype=np.uint8)
    return unpack_rgb(_column(m, data, n, f, "u4").astype(np.uint32))


def _point_bytes(m: PointCloud2) -> tuple[bytes, int]:
    """(the points' bytes without row padding, number of points); ValueError when the sizes
    do not fit."""
    width, height = int(m.width), int(m.height)
    n = width * height
    if n == 0:
        return b"", 0
    step = int(m.point_step)
    row = int(m.row_step) or width * step  # 0 from some unorganised producers: rows of width points
    if step <= 0 or row < width * step:
        raise ValueError(f"cloud row_step {m.row_step} is shorter than width {width} x point_step {step}")
    need = (height - 1) * row + width * step
    if len(m.data) < need:
        raise ValueError(f"cloud data has {len(m.data)} bytes, {height} rows of {row} bytes need {need}")
    data = bytes(m.data)
    if row != width * step:  # padded rows: the points of each row, without its padding
        data = b"".join(data[r * row:r * row + width * step] for r in range(height))
    return data, n


def _column(m: PointCloud2, data: bytes, n: int, f: PointField, fmt: str) -> np.ndarray:
    """One field of every point, read as `fmt` ("f4", "f8", "u4") in the cloud's byte order."""
    step = int(m.point_step)
    if not 0 <= f.offset <= step - np.dtype(fmt).itemsize:
        raise ValueError(f"cloud field {f.name} at offset {f.offset} does not fit a point of {step} bytes")
    endian = ">" if m.is_bigendian else "<"
    dt = np.dtype({"names": [f.name], "formats": [endian + fmt], "offsets": [f.offset], "itemsize": step})
    return np.frombuffer(data[:n * step], dtype=dt, count=n)[f.name]


class KeypointNode(Node):
    def __init__(self) -> None:
        super().__init__("keypoint_node")
        params.declare(self, PARAMS, _cross_check)
        self.pub = self.create_publisher(Keypoints, common.KEYPOINTS, common.LATCHED)
        self.count = 0
        self.errors = ErrorLog(interval=1.0)  # bad inputs: each counted, a flood logged once a second a kind
        self.create_timer(5.0, self._report_unlogged, clock=Clock(clock_type=ClockType.STEADY_TIME))  # wall s
        self.folds: list = []  # core FoldSpecs of the folds done, in order
        self.active = None  # the fold being executed (PlannedFold), None when the cloth rests
        self.given_up = None  # the last fold taken as over without its result (PlannedFold)
        self.failed = None  # a fold that failed: the cloth may or may not be folded by it
        self.prior = None  # the last good estimate (source = points)
        self.flat_area: float | None = None  # m^2, the flat shirt last fitted with no fold done (source = points)
        self.skipped = None  # (callback, msg) of the last cloth message skipped while a fold ran
        self.held = 0  # cloth messages that arrived while the active fold ran (only the last is handled)
        self.published_ns = -1  # stamp of the newest keypoints published: an older cloth message is stale
        self._garment = None
        source = params.value(self, "source")
        if source in ("points", "cloth_state"):
            self.create_subscription(FoldSpecMsg, common.FOLD_ACTIVE, self.on_active, common.LATCHED)
            self.create_subscription(FoldResult, common.FOLD_RESULT, self.on_result, common.RESULTS)
            self.create_service(Trigger, "~/reset", self.on_reset)
            self.create_timer(1.0, self.check_stale, clock=Clock(clock_type=ClockType.STEADY_TIME))
        if source == "points":
            from ..perception.estimator import EstimatorConfig

            self.config = EstimatorConfig(pixel=params.value(self, "pixel"),
                                          min_height=params.value(self, "min_height"),
                                          max_height=params.value(self, "max_height"),
                                          max_residual=params.value(self, "max_residual"))
            t = params.value(self, "table_from_camera")
            q = np.asarray(t[3:], float)
            if np.linalg.norm(q) < 1e-6:
                raise ValueError("table_from_camera has a zero quaternion")
            from scipy.spatial.transform import Rotation

            self.rotation = Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()
            self.translation = np.asarray(t[:3], float)
            self.outline_pub = self.create_publisher(Marker, OUTLINE_TOPIC, common.LATCHED)
            topic = params.value(self, "points_topic")
            qos = params.value(self, "points_qos")
            self.create_subscription(PointCloud2, topic, self.on_points, POINTS_QOS[qos])
            self.get_logger().info(f"publishing keypoints estimated from the point cloud on {topic} ({qos} QoS)")
        elif source == "cloth_state":
            self.create_subscription(ClothState, common.CLOTH_STATE, self.on_state, common.LATCHED)
            self.get_logger().info(f"publishing keypoints of the cloth on {common.CLOTH_STATE}")
        else:
            from ..garment import make_shirt

            g = make_shirt(params.value(self, "shape"), max_area=params.value(self, "max_area"))
            self.model = (g.keypoints(), dict(g.keypoint_ids))
            self.publish_model()
            # wall period: a simulated clock stands still between folds, and a timer on it would not fire
            # then; after each /fold/result at once, stamped no earlier than the result (the keypoints of
            # the cloth as it lies after it, which the planner waits for)
            self.create_timer(params.value(self, "model_period"), self.publish_model,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
            self.create_subscription(FoldResult, common.FOLD_RESULT,
                                     lambda m: self.publish_model(rc.time_to_ns(m.header.stamp)), common.RESULTS)
            self.get_logger().info(f"publishing the flat model shirt's keypoints (shape {params.value(self, 'shape')})")

    # -- the folds done ----------------------------------------------------------------------------
    def on_active(self, msg: FoldSpecMsg) -> None:
        try:
            active = rc.fold_spec_from_msg(msg)
        except ValueError as err:
            self.get_logger().error(f"bad /fold/active ignored: {err}")
            return
        if self.active is not None and self.active.spec.name != active.spec.name:
            self.get_logger().warn(f"fold {active.spec.name!r} announced while fold {self.active.spec.name!r} had no "
                                   "result yet: that one's outcome stays unknown")
        self.active, self.held = active, 0
        now, end = self.get_clock().now().nanoseconds, self.end_ns(self.active)
        if 0 < now and end < now:  # a latched announcement of a fold over before this node started
            self.give_up(f"it ended at {end * 1e-9:.3f} s, before its /fold/active reached this node (clock "
                         f"{now * 1e-9:.3f} s): its result was missed")

    def on_result(self, msg: FoldResult) -> None:
        if self.active is not None and self.active.spec.name != msg.fold_name:
            # a late result of an earlier fold while another one runs: the running fold stays
            # active (its own result completes it) and its held cloth message stays held
            self.get_logger().warn(f"result of fold {msg.fold_name!r} while fold {self.active.spec.name!r} is "
                                   "executing: the fold history is not changed")
            return
        active, self.active = self.active, None
        if active is None and self.given_up is not None and self.given_up.spec.name == msg.fold_name:
            active = self.given_up  # the result of a fold given up on came after all: its outcome is known
        self.given_up = None
        skipped, self.skipped = self.skipped, None
        if skipped is not None:  # the cloth message that came before this result (other topic, any order)
            self.get_logger().info(f"{self.held} cloth message(s) arrived during fold {msg.fold_name}: the last "
                                   "is handled now, the others are left out (the cloth was moving)")
            self.call_later((self.replay, skipped))
        self.held = 0
        if active is None or active.spec.name != msg.fold_name:
            self.get_logger().warn(f"result of fold {msg.fold_name!r} without its /fold/active spec: "
                                   "the fold history is not changed")
            return
        if msg.success:
            self.folds.append(active.spec)
            self.failed = None
            self.get_logger().info(f"fold {msg.fold_name} done; folds so far: {self.fold_names()}")
        else:
            self.failed = active.spec
            self.get_logger().warn(f"fold {msg.fold_name} failed ({msg.reason}): the next estimate tries the cloth "
                                   "with and without it")

    def call_later(self, call) -> None:
        """Run call = (callback, msg) once on the executor, after the current callback."""
        def once():
            timer.cancel()
            self.destroy_timer(timer)
            call[0](call[1])

        timer = self.create_timer(0.001, once, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def on_reset(self, _req, resp):
        self.folds, self.failed, self.prior, self.active, self.given_up = [], None, None, None, None
        self.flat_area = None
        resp.success, resp.message = True, "fold history cleared: the cloth is taken to be flat"
        self.get_logger().info(resp.message)
        return resp

    @staticmethod
    def end_ns(a) -> int:
        """When the fold a (PlannedFold) ends: its motion and settling done."""
        return a.stamp_ns + rc.seconds_to_ns(a.duration + a.settle_time)

    def give_up(self, why: str) -> None:
        """Take the active fold as over, its outcome unknown (its result was missed), and handle the
        cloth message held for it (after the current callback; dropped if a newer one is handled)."""
        a, self.active, self.failed = self.active, None, self.active.spec
        self.given_up = a  # a result that still comes settles its outcome
        self.get_logger().warn(f"no result seen for fold {a.spec.name} ({why}): its outcome is taken as unknown")
        skipped, self.skipped = self.skipped, None
        if skipped is not None:
            self.call_later((self.replay, skipped))

    def check_stale(self) -> None:
        """Once a second: give up an active fold STALE_AFTER s past its end by the node's clock, so
        a held cloth message is handled though no later message comes (none while the cloth rests)."""
        now = self.get_clock().now().nanoseconds
        if self.active is not None and 0 < now and now > self.end_ns(self.active) + rc.seconds_to_ns(STALE_AFTER):
            self.give_up(f"the clock reads {now * 1e-9:.3f} s, {STALE_AFTER:g} s past its end at "
                         f"{self.end_ns(self.active) * 1e-9:.3f} s")

    def folding(self, stamp_ns: int) -> bool:
        """Whether a fold is executing at stamp_ns. A latched /fold/active of a fold whose
        result this node never saw (it started later) is given up STALE_AFTER s after its end."""
        a = self.active
        if a is None:
            return False
        if stamp_ns > self.end_ns(a) + rc.seconds_to_ns(STALE_AFTER):
            self.give_up(f"a cloth message stamped {stamp_ns * 1e-9:.3f} s, {STALE_AFTER:g} s past its end at "
                         f"{self.end_ns(a) * 1e-9:.3f} s")
            return False
        return True

    def replay(self, call) -> None:
        """Handle a cloth message skipped during the fold that just ended, unless a newer one was
        handled meanwhile (the fold's final state can arrive before its result or between the result
        and this replay): replaying it then would replace newer keypoints with older ones."""
        callback, msg = call
        stamp = rc.time_to_ns(msg.header.stamp)
        if stamp >= self.published_ns:
            callback(msg)
        else:
            self.get_logger().debug(f"held cloth message of {stamp * 1e-9:.3f} s dropped: keypoints of "
                                    f"{self.published_ns * 1e-9:.3f} s were published meanwhile")

    def fold_names(self, extra=None) -> list[str]:
        return [s.name for s in self.folds] + ([extra.name] if extra is not None else [])

    # -- bad input ------------------------------------------------------------------------------------
    def input_error(self, kind: str, text: str) -> None:
        """Log a skipped input: every one counted, the first of a kind logged at once, repeats at
        most once a second with the count (a camera in the wrong frame at 30 Hz is one line a second)."""
        line = self.errors.record(kind, text)
        if line:
            self.get_logger().error(line)

    def _report_unlogged(self) -> None:
        line = self.errors.flush()  # what a flood left unlogged since its last line, with the counts
        if line:
            self.get_logger().error(line)

    # -- source = points ------------------------------------------------------------------------------
    def on_points(self, msg: PointCloud2) -> None:
        from ..perception.estimator import PerceptionError, PoorFitError, flat_area
        from ..perception.tracking import estimate_state

        try:
            stamp = rc.stamp_ns(msg.header, "cloud")
        except ValueError as err:
            self.input_error("cloud", f"bad cloud skipped: {err}; keeping the last good keypoints")
            return
        if self.folding(stamp):
            self.skipped = (self.on_points, msg)  # a fold is moving the cloth: handled after its result
            self.held += 1
            return
        try:
            if msg.header.frame_id != params.value(self, "points_frame"):
                raise ValueError(f"cloud frame is {msg.header.frame_id!r}; points_frame is "
                                 f"{params.value(self, 'points_frame')!r}")
            pts = cloud_from_msg(msg) @ self.rotation.T + self.translation
            table_rgb = params.value(self, "table_color")
            if min(table_rgb) >= 0:  # the cloud holds the table: keep the points not of its colour
                from ..perception.colour import cloth_points

                pts = cloth_points(pts, cloud_colours(msg), table_rgb, params.value(self, "table_color_distance"),
                                   self.config)
            state = estimate_state(pts, self.fold_names(), prior=self.prior,
                                   failed=self.failed.name if self.failed is not None else None,
                                   flat_shirt_area=self.flat_area, config=self.config)
        except PoorFitError as err:
            self.input_error("fit", f"keypoint fit rejected: {err}; keeping the last good keypoints")
            self.outline_pub.publish(self.outline_marker(err.estimate.segments, stamp, rejected=True))
            return
        except (PerceptionError, ValueError) as err:
            self.input_error("cloud", f"bad cloud skipped: {type(err).__name__}: {err}; keeping the last good "
                             "keypoints")
            return
        for warning in state.warnings:
            self.get_logger().warn(warning)
        names, est = state.folds, state.estimate
        if names != self.fold_names():
            self.get_logger().warn(f"the cloud fits folds {names} better than the expected {self.fold_names()}: "
                                   "taking that as the cloth's state")
            self.folds = (self.folds + [self.failed]) if len(names) > len(self.folds) else []
        elif state.start != "prior" and self.prior is not None:
            self.get_logger().info(f"keypoints fitted from the {state.start} start ({'; '.join(state.tried)})")
        self.failed = None
        self.prior = est
        if not names:  # the shirt as it lies flat now (a new shirt may have been laid down)
            self.flat_area = flat_area(est.shape)
        self.published_ns = stamp
        self.pub.publish(rc.keypoints_to_msg(est.keypoints, stamp, folds=names))
        self.outline_pub.publish(self.outline_marker(est.segments, stamp))
        self.count += 1
        if self.count == 1 or self.count % 20 == 0:
            self.get_logger().info(f"keypoints from {est.n_points} cloud points, folds {names}: residual "
                                   f"{est.residual * 1e3:.1f} mm, {est.seconds * 1e3:.0f} ms CPU ({self.count} so far)")

    def outline_marker(self, segments: np.ndarray, stamp: int, rejected: bool = False) -> Marker:
        """LINE_LIST of the fitted model outline (segments (S, 2, 2) m, table frame) at z = 1 cm."""
        m = Marker(header=rc.header(stamp), ns="rejected" if rejected else "fitted", id=0, type=Marker.LINE_LIST,
                   action=Marker.ADD,
                   color=ColorRGBA(r=1.0, g=0.1, b=0.1, a=1.0) if rejected else ColorRGBA(r=0.1, g=0.9, b=0.2, a=1.0))
        m.pose.orientation.w = 1.0
        m.scale.x = 0.003
        m.points = [Point(x=float(x), y=float(y), z=0.01) for x, y in np.asarray(segments).reshape(-1, 2).tolist()]
        return m

    # -- source = cloth_state --------------------------------------------------------------------------
    def garment(self, n_vertices: int):
        from ..garment import make_shirt

        if self._garment is None:
            self._garment = make_shirt(params.value(self, "shape"), max_area=params.value(self, "max_area"))
        if len(self._garment.vertices) != n_vertices:
            raise ValueError(f"cloth state has {n_vertices} vertices but the flat shirt of shape "
                             f"{params.value(self, 'shape')}, max_area {params.value(self, 'max_area')} has "
                             f"{len(self._garment.vertices)}: set keypoint_node's shape and max_area like the sim's")
        return self._garment

    def publish_model(self, not_before_ns: int = 0) -> None:
        kp, ids = self.model
        self.pub.publish(rc.keypoints_to_msg(kp, max(self.get_clock().now().nanoseconds, not_before_ns), ids))

    def on_state(self, msg: ClothState) -> None:
        from ..perception.visible import visible_keypoints

        try:
            state = rc.cloth_state_from_msg(msg)
            if not state.keypoint_ids:
                raise ValueError("cloth state names no keypoint vertices")
            ids = dict(state.keypoint_ids)
            unknown = sorted(set(ids) - set(KEYPOINT_NAMES))
            if unknown:
                raise ValueError(f"cloth state names keypoints the shirt model lacks: {', '.join(unknown)}")
            kp = state.keypoints()
            if self.folding(state.stamp_ns):
                self.skipped = (self.on_state, msg)  # mid-fold: handled after the fold's result
                self.held += 1
                return
            if self.folds:
                kp = visible_keypoints(self.garment(len(state.vertices)), state.vertices, self.folds)
                ids = {n: (i if np.array_equal(kp[n], state.vertices[i]) else -1) for n, i in ids.items()}
            if not all(np.all(np.isfinite(p)) for p in kp.values()):
                raise ValueError("keypoints are not finite")
        except ValueError as err:
            self.input_error("state", f"bad cloth state skipped: {err}")
            return
        self.published_ns = state.stamp_ns
        self.pub.publish(rc.keypoints_to_msg(kp, state.stamp_ns, ids, folds=self.fold_names()))
        self.count += 1


def main(argv: list[str] | None = None) -> int:
    full = list(sys.argv if argv is None else ["keypoint_node", *argv])
    return common.run(KeypointNode, full)


if __name__ == "__main__":
    sys.exit(main())
