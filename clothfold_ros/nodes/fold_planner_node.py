"""fold_planner_node: PlanFold service (/plan_fold) -> fold specification from the latest keypoints.

On a request naming a fold (left_sleeve, right_sleeve, left_side, right_side, middle) it
builds the fold line and gripper start/end poses from the latest /keypoints
(`folding.fold_spec`), picks (height ratio, tilt) with the selector, publishes the
FoldSpec on /fold/spec (latched) and, when execute = true, sends it to trajectory_node
(action /execute_fold); the response then says whether the goal was accepted (the
outcome arrives on /fold/result). Bad requests (unknown fold, no keypoints yet,
NaN keypoints, a refused goal) get success = false and a clear message; the node keeps
serving. Successful folds on /fold/result are remembered (`~/reset`, std_srvs/Trigger,
forgets them) and passed to fold_spec: the keypoints then describe the folded shirt as
a camera sees it (docs/method.md, keypoints of a folded shirt).

Selection: `selection` = "parameter" uses the height_ratio and tilt_deg parameters;
"table" uses clothfold_ros.lookup.planner_selector.TableSelector(table_dir). When the
table cannot be used the request is refused, unless fallback_to_parameters is true.
"""
from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

from clothfold_msgs.action import ExecuteFold
from clothfold_msgs.msg import FoldResult, FoldSpec as FoldSpecMsg, Keypoints
from clothfold_msgs.srv import PlanFold
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from std_srvs.srv import Trigger

from .action_client import LockedActionClient
from . import conversions as rc
from ..folding import FOLD_NAMES, FOLD_SEQUENCE, body_length, fold_spec, fold_type
from ..garment import KEYPOINT_NAMES
from . import common, params
from .limits import DURATION_RANGE, HEIGHT_RATIO_RANGE, TILT_RANGE_DEG
from .params import Param
from .waiting import wait_future

PARAMS = [
    Param("selection", "table", "how (height ratio, tilt) are chosen", choices=("parameter", "table")),
    Param("height_ratio", 0.5, "Bezier height ratio (-) when selection = parameter (the search space)",
          range=HEIGHT_RATIO_RANGE),
    Param("tilt_deg", 30.0, "Bezier tilt (deg) when selection = parameter (the search space)", range=TILT_RANGE_DEG),
    Param("table_dir", "config/tables", "lookup table directories in order of precedence, "
          "joined by ':' (a scenario's table comes from the first with a complete one); relative paths are below "
          "the package's share directory, found through the ament index (the checkout when run from source)"),
    Param("fallback_to_parameters", False, "use the parameters when the table cannot be used (else refuse)"),
    params.MATERIAL,
    Param("friction", 0.5, "friction coefficient assumed for table selection (-)", range=(0.0, 2.0)),
    Param("duration", 4.0, "fold motion duration (s)", range=DURATION_RANGE),
    Param("settle_time", 0.2, "settle time after release (s)", range=(0.0, 10.0)),
    Param("end_angle_deg", 175.0, "end pose: start pose rotated this much about the fold line (deg) when "
          "selection = parameter; a table's choice uses the table's own end angle",
          range=(1.0, 179.0)),
    Param("end_height", 0.05, "end pose height above the table (m)", range=(0.0, 0.5)),
    Param("goal_timeout", 10.0, "wait this long for trajectory_node to accept a goal (s)", range=(0.1, 600.0)),
    Param("fresh_keypoints_wait", 10.0, "after a /fold/result, refuse to plan from keypoints stamped before it for "
          "up to this many wall seconds (then plan from the newest, with a warning: a fold that never moved "
          "the cloth, or a rejected fit, brings no newer keypoints)", range=(0.0, 600.0)),
]


def resolve_dirs(spec: str) -> list[Path]:
    """table_dir as paths in order of precedence ("a:b"): absolute as given, relative below
    the package share directory."""
    from ..lookup.table import table_roots
    from .resources import resource

    return [resource(p) for p in table_roots(spec)]


class FoldPlannerNode(Node):
    def __init__(self) -> None:
        super().__init__("fold_planner_node")
        params.declare(self, PARAMS)
        self.group = ReentrantCallbackGroup()
        self.keypoints: dict | None = None
        self.keypoints_stamp = 0
        self.keypoint_folds: list[str] | None = None  # the folds the keypoints follow, if their publisher says
        self.create_subscription(Keypoints, common.KEYPOINTS, self.on_keypoints, common.LATCHED,
                                 callback_group=self.group)
        self.spec_pub = self.create_publisher(FoldSpecMsg, common.FOLD_SPEC, common.LATCHED)
        self.executor_client = LockedActionClient(self, ExecuteFold, common.EXECUTE_FOLD, callback_group=self.group)
        self.create_service(PlanFold, common.PLAN_FOLD, self.on_plan, callback_group=self.group)
        # Folds made so far (successful /fold/result, in order): the keypoints are those a
        # camera sees on the folded shirt, and fold_spec needs to know which folds they follow.
        self.folds_done: list[str] = []
        self.last_result_ns = -1  # stamp of the newest /fold/result: keypoints older than it show the cloth before
        self.last_result_wall = 0.0  # time.monotonic() when it arrived
        # the flat shirt's body length (m), measured when a fold is planned on the flat shirt: the
        # middle line lies half of it above the hem (folding.fold_spec); None = not seen flat
        self.flat_body_length: float | None = None
        self.create_subscription(FoldResult, common.FOLD_RESULT, self.on_result, common.RESULTS,
                                 callback_group=self.group)
        self.create_service(Trigger, "~/reset", self.on_reset, callback_group=self.group)
        self._selector = None
        self._selector_error: str | None = None
        self._selector_dirs: str | None = None  # the table_dir the selector was loaded from
        self.lock = threading.Lock()
        self.get_logger().info(f"ready: {common.PLAN_FOLD} (selection = {params.value(self, 'selection')})")

    def on_keypoints(self, msg: Keypoints) -> None:
        try:
            kp, _ = rc.keypoints_from_msg(msg)
            folds = rc.keypoint_folds_from_msg(msg)
            missing = [n for n in KEYPOINT_NAMES if n not in kp]
            if missing:  # a partial set never replaces a complete one
                raise ValueError(f"incomplete set: {len(missing)} of {len(KEYPOINT_NAMES)} keypoints missing "
                                 f"({', '.join(missing)})")
        except ValueError as err:
            self.get_logger().error(f"keypoints ignored (keeping the last good ones): {err}")
            return
        with self.lock:
            self.keypoints, self.keypoints_stamp, self.keypoint_folds = kp, rc.time_to_ns(msg.header.stamp), folds

    def on_result(self, msg: FoldResult) -> None:
        if msg.fold_name not in FOLD_NAMES:
            self.get_logger().warn(f"/fold/result of an unknown fold {msg.fold_name!r} ignored (known: "
                                   f"{', '.join(FOLD_NAMES)})")
            return
        with self.lock:
            if msg.fold_name in FOLD_NAMES:  # failed or not, the cloth may have moved
                self.last_result_ns = max(self.last_result_ns, rc.time_to_ns(msg.header.stamp))
                self.last_result_wall = time.monotonic()
            if msg.success and msg.fold_name in FOLD_NAMES and msg.fold_name not in self.folds_done:
                self.folds_done.append(msg.fold_name)
                self.get_logger().info(f"folds done: {', '.join(self.folds_done)}")

    def on_reset(self, _req, resp):
        with self.lock:
            self.folds_done, self.last_result_ns, self.flat_body_length = [], -1, None
        resp.success, resp.message = True, ("folds done and the flat body length forgotten (the shirt lies flat); "
                                            "keypoints that list folds still win: reset keypoint_node too (clothfold reset "
                                            "resets cloth, keypoints and planner in order)")
        return resp

    # -- selection -----------------------------------------------------------------------------
    def selector(self):
        """The TableSelector (loaded lazily, again when `table_dir` is set to other directories);
        raises RuntimeError with the reason."""
        if params.value(self, "table_dir") != self._selector_dirs:
            self._selector, self._selector_error = None, None
            self._selector_dirs = params.value(self, "table_dir")
        if self._selector is None and self._selector_error is None:
            table_dir = resolve_dirs(params.value(self, "table_dir"))
            try:
                from ..lookup.planner_selector import TableSelector

                self._selector = TableSelector(table_dir)
            except Exception as err:  # noqa: BLE001 - missing module, tables or a bad file
                self._selector_error = f"lookup table selector unavailable ({':'.join(map(str, table_dir))}): {type(err).__name__}: {err}"
        if self._selector is None:
            raise RuntimeError(self._selector_error)
        return self._selector

    def select(self, name: str, keypoints: dict) -> tuple[float, float, float, str, str]:
        """(height ratio, tilt deg, end angle deg, note, source) for the fold: a table's choice
        comes with the end angle its folds were simulated with; source is the short form
        ("table shape1, fan point 7" or "parameters") the service's reply carries."""
        h, tilt = params.value(self, "height_ratio"), params.value(self, "tilt_deg")
        end_angle = params.value(self, "end_angle_deg")
        if params.value(self, "selection") == "parameter":
            return h, tilt, end_angle, "from parameters", "parameters"
        try:
            s = self.selector().select(fold_name=name, keypoints=keypoints, material=params.value(self, "material"),
                                       friction=params.value(self, "friction"),
                                       duration=params.value(self, "duration"), stage=FOLD_SEQUENCE.index(name))
            return float(s.height_ratio), float(s.tilt_deg), s.end_angle_deg, \
                f"table {s.scenario}: expected loss {s.expected_loss:.4f} m; {s.note}; end angle {s.end_angle_deg:g} deg", \
                f"table {s.scenario}, fan point {s.point}"
        except Exception as err:  # noqa: BLE001
            if not params.value(self, "fallback_to_parameters"):
                raise RuntimeError(f"table selection failed: {err}") from err
            self.get_logger().warn(f"table selection failed ({err}); falling back to parameters as configured")
            return h, tilt, end_angle, f"from parameters (table failed: {err})", "parameters, the table failed"

    # -- service --------------------------------------------------------------------------------
    def on_plan(self, req: PlanFold.Request, resp: PlanFold.Response) -> PlanFold.Response:
        try:
            return self._on_plan(req, resp)
        except Exception as err:  # noqa: BLE001 - a bad request never kills the planner
            resp.success, resp.message = False, f"cannot plan {req.fold_name!r}: {type(err).__name__}: {err}"
            self.get_logger().error(resp.message)
            return resp

    def _on_plan(self, req: PlanFold.Request, resp: PlanFold.Response) -> PlanFold.Response:
        resp.success = False
        try:
            msg, source = self.plan_with_source(req.fold_name)
        except (ValueError, RuntimeError) as err:
            resp.message = f"cannot plan {req.fold_name!r}: {err}"
            self.get_logger().error(resp.message)
            return resp
        resp.spec = msg
        self.spec_pub.publish(msg)
        if not req.execute:
            resp.success, resp.message = True, f"planned {req.fold_name} (h={msg.height_ratio:g}, " \
                                               f"tilt={msg.tilt_deg:g} deg; {source})"
            return resp
        accepted, why = self.send(msg)
        resp.success = accepted
        resp.message = (f"executing {req.fold_name} (h={msg.height_ratio:g}, tilt={msg.tilt_deg:g} deg; {source}); "
                        f"result on {common.FOLD_RESULT}") if accepted else f"planned {req.fold_name} but {why}"
        if accepted:
            self.get_logger().info(resp.message)
        else:
            self.get_logger().error(resp.message)
        return resp

    def plan(self, name: str) -> FoldSpecMsg:
        """The fold's spec message from the latest keypoints; ValueError / RuntimeError with the
        reason it cannot be planned."""
        return self.plan_with_source(name)[0]

    def plan_with_source(self, name: str) -> tuple[FoldSpecMsg, str]:
        """`plan`, and where (h, tilt) came from (`select`'s source: "table shape1, fan point 7")."""
        if name not in FOLD_NAMES:
            raise ValueError(f"unknown fold; known folds: {', '.join(FOLD_NAMES)}")
        with self.lock:
            kp, stamp, done, last = self.keypoints, self.keypoints_stamp, list(self.folds_done), self.last_result_ns
            seen = self.keypoint_folds
            waited = time.monotonic() - self.last_result_wall
        if kp is None:
            raise ValueError(f"no keypoints received on {common.KEYPOINTS} yet")
        if stamp < last:
            stale = (f"the newest keypoints are stamped {stamp * 1e-9:.3f} s, before the last fold result "
                     f"({last * 1e-9:.3f} s)")
            if waited < params.value(self, "fresh_keypoints_wait"):
                raise ValueError(f"no keypoints of the cloth as it lies now: {stale}")
            self.get_logger().warn(f"{stale}; none newer for {waited:.1f} s: planning from them, with the "
                                   "folds of the fold results (the keypoints' list predates the last result)")
        elif seen is not None:  # one history: the folds the keypoints follow, as the keypoint source saw them
            if seen != done:
                self.get_logger().warn(f"the keypoints follow folds [{', '.join(seen)}], the fold results "
                                       f"[{', '.join(done)}]: planning with the keypoints' folds")
            done = seen
        if name in done:
            raise ValueError(f"the folds made are [{', '.join(done)}]: {name} is done already")
        length = self.flat_length(kp, done, name)
        h, tilt, end_angle, note, source = self.select(name, kp)
        spec = fold_spec(name, kp, end_angle, params.value(self, "end_height"), folds_done=done, body_length=length)
        self.get_logger().info(f"{name}: h={h:g}, tilt={tilt:g} deg ({note}); keypoints stamped {stamp * 1e-9:.3f} s")
        return rc.fold_spec_to_msg(rc.PlannedFold(spec, h, tilt, params.value(self, "duration"),
                                                  params.value(self, "settle_time"), FOLD_SEQUENCE.index(name),
                                                  self.get_clock().now().nanoseconds, folds_done=tuple(done))), source

    def flat_length(self, kp: dict, done: list[str], name: str) -> float | None:
        """The flat shirt's body length (m): the one measured the first time a fold was planned
        with no fold done (since the start or ~/reset; a later "flat" history may come from a
        partly folded cloth), else None, with a warning for the middle fold."""
        with self.lock:
            if not done and self.flat_body_length is None:
                self.flat_body_length = body_length(kp)
            length = self.flat_body_length
        if length is None and fold_type(name) == "middle":
            self.get_logger().warn("the shirt was never seen flat (planner started or reset after a fold): the "
                                   "middle line lies halfway between the visible shoulders and hem, above the study's")
        return length

    def send(self, msg: FoldSpecMsg) -> tuple[bool, str]:
        timeout = params.value(self, "goal_timeout")
        if not self.executor_client.wait_for_server(timeout_sec=timeout):
            return False, f"trajectory_node ({common.EXECUTE_FOLD}) is not available"
        future = self.executor_client.send_goal_async(ExecuteFold.Goal(spec=msg))
        if not wait_future(future, timeout):
            future.add_done_callback(_cancel_if_accepted)  # the caller is told it failed: it must not run later
            return False, f"trajectory_node did not answer within {timeout:g} s"
        handle = future.result()
        if handle is None or not handle.accepted:
            return False, ("trajectory_node refused it (a fold is running, or the motion leaves the workspace "
                           "or exceeds the speed limit; its log says which)")
        return True, ""


def _cancel_if_accepted(future) -> None:
    """Done-callback of a goal request given up on: cancel the goal if it was accepted after all."""
    handle = future.result()
    if handle is not None and handle.accepted:
        handle.cancel_goal_async()


def main(argv: list[str] | None = None) -> int:
    full = list(sys.argv if argv is None else ["fold_planner_node", *argv])
    return common.run(FoldPlannerNode, full, threads=4)


if __name__ == "__main__":
    sys.exit(main())
