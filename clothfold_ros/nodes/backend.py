"""LockStepBackend: the robot side of the pipeline contract (docs/robot-interface.md), shared by
cloth_sim_node and kinematic_robot_node.

It owns simulated time and publishes it on /clock (rosgraph_msgs/Clock); it must run on
wall time itself (never use_sim_time). Subscribes /gripper_<i>/target_pose and
/gripper_<i>/command and /fold/active; publishes /gripper_<i>/pose (the gripper's actual
pose, PoseStamped, every step while closed), /gripper_<i>/state (sensor_msgs/JointState:
finger opening in m) and /fold/result. Time advances by `LockStep` rules: a step t -> t + dt
only once the target stamped t + dt of every closed gripper is there; while every gripper
is open the clock runs at real_time_factor. Subclasses implement the physics hooks.
"""
from __future__ import annotations

import math
import time

from clothfold_msgs.msg import FoldResult, FoldSpec as FoldSpecMsg, GripperCommand
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from .. import ros_conversions as rc
from ..pose import Pose
from . import common, params
from .lockstep import LockStep
from .params import Param

BACKEND_PARAMS = [
    params.N_GRIPPERS,
    Param("dt", 0.04, "time step (s): the clock advances by dt per step while a gripper is closed",
          range=(0.001, 0.5), read_only=True),
    params.REAL_TIME_FACTOR,
    Param("tick", 0.01, "wall period of the main loop (s)", range=(0.001, 1.0), read_only=True),
    Param("close_threshold", 0.005, "a command with finger opening <= this (m) closes the gripper",
          range=(0.0, 1.0)),
    Param("stall_timeout", 60.0, "fail the fold when a closed gripper gets no target for this long (wall s)",
          range=(0.1, 3600.0)),
]


class LockStepBackend(Node):
    """Base node: subclasses override on_close, on_step, on_open, on_all_open (and may use idle_work)."""

    def __init__(self, name: str, extra_params: list[Param], cross_check=None) -> None:
        super().__init__(name)
        if self.get_parameter("use_sim_time").value:
            raise ValueError(f"{name} publishes /clock and must run on wall time (use_sim_time false)")
        params.declare(self, BACKEND_PARAMS + extra_params, cross_check)
        self.n = params.value(self, "n_grippers")
        self.ls = LockStep(self.n, params.value(self, "dt"))
        self.clock_pub = self.create_publisher(Clock, common.CLOCK, common.CLOCK_QOS)
        self.result_pub = self.create_publisher(FoldResult, common.FOLD_RESULT, common.RESULTS)
        self.pose_pubs = [self.create_publisher(PoseStamped, common.gripper_topic(i, "pose"), common.FEEDBACK)
                          for i in range(self.n)]
        self.state_pubs = [self.create_publisher(JointState, common.gripper_topic(i, "state"), common.FEEDBACK)
                           for i in range(self.n)]
        for i in range(self.n):
            self.create_subscription(PoseStamped, common.gripper_topic(i, "target_pose"),
                                     lambda m, i=i: self.on_target(i, m), common.TARGETS)
            self.create_subscription(GripperCommand, common.gripper_topic(i, "command"),
                                     lambda m, i=i: self.on_command(i, m), common.COMMANDS)
        self.create_subscription(FoldSpecMsg, common.FOLD_ACTIVE, self.on_active, common.LATCHED)
        self.active: rc.PlannedFold | None = None  # the fold being executed (from /fold/active)
        self.next_active: rc.PlannedFold | None = None
        self.opening = [0.0] * self.n
        self._last_wall = time.monotonic()
        self._budget_ns = 0
        self._waiting_since: float | None = None
        self._error_counts: dict[str, int] = {}
        self.create_timer(params.value(self, "tick"), self.on_tick)
        self.publish_clock()

    # -- input -------------------------------------------------------------------------------
    def error_once(self, key: str, text: str) -> None:
        """Log an input error (every one counted; repeats of the same kind logged sparsely)."""
        n = self._error_counts.get(key, 0) + 1
        self._error_counts[key] = n
        if n <= 3 or n % 100 == 0:
            self.get_logger().error(f"{text} (#{n} of this kind)")

    def on_target(self, i: int, msg: PoseStamped) -> None:
        try:
            if msg.header.frame_id not in ("", rc.TABLE_FRAME):
                raise ValueError(f"frame {msg.header.frame_id!r} is not {rc.TABLE_FRAME!r}")
            self.ls.add_target(i, rc.time_to_ns(msg.header.stamp), rc.pose_from_msg(msg.pose, f"gripper_{i} target"))
        except ValueError as err:
            self.error_once(f"target{i}", f"gripper_{i} target pose ignored: {err}")

    def on_command(self, i: int, msg: GripperCommand) -> None:
        try:
            if msg.gripper and msg.gripper != f"gripper_{i}":
                raise ValueError(f"command names {msg.gripper!r} on gripper_{i}'s topic")
            if not (math.isfinite(msg.position) and msg.position >= 0):
                raise ValueError(f"finger opening must be >= 0 m, got {msg.position}")
            closed = msg.position <= params.value(self, "close_threshold")
            self.ls.add_command(i, rc.time_to_ns(msg.header.stamp), closed)
            if not closed:
                self.opening[i] = msg.position  # applied when due; remembered for the state
        except ValueError as err:
            self.error_once(f"cmd{i}", f"gripper_{i} command ignored: {err}")
            if self.ls.closed:
                self.fail(f"gripper command refused mid-fold: {err}")

    def on_active(self, msg: FoldSpecMsg) -> None:
        try:
            plan = rc.fold_spec_from_msg(msg)
        except ValueError as err:
            self.error_once("active", f"/fold/active ignored: {err}")
            return
        self.next_active = plan
        if not self.ls.closed and plan.stamp_ns >= self.ls.now_ns:
            self.ls.hold_until = plan.stamp_ns  # do not run the idle clock past the fold's start

    # -- main loop ------------------------------------------------------------------------------
    def publish_clock(self) -> None:
        self.clock_pub.publish(Clock(clock=rc.ns_to_time(self.ls.now_ns)))

    def publish_gripper_state(self, i: int) -> None:
        closed = i in self.ls.closed
        self.state_pubs[i].publish(JointState(header=rc.header(self.ls.now_ns, ""), name=[f"gripper_{i}"],
                                              position=[0.0 if closed else float(self.opening[i])]))

    def on_tick(self) -> None:
        wall = time.monotonic()
        rtf = params.value(self, "real_time_factor")
        self._budget_ns = min(self._budget_ns + int((wall - self._last_wall) * rtf * 1e9),
                              max(2 * self.ls.dt_ns, int(0.1 * rtf * 1e9)))
        self._last_wall = wall
        try:
            self._tick()
        except Exception as err:  # noqa: BLE001 - a failed fold never kills the backend
            self.get_logger().error(f"fold failed: {type(err).__name__}: {err}")
            self.fail(f"{type(err).__name__}: {err}")

    def _tick(self) -> None:
        start = self.ls.now_ns
        while True:
            cmd = self.ls.due_command()
            if cmd is not None:
                if cmd.closed:
                    pose = self.ls.target_now(cmd.gripper)
                    if pose is None:
                        return self._stalled(f"no target pose of gripper_{cmd.gripper} at its close time "
                                             f"{cmd.stamp_ns * 1e-9:.3f} s")
                    self.ls.pop_command()
                    if cmd.gripper not in self.ls.closed:
                        if not self.ls.closed:
                            self.active = self.next_active
                        self.on_close(cmd.gripper, pose)
                        self.ls.close(cmd.gripper)
                        self.publish_gripper_state(cmd.gripper)
                else:
                    self.ls.pop_command()
                    if cmd.gripper in self.ls.closed:
                        self.on_open(cmd.gripper)
                        self.ls.open(cmd.gripper)
                        self.publish_gripper_state(cmd.gripper)
                        if not self.ls.closed:
                            self.on_all_open()
                self._waiting_since = None
                continue
            if self.ls.closed:
                if self._budget_ns < self.ls.dt_ns:
                    break
                targets = self.ls.step_targets()
                if targets is None:
                    return self._stalled(f"no target pose stamped {(self.ls.now_ns + self.ls.dt_ns) * 1e-9:.3f} s")
                self._waiting_since = None
                self.on_step(targets)
                self.ls.stepped()
                self._budget_ns -= self.ls.dt_ns
                for g, p in targets.items():
                    self.pose_pubs[g].publish(rc.pose_stamped(p, self.ls.now_ns))
                self.publish_clock()
                if self.heavy_steps():
                    break
                continue
            if self.idle_work():
                self.publish_clock()
                break
            before = self.ls.now_ns
            self.ls.advance_free(self._budget_ns)
            self._budget_ns -= self.ls.now_ns - before
            break
        if self.ls.now_ns != start or not self.ls.closed:
            self.publish_clock()

    def _stalled(self, what: str) -> None:
        now = time.monotonic()
        if self._waiting_since is None:
            self._waiting_since = now
        elif now - self._waiting_since > params.value(self, "stall_timeout"):
            self._waiting_since = None
            self.fail(f"{what} for {params.value(self, 'stall_timeout'):g} s (trajectory_node gone?)")

    def fail(self, reason: str) -> None:
        """Abort the running fold: open every gripper, drop pending input, publish a failed result."""
        self.get_logger().error(f"fold failed: {reason}")
        for g in list(self.ls.closed):
            try:
                self.on_open(g)
            except Exception:  # noqa: BLE001
                pass
        self.ls.abort()
        self.on_abort()
        self.publish_result(False, reason, math.nan)
        self.active = None

    def publish_result(self, success: bool, reason: str, loss: float, steps: int = 0, newton: int = 0,
                       wall: float = 0.0) -> None:
        a = self.active
        self.result_pub.publish(FoldResult(
            header=rc.header(self.ls.now_ns), fold_name=a.spec.name if a else "", stage=a.stage if a else 0,
            success=bool(success), reason=reason, loss=float(loss), height_ratio=a.height_ratio if a else math.nan,
            tilt_deg=a.tilt_deg if a else math.nan, steps=int(steps), newton_iterations=int(newton),
            wall_time=float(wall)))

    # -- hooks -----------------------------------------------------------------------------------
    def heavy_steps(self) -> bool:
        """True: one step per tick (keeps the node responsive when steps are slow)."""
        return False

    def idle_work(self) -> bool:
        """Work to do while every gripper is open (e.g. settling); True if something was done."""
        return False

    def on_close(self, gripper: int, pose: Pose) -> None:
        raise NotImplementedError

    def on_step(self, targets: dict[int, Pose]) -> None:
        raise NotImplementedError

    def on_open(self, gripper: int) -> None:
        raise NotImplementedError

    def on_all_open(self) -> None:
        raise NotImplementedError

    def on_abort(self) -> None:
        pass
