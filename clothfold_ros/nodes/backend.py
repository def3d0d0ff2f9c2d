"""LockStepBackend: the robot side of the pipeline contract (docs/robot-interface.md), shared by
cloth_sim_node and kinematic_robot_node.

It owns simulated time and publishes it on /clock (rosgraph_msgs/Clock); it must run on
wall time itself (never use_sim_time). Subscribes /gripper_<i>/target_pose and
/gripper_<i>/command and /fold/active; publishes /gripper_<i>/pose (the gripper's actual
pose, PoseStamped, every step while closed), /gripper_<i>/state (sensor_msgs/JointState:
finger opening in m) and /fold/result. Time advances by `LockStep` rules: a step t -> t + dt
only once the target stamped t + dt of every closed gripper is there; while every gripper
is open the clock runs at real_time_factor (in whole steps of dt) to an announced fold's start
and stops there, and stands still while nothing is announced (commands nobody announced are
run to after `announce_wait` s). Idle, the main loop sleeps (its timer cancelled; input wakes
it) and /clock goes out once a second (HEARTBEAT), so that no node of the pipeline wakes per
tick. The clock starts at 1 s (0 means "no /clock yet" on sim time). Subclasses implement the
physics hooks.

For a person watching (Foxglove): /gripper_<i>/marker (visualization_msgs/Marker CUBE, latched)
draws each gripper as its grasp box (GRIPPER_BOX along the gripper x, y, z axes) at its pose,
red while closed, green while open, at every step and at every open/close; a gripper is drawn
from its first close on (where it opened, it stays).

What the backend refuses (logged through ErrorLog, never silently): targets in another frame,
NaN poses or efforts, targets for a gripper that is open with no fold running, announced or
pending for it (idle), a close command with no target pose at its stamp and no fold announced
for it (dropped at once: the clock never waits for it). Its own limits (workspace box, speed
over a step) fail a running fold, and so do grippers that open before the end of the
announced motion (the fold was cancelled or aborted upstream): /fold/result success = false
with the reason.
"""
from __future__ import annotations

import math
import time

from clothfold_msgs.msg import FoldResult, FoldSpec as FoldSpecMsg, GripperCommand
from rcl_interfaces.msg import SetParametersResult
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker

from . import conversions as rc
from ..pose import Pose
from . import common, params
from .errorlog import ErrorLog
from .limits import check_step, check_workspace_params
from .lockstep import STAMP_TOLERANCE_NS, LockStep
from .params import Param

GRIPPER_BOX = (0.05, 0.12, 0.05)  # m along the gripper x, y, z: the grasp box (sim/grasp.py GRASP_BOX)
GRIPPER_COLOURS = {True: (0.9, 0.2, 0.2, 0.8), False: (0.2, 0.8, 0.3, 0.6)}  # closed: red, open: green


def gripper_marker(i: int, pose: Pose, closed: bool, stamp_ns: int) -> Marker:
    """visualization_msgs/Marker CUBE of gripper i: the grasp box at its pose (table frame)."""
    r, g, b, a = GRIPPER_COLOURS[bool(closed)]
    m = Marker(header=rc.header(stamp_ns), ns="gripper", id=i, type=Marker.CUBE, action=Marker.ADD,
               pose=rc.pose_to_msg(pose), color=ColorRGBA(r=r, g=g, b=b, a=a), text=f"gripper_{i}")
    m.scale.x, m.scale.y, m.scale.z = GRIPPER_BOX
    return m


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
    Param("workspace_min", [-1.0, -1.0, 0.0], "the backend's own workspace box, lower corner (m, table frame); "
          "a target outside it fails the fold", range=(-10.0, 10.0), length=3),
    Param("workspace_max", [1.0, 1.0, 1.0], "the backend's own workspace box, upper corner (m, table frame)",
          range=(-10.0, 10.0), length=3),
    Param("max_speed", 1.0, "the backend's own gripper speed limit (m/s) over one dt step; faster fails the fold",
          range=(0.01, 10.0)),
    Param("announce_wait", 5.0, "a gripper command with no fold announced on /fold/active for it waits this long "
          "(wall s) for its announcement before the clock runs to it", range=(0.0, 600.0)),
]
START_NS = 1_000_000_000  # the clock starts at 1 s: 0 reads as "no /clock yet" to a node on sim time
HEARTBEAT = 1.0  # wall s: a clock standing still is published again this often (nodes started later learn it)


class LockStepBackend(Node):
    """Base node: subclasses override on_close, on_step, on_open, on_all_open (and may use idle_work)."""

    def __init__(self, name: str, extra_params: list[Param]) -> None:
        super().__init__(name)
        if self.get_parameter("use_sim_time").value:
            raise ValueError(f"{name} publishes /clock and must run on wall time (use_sim_time false)")
        params.declare(self, BACKEND_PARAMS + extra_params, check_workspace_params)
        self.add_on_set_parameters_callback(self._keep_wall_time)
        self.n = params.value(self, "n_grippers")
        self.ls = LockStep(self.n, params.value(self, "dt"))
        self.clock_pub = self.create_publisher(Clock, common.CLOCK, common.CLOCK_QOS)
        self.result_pub = self.create_publisher(FoldResult, common.FOLD_RESULT, common.RESULTS)
        self.pose_pubs = [self.create_publisher(PoseStamped, common.gripper_topic(i, "pose"), common.FEEDBACK)
                          for i in range(self.n)]
        self.state_pubs = [self.create_publisher(JointState, common.gripper_topic(i, "state"), common.FEEDBACK)
                           for i in range(self.n)]
        self.marker_pubs = [self.create_publisher(Marker, common.gripper_topic(i, "marker"), common.STREAMED)
                            for i in range(self.n)]
        self.drawn: dict[int, Pose] = {}  # where each gripper is drawn: its last pose (kept after it opens)
        # created in the order trajectory_node publishes a fold (announcement, commands, targets): the
        # executor serves the subscriptions that are ready together in creation order, so a fold's first
        # target is never taken (and dropped as unexpected) before its announcement and close command
        self.create_subscription(FoldSpecMsg, common.FOLD_ACTIVE, self.on_active, common.LATCHED)
        for i in range(self.n):
            self.create_subscription(GripperCommand, common.gripper_topic(i, "command"),
                                     lambda m, i=i: self.on_command(i, m), common.COMMANDS)
        for i in range(self.n):
            self.create_subscription(PoseStamped, common.gripper_topic(i, "target_pose"),
                                     lambda m, i=i: self.on_target(i, m), common.TARGETS)
        self.active: rc.PlannedFold | None = None  # the fold being executed (from /fold/active)
        self.announced: rc.PlannedFold | None = None  # the next fold (from /fold/active), not started yet
        self.ended_early: str | None = None  # why the fold whose grippers just opened is a failure
        self.failed: rc.PlannedFold | None = None  # the fold this backend failed last: its late input is ignored
        self.opening = [0.0] * self.n
        self.last_pose: dict[int, Pose] = {}  # last commanded pose of each closed gripper
        self._last_wall = time.monotonic()
        self._budget_ns = 0
        self._waiting_since: float | None = None
        self._held_since: float | None = None
        self._unannounced_since: float | None = None  # wall s since commands wait with no fold announced
        self._clock_sent: tuple[int, float] | None = None  # (clock ns, wall s) of the last /clock
        self.errors = ErrorLog(interval=1.0)
        self.ls.now_ns = START_NS
        # the main loop runs only while something moves or waits (a fold announced, running or settling,
        # commands pending); idle, it is cancelled and the clock stands still: input wakes it (`wake`)
        self.tick_timer = self.create_timer(params.value(self, "tick"), self.on_tick)
        self.create_timer(HEARTBEAT, self.on_heartbeat)
        self.publish_clock()

    @staticmethod
    def _keep_wall_time(changes) -> SetParametersResult:
        """A backend publishes /clock: switched to it (use_sim_time true) its own timer would wait
        for a clock only it advances, and the whole pipeline would stop without a word."""
        if any(p.name == "use_sim_time" and p.value for p in changes):
            return SetParametersResult(successful=False, reason="this backend publishes /clock and runs on wall "
                                                                "time: use_sim_time stays false")
        return SetParametersResult(successful=True)

    # -- input -------------------------------------------------------------------------------
    def error_once(self, key: str, text: str) -> None:
        """Log an input error: every one counted, the first of each kind logged, repeats at most
        once a second with the counts (ErrorLog); the rest are reported with the fold's result."""
        line = self.errors.record(key, text)
        if line:
            self.get_logger().error(line)

    def _fold_covers(self, stamp_ns: int) -> bool:
        """True when the running or the announced fold's motion [t0, t0 + duration] covers the stamp."""
        for f in (self.active, self.announced):
            if f is not None and f.stamp_ns - STAMP_TOLERANCE_NS <= stamp_ns <= \
                    f.stamp_ns + rc.seconds_to_ns(f.duration) + STAMP_TOLERANCE_NS:
                return True
        return False

    def _of_failed_fold(self, i: int, stamp_ns: int) -> bool:
        """Input stamped inside the motion of the fold this backend failed (its sender streams on until it
        hears of the failure), for an open gripper with no other fold running or announced then."""
        f = self.failed
        if f is None or i in self.ls.closed or self._fold_covers(stamp_ns):
            return False
        return f.stamp_ns - STAMP_TOLERANCE_NS <= stamp_ns <= \
            f.stamp_ns + rc.seconds_to_ns(f.duration) + STAMP_TOLERANCE_NS

    def _expects_target(self, i: int, stamp_ns: int) -> bool:
        """A target for gripper i stamped stamp_ns belongs to a fold: the gripper is closed, a close is
        pending for it at or before the stamp, or the running/announced fold's motion covers the stamp."""
        if i in self.ls.closed:
            return True
        if any(c.closed and c.gripper == i and c.stamp_ns <= stamp_ns + STAMP_TOLERANCE_NS for c in self.ls.pending):
            return True
        return self._fold_covers(stamp_ns)

    def on_target(self, i: int, msg: PoseStamped) -> None:
        try:
            rc.check_table_frame(msg.header, "target pose")
            stamp = rc.time_to_ns(msg.header.stamp)
            pose = rc.pose_from_msg(msg.pose, f"gripper_{i} target")
            if self._of_failed_fold(i, stamp):
                return  # the sender streams on until it hears of the failure, which is reported already
            if not self._expects_target(i, stamp):
                self.error_once(f"idle_target{i}", f"gripper_{i} target stamped {stamp * 1e-9:.3f} s dropped: the "
                                "gripper is open and no fold is running, announced or pending for that time")
                return
            self.ls.add_target(i, stamp, pose)
            self.wake()
        except ValueError as err:
            self.error_once(f"target{i}", f"gripper_{i} target pose ignored: {err}")

    def on_command(self, i: int, msg: GripperCommand) -> None:
        try:
            rc.check_table_frame(msg.header, "command")
            if msg.gripper and msg.gripper != f"gripper_{i}":
                raise ValueError(f"command names {msg.gripper!r} on gripper_{i}'s topic")
            if not (math.isfinite(msg.position) and msg.position >= 0):
                raise ValueError(f"finger opening must be >= 0 m, got {msg.position}")
            if not math.isfinite(msg.max_effort):
                raise ValueError(f"max_effort must be finite (N; negative = no limit), got {msg.max_effort}")
            closed = msg.position <= params.value(self, "close_threshold")
            if self._of_failed_fold(i, rc.time_to_ns(msg.header.stamp)):
                self.get_logger().info(f"gripper_{i} {'close' if closed else 'open'} command stamped "
                                       f"{rc.time_to_ns(msg.header.stamp) * 1e-9:.3f} s of the failed fold "
                                       f"{self.failed.spec.name} ignored (the gripper is open)")
                return
            self.ls.add_command(i, rc.time_to_ns(msg.header.stamp), closed)
            if not closed:
                self.opening[i] = msg.position  # applied when due; remembered for the state
            self.wake()
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
        if plan.stamp_ns < self.ls.now_ns - STAMP_TOLERANCE_NS and not self._closes_pending_at(plan.stamp_ns):
            late = (f"/fold/active {plan.spec.name} ignored: it starts at {plan.stamp_ns * 1e-9:.3f} s, before "
                    f"the clock ({self.ls.now_ns * 1e-9:.3f} s)")
            if self.ls.now_ns < plan.stamp_ns + rc.seconds_to_ns(plan.duration):
                # its motion is under way without this backend: say so now, or the sender waits for a result
                self.get_logger().error(late)
                self.publish_result(False, f"{late}; the announcement came too late (start_delay too short for "
                                    "the clock's pace?)", math.nan, fold=plan)
            else:  # a latched announcement of a fold long over (this node started later)
                self.error_once("old_active", late)
            return
        self.announced = plan
        self.failed = None
        if not self.ls.closed:
            self.ls.hold_until = plan.stamp_ns  # the idle clock runs to the fold's start, not past it
        self.wake()

    def _open_pending(self, gripper: int, stamp_ns: int) -> bool:
        return any(not c.closed and c.gripper == gripper and c.stamp_ns <= stamp_ns + STAMP_TOLERANCE_NS
                   for c in self.ls.pending)

    def _closes_pending_at(self, stamp_ns: int) -> bool:
        return any(c.closed and abs(c.stamp_ns - stamp_ns) <= STAMP_TOLERANCE_NS for c in self.ls.pending)

    # -- main loop ------------------------------------------------------------------------------
    def publish_clock(self) -> None:
        self.clock_pub.publish(Clock(clock=rc.ns_to_time(self.ls.now_ns)))
        self._clock_sent = (self.ls.now_ns, time.monotonic())

    def busy(self) -> bool:
        """Whether the main loop has anything to do: a gripper closed, a command pending, a fold
        announced (the clock runs to its start) or work of the subclass (`idle_work`, e.g. settling).
        Otherwise the clock stands still and the loop sleeps until input wakes it."""
        return bool(self.ls.closed or self.ls.pending or self.ls.hold_until is not None
                    or self.announced is not None or self.has_idle_work())

    def wake(self) -> None:
        """Restart the main loop after idling (input arrived); its pace restarts from now."""
        if self.tick_timer.is_canceled():
            self._last_wall, self._budget_ns = time.monotonic(), 0
            self.tick_timer.reset()

    def on_heartbeat(self) -> None:
        """Once a second: a clock that stood still since the last /clock is published again (a node
        started later learns the time; nothing wakes the nodes per tick while nothing moves)."""
        sent = self._clock_sent
        if sent is None or sent[0] != self.ls.now_ns or time.monotonic() - sent[1] >= 0.9 * HEARTBEAT:
            self.publish_clock()

    def publish_gripper_state(self, i: int) -> None:
        closed = i in self.ls.closed
        self.state_pubs[i].publish(JointState(header=rc.header(self.ls.now_ns, ""), name=[f"gripper_{i}"],
                                              position=[0.0 if closed else float(self.opening[i])]))
        self.publish_gripper_markers([i])

    def publish_gripper_markers(self, grippers=None) -> None:
        """The grasp-box marker of each given gripper (default: all) that has a pose to draw."""
        for i in (range(self.n) if grippers is None else grippers):
            if i in self.drawn:
                self.marker_pubs[i].publish(gripper_marker(i, self.drawn[i], i in self.ls.closed, self.ls.now_ns))

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
        if not self.busy():
            self.tick_timer.cancel()  # idle: the clock stands still until input wakes the loop
            self._unannounced_since = None

    def _tick(self) -> None:
        start = self.ls.now_ns
        while True:
            cmd = self.ls.due_command()
            if cmd is not None:
                if cmd.closed:
                    pose = self.ls.target_now(cmd.gripper)
                    if pose is None and not self.ls.closed and not self._fold_covers(cmd.stamp_ns):
                        self.ls.pop_command()  # a stray close: never hold the clock for it
                        self.error_once(f"stray_close{cmd.gripper}", f"gripper_{cmd.gripper} close command stamped "
                                        f"{cmd.stamp_ns * 1e-9:.3f} s dropped: no target pose at its stamp and no "
                                        f"fold announced on {common.FOLD_ACTIVE} for it")
                        continue
                    if pose is None and not self.ls.closed and self._open_pending(cmd.gripper, cmd.stamp_ns):
                        # cancelled before it started: the opens are already queued; the other grippers'
                        # closes of that start go too, and the fold's sender hears of it at once
                        self.ls.pending = [c for c in self.ls.pending if not (
                            c.closed and abs(c.stamp_ns - cmd.stamp_ns) <= STAMP_TOLERANCE_NS
                            and self._open_pending(c.gripper, c.stamp_ns))]
                        why = (f"gripper_{cmd.gripper} close at {cmd.stamp_ns * 1e-9:.3f} s dropped: the fold was "
                               "cancelled before it started")
                        self.get_logger().warning(why)
                        if self.announced is not None and self._fold_covers(cmd.stamp_ns):
                            self.publish_result(False, why, math.nan, fold=self.announced)
                        self.announced = None
                        self.ls.hold_until = None  # nothing to wait for
                        continue
                    if pose is None:
                        return self._stalled(f"no target pose of gripper_{cmd.gripper} at its close time "
                                             f"{cmd.stamp_ns * 1e-9:.3f} s")
                    self.ls.pop_command()
                    if cmd.gripper not in self.ls.closed:
                        if not self.ls.closed:
                            self.active, self.announced = self.announced, None
                            self.ended_early = None
                        reason = check_step({}, {cmd.gripper: pose}, self.ls.dt_ns * 1e-9,
                                            params.value(self, "workspace_min"), params.value(self, "workspace_max"),
                                            params.value(self, "max_speed"))
                        if reason:
                            self.ls.close(cmd.gripper)  # so that fail() opens it again
                            return self.fail(f"grasp refused: {reason}")
                        self.on_close(cmd.gripper, pose)
                        self.ls.close(cmd.gripper)
                        self.last_pose[cmd.gripper] = pose
                        self.drawn[cmd.gripper] = pose
                        self.publish_gripper_state(cmd.gripper)
                else:
                    self.ls.pop_command()
                    if cmd.gripper in self.ls.closed:
                        self.on_open(cmd.gripper)
                        self.ls.open(cmd.gripper)
                        self.last_pose.pop(cmd.gripper, None)
                        self.publish_gripper_state(cmd.gripper)
                        if not self.ls.closed:
                            self.ended_early = self._early_open_reason()
                            if self.ended_early:
                                self.get_logger().error(f"fold failed: {self.ended_early}")
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
                reason = check_step(self.last_pose, targets, self.ls.dt_ns * 1e-9, params.value(self, "workspace_min"),
                                    params.value(self, "workspace_max"), params.value(self, "max_speed"))
                if reason:
                    return self.fail(f"limit at {(self.ls.now_ns + self.ls.dt_ns) * 1e-9:.3f} s: {reason}")
                self.on_step(targets)
                self.last_pose.update(targets)
                self.ls.stepped()
                self._budget_ns -= self.ls.dt_ns
                for g, p in targets.items():
                    self.pose_pubs[g].publish(rc.pose_stamped(p, self.ls.now_ns))
                self.drawn.update(targets)
                self.publish_gripper_markers()  # every gripper at every step
                self.publish_clock()
                if self.heavy_steps():
                    break
                continue
            if self.idle_work():
                self.publish_clock()
                break
            if self.announced is not None and self.ls.hold_until is None:
                self.ls.hold_until = self.announced.stamp_ns  # announced while a fold ran: run to its start
            if not self._may_run_free():
                break
            before = self.ls.now_ns
            self.ls.advance_free(self._budget_ns // self.ls.dt_ns * self.ls.dt_ns)  # whole steps: one /clock per dt
            self._budget_ns -= self.ls.now_ns - before
            hold = self.ls.hold_until
            if hold is not None and self.ls.now_ns >= hold - STAMP_TOLERANCE_NS and not self.ls.pending:
                self._held_since = self._held_since or time.monotonic()
                if time.monotonic() - self._held_since > params.value(self, "stall_timeout"):
                    # the announced fold's close command never came: stop holding the clock for it
                    self.error_once("no_close", f"fold {self.announced.spec.name if self.announced else '?'} "
                                    f"announced for {hold * 1e-9:.3f} s: no close command within "
                                    f"{params.value(self, 'stall_timeout'):g} s; the clock runs on")
                    self.ls.hold_until = None
                    self.announced = None
            else:
                self._held_since = None
            break
        if self.ls.now_ns != start:
            self.publish_clock()

    def _may_run_free(self) -> bool:
        """Whether the clock may run while every gripper is open: towards an announced fold's start,
        or towards pending commands nobody announced once they waited announce_wait s for it (their
        announcement may still be in flight: running the clock to them at once would drop a close
        whose /fold/active comes a moment later). Never while nothing is announced or pending."""
        if self.ls.hold_until is not None:
            self._unannounced_since = None
            return True
        if not self.ls.pending:
            self._unannounced_since = None
            return False
        now = time.monotonic()
        if self._unannounced_since is None:
            self._unannounced_since = now
        return now - self._unannounced_since >= params.value(self, "announce_wait")

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
        self.last_pose.clear()
        self.publish_gripper_markers()  # drawn open
        self.on_abort()
        self.publish_result(False, reason, math.nan)
        self.failed = self.active
        self.active = None
        self._report_unlogged()

    def _early_open_reason(self) -> str | None:
        """Why a fold whose grippers all opened now is a failure: they opened before the end of the
        announced motion (t0 + duration), i.e. the fold was cancelled or aborted. None otherwise."""
        a = self.active
        if a is None:
            return None
        end = a.stamp_ns + rc.seconds_to_ns(a.duration)
        if self.ls.now_ns >= end - STAMP_TOLERANCE_NS:
            return None
        return (f"the grippers opened at {self.ls.now_ns * 1e-9:.3f} s, {(end - self.ls.now_ns) * 1e-9:.3f} s before "
                f"the end of the planned motion ({end * 1e-9:.3f} s): the fold was cancelled or aborted")

    def _report_unlogged(self) -> None:
        line = self.errors.flush()
        if line:
            self.get_logger().error(line)

    def publish_result(self, success: bool, reason: str, loss: float, steps: int = 0, newton: int = 0,
                       wall: float = 0.0, fold: rc.PlannedFold | None = None) -> None:
        """/fold/result of the running fold, or of `fold` (one this backend will not run)."""
        a = self.active if fold is None else fold
        if success is not False and self.ended_early:
            success, reason = False, self.ended_early
        self._report_unlogged()
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

    def has_idle_work(self) -> bool:
        """Whether idle_work has something to do (the main loop keeps running for it)."""
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
