"""PipelineClient: drive a running pipeline from Python (used by `clothfold demo`, `clothfold fold`
and the tests).

Calls /plan_fold, waits for /keypoints and /fold/result; `fold_in_turn` runs a fold sequence
stage by stage, each planned from the keypoints of the cloth as it is after the previous one. Spins its own node in a
background thread; call `close()` (or use it as a context manager) to stop it.
rclpy must not be initialised yet in this process, or pass a context.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import rclpy
from clothfold_msgs.action import ExecuteFold
from clothfold_msgs.msg import ClothState, FoldResult, FoldSpec as FoldSpecMsg, Keypoints
from clothfold_msgs.srv import PlanFold
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock

from .action_client import LockedActionClient
from . import conversions as rc
from .waiting import wait_future, wait_until
from . import common


def loss_text(loss: float, success: bool = True) -> str:
    """A fold result's loss for a line of output. NaN: a successful fold on a backend without
    cloth (it measures none), or a fold that failed or never ran."""
    if math.isfinite(loss):
        return f"loss {loss:.6f} m"
    return "no loss (the backend simulates no cloth)" if success else "no loss"


@dataclass(frozen=True)
class StageOutcome:
    """One stage of `fold_in_turn`: success, loss (m; NaN: none observed or never run), the
    reason of a failure, and the backend's /fold/result (None when the planner refused)."""

    fold: str
    success: bool
    loss: float
    reason: str
    result: FoldResult | None = None


class PipelineClient:
    def __init__(self, name: str = "clothfold_client") -> None:
        self.context = rclpy.Context()
        # no rclpy signal handlers: the caller (clothfold demo) handles SIGINT/SIGTERM itself
        rclpy.init(args=[], context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = Node(name, context=self.context)
        self.cond = threading.Condition()
        self.keypoints: Keypoints | None = None
        self.cloth_state: ClothState | None = None
        self.results: list[FoldResult] = []
        self.node.create_subscription(Keypoints, common.KEYPOINTS, self._on_keypoints, common.LATCHED)
        self.result_sub = self.node.create_subscription(FoldResult, common.FOLD_RESULT, self._on_result,
                                                        common.RESULTS)
        self.node.create_subscription(ClothState, common.CLOTH_STATE, self._on_state, common.LATCHED)
        self.clock_messages = 0
        self.node.create_subscription(Clock, common.CLOCK, self._on_clock, 10)
        self.plan_client = self.node.create_client(PlanFold, common.PLAN_FOLD)
        self.execute_client = LockedActionClient(self.node, ExecuteFold, common.EXECUTE_FOLD)
        self.keypoints_pub = self.node.create_publisher(Keypoints, common.KEYPOINTS, common.LATCHED)
        self.state_pub = self.node.create_publisher(ClothState, common.CLOTH_STATE, common.LATCHED)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except Exception:  # noqa: BLE001 - shutdown
            pass

    def _on_keypoints(self, msg: Keypoints) -> None:
        with self.cond:
            self.keypoints = msg
            self.cond.notify_all()

    def _on_state(self, msg: ClothState) -> None:
        with self.cond:
            self.cloth_state = msg
            self.cond.notify_all()

    def wait_state(self, timeout: float, newer_than_ns: int = -1) -> ClothState:
        """The latest /cloth/state (stamped after newer_than_ns); TimeoutError."""
        s = wait_until(self.cond, lambda: self.cloth_state if self.cloth_state is not None and rc.time_to_ns(
            self.cloth_state.header.stamp) > newer_than_ns else None, timeout)
        if s is None:
            raise TimeoutError(f"no cloth state on {common.CLOTH_STATE} within {timeout:g} s")
        return s

    def _on_clock(self, _msg: Clock) -> None:
        with self.cond:
            self.clock_messages += 1

    def clock_count(self) -> int:
        """/clock messages received so far."""
        with self.cond:
            return self.clock_messages

    def _on_result(self, msg: FoldResult) -> None:
        with self.cond:
            self.results.append(msg)
            self.cond.notify_all()

    def wait_keypoints(self, timeout: float, newer_than_ns: int = -1) -> Keypoints:
        """The latest keypoints (stamped after newer_than_ns); TimeoutError."""
        k = wait_until(self.cond, lambda: self.keypoints if self.keypoints is not None and rc.time_to_ns(
            self.keypoints.header.stamp) > newer_than_ns else None, timeout, poll=0.2)
        if k is None:
            raise TimeoutError(f"no keypoints on {common.KEYPOINTS} within {timeout:g} s")
        return k

    def plan(self, fold_name: str, execute: bool = True, timeout: float = 30.0,
             wait_for_keypoints: bool = True, retry_refused: float = 0.0) -> PlanFold.Response:
        """Call /plan_fold; TimeoutError when the planner does not answer. With
        wait_for_keypoints, a refusal because the planner has no keypoints yet is retried
        until the timeout (the planner may start after the keypoints were published);
        a goal refused by trajectory_node (e.g. still finishing the previous fold) is
        retried for retry_refused seconds."""
        deadline = time.monotonic() + timeout
        if execute:
            self.wait_result_publisher(timeout)
        refused_until = time.monotonic() + retry_refused
        while True:
            resp = self._plan_once(fold_name, execute, max(0.1, deadline - time.monotonic()))
            now = time.monotonic()
            retry = (wait_for_keypoints and "no keypoints" in resp.message and now < deadline) or \
                ("refused" in resp.message and now < min(refused_until, deadline))
            if resp.success or not retry:
                return resp
            time.sleep(0.2)

    def wait_result_publisher(self, timeout: float) -> None:
        """Wait until a /fold/result publisher (the backend) has matched this client's
        subscription; TimeoutError otherwise. /fold/result is volatile: a fold that ends before
        discovery pairs the backend with this client is a result lost (a kinematic backend at
        50x real time ends a fold within a second of the plan call)."""
        if not wait_until(self.cond, lambda: self.backend_matched() or None, timeout, poll=0.05):
            raise TimeoutError(f"no {common.FOLD_RESULT} publisher but trajectory_node's (no backend or robot driver "
                               f"running?) matched within {timeout:g} s")

    def backend_matched(self) -> bool:
        """Whether a /fold/result publisher other than trajectory_node's (which publishes only the
        failures it reports itself) is known, and every known one matched this client."""
        infos = self.node.get_publishers_info_by_topic(common.FOLD_RESULT)
        return any(i.node_name != "trajectory_node" for i in infos) and \
            self.result_sub.get_publisher_count() >= len(infos)

    def _plan_once(self, fold_name: str, execute: bool, timeout: float) -> PlanFold.Response:
        if not self.plan_client.wait_for_service(timeout_sec=timeout):
            raise TimeoutError(f"{common.PLAN_FOLD} not available within {timeout:g} s")
        future = self.plan_client.call_async(PlanFold.Request(fold_name=fold_name, execute=execute))
        if not wait_future(future, timeout):
            raise TimeoutError(f"{common.PLAN_FOLD} did not answer within {timeout:g} s")
        return future.result()

    def send_goal(self, spec: FoldSpecMsg, timeout: float = 30.0) -> bool:
        """Send an ExecuteFold goal straight to trajectory_node; True if it was accepted."""
        return bool(self.start_goal(spec, timeout).accepted)

    def start_goal(self, spec: FoldSpecMsg, timeout: float = 30.0):
        """Send an ExecuteFold goal straight to trajectory_node; its goal handle (accepted or not)."""
        self.wait_result_publisher(timeout)
        if not self.execute_client.wait_for_server(timeout_sec=timeout):
            raise TimeoutError(f"{common.EXECUTE_FOLD} not available within {timeout:g} s")
        future = self.execute_client.send_goal_async(ExecuteFold.Goal(spec=spec))
        if not wait_future(future, timeout):
            raise TimeoutError(f"{common.EXECUTE_FOLD} did not answer within {timeout:g} s")
        return future.result()

    def cancel(self, handle, timeout: float = 30.0) -> None:
        """Ask trajectory_node to cancel a running goal (TimeoutError if it does not answer)."""
        future = handle.cancel_goal_async()
        if not wait_future(future, timeout):
            raise TimeoutError(f"cancel of the goal not answered within {timeout:g} s")

    def result_count(self) -> int:
        with self.cond:
            return len(self.results)

    def wait_result(self, fold_name: str, timeout: float, after: int = 0) -> FoldResult:
        """The first /fold/result for fold_name among results received after the first `after`."""
        r = wait_until(self.cond, lambda: next((r for r in self.results[after:] if r.fold_name == fold_name), None),
                       timeout, poll=0.5)
        if r is None:
            raise TimeoutError(f"no {common.FOLD_RESULT} for {fold_name} within {timeout:g} s")
        return r

    def close(self) -> None:
        try:
            self.executor.shutdown(timeout_sec=1.0)
        except Exception:  # noqa: BLE001
            pass
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self.thread.join(2.0)

    def __enter__(self) -> "PipelineClient":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def fold_in_turn(self, folds: Sequence[str], timeout: float, alive: Callable[[], None] = lambda: None,
                     planned: Callable[[FoldSpecMsg], None] | None = None,
                     finished: Callable[[int, str, FoldResult], None] | None = None,
                     say: Callable[[str], None] = print, keypoints_wait: float = 60.0,
                     outcomes: list[StageOutcome] | None = None) -> list[StageOutcome]:
        """Plan and execute `folds` one after the other on the running pipeline; stop at the first
        refusal or failed fold. Each stage waits up to `timeout` s for its /fold/result; before the
        next, keypoints stamped after that result (the cloth as it is now; the planner refuses older
        ones). `alive()` is called while waiting and may raise (e.g. a node exited); `planned` /
        `finished` see each plan and result; `say` prints the progress lines. RuntimeError when no
        fresh keypoints come within `keypoints_wait` s, TimeoutError when a result does not come.
        Each stage's outcome is appended to `outcomes` (returned) as it ends: a caller that passes
        its own list keeps the finished stages when a later one raises."""
        outcomes = [] if outcomes is None else outcomes
        for stage, fold in enumerate(folds):
            alive()
            before = self.result_count()
            resp = self.plan(fold, execute=True, timeout=120, retry_refused=10.0)
            if not resp.success:
                outcomes.append(StageOutcome(fold, False, math.nan, f"planner refused: {resp.message}"))
                say(f"{fold}: planner refused: {resp.message}")
                break
            say(f"stage {stage}: {resp.message}")
            if planned is not None:
                planned(resp.spec)
            res = self._wait_result_alive(fold, timeout, before, alive)
            outcomes.append(StageOutcome(fold, res.success, res.loss, res.reason, res))
            say(f"{fold}: {'success' if res.success else 'FAILED'}, {loss_text(res.loss, res.success)}"
                + (f" ({res.reason})" if res.reason else "") + f", {res.steps} steps")
            if finished is not None:
                finished(stage, fold, res)
            if not res.success:
                say(f"stopping the sequence: {fold} failed")
                break
            if stage + 1 < len(folds):
                try:
                    self.wait_keypoints(keypoints_wait, newer_than_ns=rc.time_to_ns(res.header.stamp) - 1)
                except TimeoutError:
                    raise RuntimeError(f"no keypoints of the cloth after {fold} within {keypoints_wait:g} s (the "
                                       "keypoint node's log says why, e.g. a rejected fit)") from None
        return outcomes

    def _wait_result_alive(self, fold: str, timeout: float, after: int, alive: Callable[[], None]) -> FoldResult:
        """The fold's /fold/result, calling alive() about once a second meanwhile."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                return self.wait_result(fold, min(1.0, max(0.01, deadline - time.monotonic())), after=after)
            except TimeoutError:
                alive()
                if time.monotonic() >= deadline:
                    raise
