"""trajectory_node: executes fold specifications (action /execute_fold, clothfold_msgs/ExecuteFold).

For one goal (a FoldSpec with height ratio, tilt, duration) it
1. checks it (finite values; a known fold name; h, tilt inside the search space of the
   lookup, duration and settle time in range: limits.check_plan_limits; gripper count, workspace
   box, gripper speed limit) and that no other fold runs; a refused goal is rejected with
   the reason logged;
2. picks the start time t0 = now + start_delay (node clock: /clock with use_sim_time, or
   wall time), publishes the spec on /fold/active and each gripper's whole path
   (nav_msgs/Path, latched) on /gripper_<i>/path;
3. closes the grippers at t0 (clothfold_msgs/GripperCommand position 0 on
   /gripper_<i>/command, stamped t0), streams each gripper's geometry_msgs/PoseStamped
   target on /gripper_<i>/target_pose at `rate` Hz (stamps t0 + k / rate, frame
   "table"), publishing every sample whose stamp is <= now + lookahead (lock-step
   backends need to see the next sample before their clock reaches it), and opens the
   grippers (position = open_position) stamped at the last sample;
4. reports feedback (progress 0..1, time from start) and, once the backend's
   /fold/result for this fold arrives (wait_for_result), the action result.
A fold that ends otherwise (cancelled, the clock stood still: backend gone, no result in
time) always ends with a failed /fold/result: the backend's if it sends one within
`failure_report_wait` s, else one published by this node with the reason. A cancel after
the whole motion was sent cannot stop it: it is logged, the backend's result stands.
Everything in the table frame (m, z up).
"""
from __future__ import annotations

import dataclasses
import math
import sys
import threading
import time
from collections import deque

import numpy as np
from clothfold_msgs.action import ExecuteFold
from clothfold_msgs.msg import FoldResult, FoldSpec as FoldSpecMsg, GripperCommand
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from . import conversions as rc
from ..pose import Pose
from . import common, params
from .limits import check_plan_limits, check_ranges, check_trajectory, check_workspace_params
from .lockstep import STAMP_TOLERANCE_NS
from .params import Param
from .waiting import wait_until

PACE_WINDOW = 3.0  # s of wall time over which the clock's pace is measured (start lead)
PACE_SPAN = 0.5  # s of wall time: the shortest stretch a pace is measured over (timer jitter averages out)


def fastest_pace(samples: list[tuple[float, int]], span: float = PACE_SPAN) -> float:
    """The clock's fastest pace (clock ns per wall s) over any stretch of at least span wall
    seconds between samples (wall s, clock ns), in time order; over all of them if they span
    less; 0 for fewer than two. The fastest, not the mean: a backend starved for a while (a
    loaded machine) and then running at full speed would otherwise get too short a lead."""
    if len(samples) < 2:
        return 0.0
    wall = np.array([w for w, _ in samples])
    clock = np.array([c for _, c in samples], dtype=float)
    if wall[-1] - wall[0] < span:
        return max(0.0, clock[-1] - clock[0]) / max(wall[-1] - wall[0], 1e-9)
    ends = np.searchsorted(wall, wall + span)  # the first sample at least span later
    ok = ends < len(wall)
    i, j = np.flatnonzero(ok), ends[ok]
    return float(max(0.0, np.max((clock[j] - clock[i]) / (wall[j] - wall[i]))))

PARAMS = [
    Param("rate", 100.0, "target pose stream rate (Hz)", range=(1.0, 1000.0)),
    Param("start_delay", 0.5, "time from accepting a fold to closing the grippers (s, node clock)",
          range=(0.0, 10.0)),
    Param("start_lead_wall", 0.5, "the fold starts at least this many wall seconds ahead: with a simulated clock "
          "running faster than real time, start_delay alone may pass before the backend gets /fold/active",
          range=(0.0, 10.0)),
    Param("lookahead", 0.2, "publish samples this far ahead of the clock (s); >= the backend's dt for lock-step, "
          "0 for a driver that executes targets on receipt", range=(0.0, 5.0)),
    Param("workspace_min", [-1.0, -1.0, 0.0], "workspace box lower corner (m, table frame)", range=(-10.0, 10.0),
          length=3),
    Param("workspace_max", [1.0, 1.0, 1.0], "workspace box upper corner (m, table frame)", range=(-10.0, 10.0),
          length=3),
    Param("max_speed", 1.0, "gripper speed limit (m/s)", range=(0.01, 10.0)),
    params.N_GRIPPERS,
    Param("open_position", 0.08, "finger opening of an open gripper (m); 0 = closed", range=(0.001, 1.0)),
    Param("max_effort", -1.0, "gripper max effort (N); negative = no limit", range=(-1.0, 1000.0)),
    Param("wait_for_result", True, "wait for the backend's /fold/result before finishing the goal"),
    Param("result_timeout", 600.0, "wall seconds to wait for /fold/result after the motion", range=(0.1, 36000.0)),
    Param("stall_timeout", 60.0, "abort when the clock stands still this many wall seconds", range=(0.1, 3600.0)),
    Param("failure_report_wait", 5.0, "after a cancel or abort, wait this long (wall s) for the backend's failed "
          "/fold/result before publishing one itself", range=(0.0, 600.0)),
]


def _param_check(values: dict, changed=()) -> str | None:
    """Cross checks: the workspace box, and that one lookahead's burst of target poses
    (rate x lookahead samples) fits half the target topic's history (a reliable KEEP_LAST
    writer drops its oldest unacknowledged sample when the history is full: lock-step then
    waits for a pose that never comes)."""
    reason = check_workspace_params(values, changed)
    if reason:
        return reason
    burst, room = values["rate"] * values["lookahead"], common.TARGETS.depth // 2
    if burst > room:
        return (f"rate x lookahead = {burst:g} target poses published at once, more than {room} (half the "
                f"target_pose history of {common.TARGETS.depth}): lower rate or lookahead")
    return None


class TrajectoryNode(Node):
    def __init__(self) -> None:
        super().__init__("trajectory_node")
        params.declare(self, PARAMS, _param_check)
        n = params.value(self, "n_grippers")
        self._prepared = None  # (goal spec message, plan) of the goal checked last
        self.group = ReentrantCallbackGroup()
        self._clock_samples: deque[tuple[float, int]] = deque()  # (wall s, clock ns): the clock's recent pace
        self.create_timer(0.1, self._sample_clock, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.pose_pubs = [self.create_publisher(PoseStamped, common.gripper_topic(i, "target_pose"), common.TARGETS)
                          for i in range(n)]
        self.cmd_pubs = [self.create_publisher(GripperCommand, common.gripper_topic(i, "command"), common.COMMANDS)
                         for i in range(n)]
        self.path_pubs = [self.create_publisher(Path, common.gripper_topic(i, "path"), common.LATCHED)
                          for i in range(n)]
        self.active_pub = self.create_publisher(FoldSpecMsg, common.FOLD_ACTIVE, common.LATCHED)
        self.result_pub = self.create_publisher(FoldResult, common.FOLD_RESULT, common.RESULTS)
        self.create_subscription(FoldResult, common.FOLD_RESULT, self.on_result, common.RESULTS,
                                 callback_group=self.group)
        self.results: list[FoldResult] = []  # /fold/result messages of the fold under way
        self.results_cv = threading.Condition()
        self._started = None  # (plan, t0 ns) of the fold under way
        self._failure: FoldResult | None = None  # the backend's failed result of the fold under way
        self._streamed_until = 0  # stamp of the last target pose sent (ns)
        self.lock = threading.Lock()
        self.busy: str | None = None  # name of the running fold
        self.server = ActionServer(self, ExecuteFold, common.EXECUTE_FOLD, self.execute,
                                   goal_callback=self.on_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
                                   callback_group=self.group)
        self.get_logger().info(f"ready: {common.EXECUTE_FOLD}, {n} gripper(s), {params.value(self, 'rate'):g} Hz")

    # -- checks ---------------------------------------------------------------------------
    def prepare(self, spec_msg: FoldSpecMsg) -> rc.PlannedFold:
        """The goal's PlannedFold (its trajectory: `plan.trajectory`); ValueError with the reason
        it is refused. The goal checked last is prepared once: its execution reuses what on_goal
        checked."""
        cached = self._prepared
        if cached is not None and cached[0] is spec_msg:
            return cached[1]
        try:
            plan = rc.fold_spec_from_msg(spec_msg)  # the core plan checks itself when built
        except ValueError as err:  # a number outside the search space says so first (its path may also
            # reach below the table, which the core refuses when the trajectory is built)
            m = spec_msg
            numbers = (m.height_ratio, m.tilt_deg, m.duration, m.settle_time, m.layer_offset_factor)
            outside = check_ranges(*numbers) if all(math.isfinite(v) for v in numbers) else None
            raise ValueError(outside or str(err)) from None
        reason = check_plan_limits(plan) or check_trajectory(
            plan.trajectory, params.value(self, "rate"), params.value(self, "workspace_min"),
            params.value(self, "workspace_max"), params.value(self, "max_speed"), params.value(self, "n_grippers"))
        if reason:
            raise ValueError(reason)
        self._prepared = (spec_msg, plan)
        return plan

    def on_goal(self, goal: ExecuteFold.Goal) -> GoalResponse:
        name = goal.spec.fold_name or "?"
        try:
            self.prepare(goal.spec)
        except Exception as err:  # noqa: BLE001 - any bad spec is refused, the node keeps serving
            self.get_logger().error(f"fold {name!r} refused: {err}")
            return GoalResponse.REJECT
        with self.lock:
            if self.busy is not None:
                self.get_logger().error(f"fold {name!r} refused: fold {self.busy!r} is still running")
                return GoalResponse.REJECT
            self.busy = name
        return GoalResponse.ACCEPT

    def on_result(self, msg: FoldResult) -> None:
        started = self._started
        with self.results_cv:
            if started is not None and self._is_result_of(msg, *started) is False:
                self.get_logger().warn(
                    f"{common.FOLD_RESULT} ignored: it names fold {msg.fold_name!r} stage {msg.stage} stamped "
                    f"{rc.time_to_ns(msg.header.stamp) * 1e-9:.3f} s; the fold under way is "
                    f"{started[0].spec.name!r} stage {started[0].stage} from {started[1] * 1e-9:.3f} s")
                return
            self.results.append(msg)
            del self.results[:-20]
            if started is not None and not msg.success and self._failure is None:
                self._failure = msg  # the backend gave up on the fold under way: stop streaming it
            self.results_cv.notify_all()

    @staticmethod
    def _is_result_of(msg: FoldResult, plan, t0: int) -> bool:
        """Whether a /fold/result is the one of the fold `plan` started at t0: its name and stage, stamped
        at or after t0 (a driver copies name and stage from /fold/active and stamps on the same clock)."""
        return (msg.fold_name == plan.spec.name and int(msg.stage) == int(plan.stage)
                and rc.time_to_ns(msg.header.stamp) >= t0 - STAMP_TOLERANCE_NS)

    # -- execution ----------------------------------------------------------------------------
    def now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _sample_clock(self) -> None:
        """10 Hz (steady clock): (wall s, node clock ns) samples of the last PACE_WINDOW s (none
        while the clock reads 0; cleared when it goes back)."""
        now, clock = time.monotonic(), self.now_ns()
        if clock <= 0:
            return  # no /clock yet: a later jump from 0 is no pace
        if self._clock_samples and clock < self._clock_samples[-1][1]:
            self._clock_samples.clear()  # the clock went back (a replay looped, a sim reset): a new clock
        self._clock_samples.append((now, clock))
        while self._clock_samples and self._clock_samples[0][0] < now - PACE_WINDOW:
            self._clock_samples.popleft()

    def _start_lead_ns(self) -> int:
        """Time from now to the fold's start (ns, node clock): start_delay, or more where the clock
        runs fast enough to cover start_lead_wall in less: its pace is the fastest the clock ran
        over the last PACE_WINDOW wall seconds (`fastest_pace`)."""
        delay = rc.seconds_to_ns(params.value(self, "start_delay"))
        lead_wall = params.value(self, "start_lead_wall")
        if lead_wall <= 0.0:
            return delay
        return max(delay, int(fastest_pace(list(self._clock_samples)) * lead_wall))

    def command(self, grippers: range, closed: bool, stamp_ns: int) -> None:
        pos = 0.0 if closed else params.value(self, "open_position")
        for i in grippers:
            self.cmd_pubs[i].publish(rc.gripper_command(i, pos, params.value(self, "max_effort"), stamp_ns))

    def execute(self, handle) -> ExecuteFold.Result:
        self._started = None  # (plan, t0 ns) once the fold is under way
        self._failure = None
        try:
            return self._execute(handle)
        except Exception as err:  # noqa: BLE001 - never leave the node busy
            if not self.context.ok():  # shutting down: nothing to report to
                return ExecuteFold.Result(success=False, message="trajectory_node shut down")
            self.get_logger().error(f"fold failed: {type(err).__name__}: {err}")
            try:
                handle.abort()
            except Exception:  # noqa: BLE001 - already finished
                pass
            result = self._report_failure(handle, f"aborted: {err}")
            return ExecuteFold.Result(success=False, message=f"{type(err).__name__}: {err}", result=result)
        finally:
            self._started = None
            with self.lock:
                self.busy = None

    def _report_failure(self, handle, reason: str, until_ns: int | None = None) -> FoldResult:
        """Make sure a failed /fold/result for this fold is published: the backend's (waited for
        failure_report_wait s; it reports grippers that opened early) or else this node's own.
        until_ns: the stamp of the open command sent; the wait starts once the clock reached it (the
        backend opens then: on a lock-step clock that is up to `lookahead` later), or once the clock
        stood still for stall_timeout: one result per fold, never this node's and then the backend's."""
        if until_ns is not None and params.value(self, "wait_for_result"):
            self._wait_clock(until_ns, params.value(self, "stall_timeout"), handle, cancellable=False)
        if self._started is not None:
            plan, t0 = self._started
        else:
            try:
                plan, t0 = rc.fold_spec_from_msg(handle.request.spec), self.now_ns()
            except ValueError:
                return FoldResult(success=False, reason=reason, loss=math.nan)
        name = plan.spec.name
        if params.value(self, "wait_for_result"):
            got = self._wait_result(name, t0, params.value(self, "failure_report_wait"))
            if got is not None:
                if got.success:  # a backend that does not check: the fold did not run to its end
                    self.get_logger().error(f"{name}: the backend reported success for a fold that was {reason}")
                else:
                    return got
        result = FoldResult(header=rc.header(max(self.now_ns(), t0)), fold_name=name, stage=plan.stage,
                            success=False, reason=f"{reason} (reported by trajectory_node)", loss=math.nan,
                            height_ratio=plan.height_ratio, tilt_deg=plan.tilt_deg)
        self.result_pub.publish(result)
        self.get_logger().error(f"published a failed {common.FOLD_RESULT} for {name}: {result.reason}")
        return result

    def _wait_clock(self, until_ns: int, stall: float, handle, cancellable: bool = True) -> str | None:
        """Wait until the clock reaches until_ns; reason on stall, a failure the backend reported
        ("backend failed") or (if cancellable) cancel."""
        last, since = self.now_ns(), time.monotonic()
        while self.now_ns() < until_ns:
            if not self.context.ok():
                return "shutting down"
            if self._failure is not None:
                return "backend failed"
            if cancellable and handle.is_cancel_requested:
                return "cancelled"
            now = self.now_ns()
            if now != last:
                last, since = now, time.monotonic()
            elif time.monotonic() - since > stall:
                return f"the clock stood still for {stall:g} s (is the backend running and publishing /clock?)"
            time.sleep(0.005)
        return None

    def _execute(self, handle) -> ExecuteFold.Result:
        plan = self.prepare(handle.request.spec)
        traj = plan.trajectory
        spec = plan.spec
        rate = params.value(self, "rate")
        ahead = rc.seconds_to_ns(params.value(self, "lookahead"))
        stall = params.value(self, "stall_timeout")
        log = self.get_logger()
        grippers = range(spec.n_grippers)
        if self.now_ns() == 0:  # sim time before the first /clock
            reason = self._wait_clock(1, stall, handle)
            if reason:
                raise RuntimeError(f"no clock: {reason}")
        times, pos, quat = traj.sample(rate)
        # after every target sent before (a fold the backend failed leaves some stamped ahead of the clock):
        # a late one of those must not land inside this fold's motion
        # (bounded by the lookahead: a clock that went back, a sim reset, leaves no such targets)
        now, period = self.now_ns(), rc.seconds_to_ns(1.0 / rate)
        t0 = now + self._start_lead_ns()
        if now < self._streamed_until <= now + ahead + period:
            t0 = max(t0, self._streamed_until + period)
        stamps = [t0 + rc.seconds_to_ns(t) for t in times]
        poses = [[Pose(pos[k, g], quat[k, g]) for g in grippers] for k in range(len(times))]
        with self.results_cv:
            self.results.clear()
            self._failure = None
            self._started = (plan, t0)
        active = rc.fold_spec_to_msg(dataclasses.replace(plan, stamp_ns=t0))
        self.active_pub.publish(active)
        for g in grippers:
            self.path_pubs[g].publish(rc.path_msg(stamps, [p[g] for p in poses]))
        log.info(f"executing {spec.name} (stage {plan.stage}, h={plan.height_ratio:g}, tilt={plan.tilt_deg:g} deg, "
                 f"{plan.duration:g} s, {len(times)} samples x {len(grippers)} gripper(s)) from t0={t0 * 1e-9:.3f} s")
        self.command(grippers, True, t0)
        k, last, since = 0, self.now_ns(), time.monotonic()
        feedback = ExecuteFold.Feedback()
        cancelled = False
        while k < len(stamps):
            if not self.context.ok():
                raise RuntimeError("shutting down during the motion")
            if self._failure is not None:
                break
            if handle.is_cancel_requested:
                cancelled = True
                break
            now = self.now_ns()
            while k < len(stamps) and stamps[k] <= now + ahead:
                for g in grippers:
                    self.pose_pubs[g].publish(rc.pose_stamped(poses[k][g], stamps[k]))
                self._streamed_until = stamps[k]
                k += 1
            if now != last:
                last, since = now, time.monotonic()
                feedback.time_from_start = max(0.0, (now - t0) * 1e-9)
                feedback.progress = float(np.clip(feedback.time_from_start / plan.duration, 0.0, 1.0))
                handle.publish_feedback(feedback)
            elif time.monotonic() - since > stall:
                self.command(grippers, False, max(now, stamps[max(k - 1, 0)]))
                raise RuntimeError(f"the clock stood still for {stall:g} s during the motion (backend gone?)")
            if k < len(stamps):
                time.sleep(min(1.0 / rate, 0.01))
        t_open = stamps[max(k - 1, 0)]
        self.command(grippers, False, t_open)
        if self._failure is not None:
            return self._backend_failed(handle, spec.name, k, len(stamps))
        if cancelled:
            handle.canceled()
            log.warn(f"fold {spec.name} cancelled; grippers open at {t_open * 1e-9:.3f} s")
            result = self._report_failure(handle, f"cancelled at {t_open * 1e-9:.3f} s", until_ns=t_open)
            return ExecuteFold.Result(success=False, message="cancelled", result=result)
        # every target and the open command are sent: the backend runs the fold to its end and
        # reports it, so a cancel from here on cannot stop it (it would only add a failed result)
        reason = self._wait_clock(t_open, stall, handle, cancellable=False)
        if reason == "backend failed":
            return self._backend_failed(handle, spec.name, k, len(stamps))
        if reason:
            raise RuntimeError(f"waiting for the end of the motion: {reason}")
        if handle.is_cancel_requested:
            log.warn(f"fold {spec.name}: cancel requested after its whole motion was sent; it ran to its end")
        feedback.progress, feedback.time_from_start = 1.0, plan.duration
        handle.publish_feedback(feedback)
        result = FoldResult(header=rc.header(t_open), fold_name=spec.name, stage=plan.stage, success=True,
                            reason="", loss=math.nan, height_ratio=plan.height_ratio, tilt_deg=plan.tilt_deg)
        if params.value(self, "wait_for_result"):
            got = self._wait_result(spec.name, t0, params.value(self, "result_timeout"))
            if got is None:
                handle.abort()
                why = f"no {common.FOLD_RESULT} from the backend within {params.value(self, 'result_timeout'):g} s"
                result = self._report_failure(handle, why)
                return ExecuteFold.Result(success=False, message=f"{spec.name}: {why}", result=result)
            result = got
        ok = bool(result.success)
        msg = f"{spec.name}: loss {result.loss:.6f} m" if ok else f"{spec.name} failed: {result.reason}"
        (handle.succeed if ok else handle.abort)()
        log.info(f"done: {msg}")
        return ExecuteFold.Result(success=ok, message=msg, result=result)

    def _backend_failed(self, handle, name: str, sent: int, total: int) -> ExecuteFold.Result:
        """The backend reported the fold under way failed: its streaming stopped, the goal aborted with
        the backend's result (published already: no second one), the node free for the next fold."""
        result = self._failure
        self.get_logger().error(f"fold {name} failed (reported by the backend after {sent} of {total} samples were "
                                f"sent; streaming stopped): {result.reason}")
        handle.abort()
        return ExecuteFold.Result(success=False, message=f"{name} failed: {result.reason}", result=result)

    def _wait_result(self, name: str, t0: int, timeout: float) -> FoldResult | None:
        started = self._started

        def probe() -> FoldResult | bool | None:  # False: shutting down, stop waiting
            r = next((r for r in self.results if (self._is_result_of(r, *started) if started is not None else
                                                  r.fold_name == name and rc.time_to_ns(r.header.stamp) >= t0)),
                     None)
            return r if r is not None else (None if self.context.ok() else False)

        r = wait_until(self.results_cv, probe, timeout, poll=0.5)
        return None if r is False else r


def main(argv: list[str] | None = None) -> int:
    full = list(sys.argv if argv is None else ["trajectory_node", *argv])
    return common.run(TrajectoryNode, full, threads=4)


if __name__ == "__main__":
    sys.exit(main())
