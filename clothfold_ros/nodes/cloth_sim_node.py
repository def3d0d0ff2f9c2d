"""cloth_sim_node: the IPC cloth simulator as the robot backend (contract: docs/robot-interface.md).

Owns a ClothSimulator of the shirt (parameters shape, max_area, material, friction, dt,
Newton settings) lying flat at z = 2 t, and publishes /clock. A fold runs in lock-step
(backend.LockStepBackend): the grippers close at the fold's start, grasp the cloth in
their boxes, each step t -> t + dt uses the commanded poses stamped t + dt, the grippers
open at the end, the cloth settles for the fold's settle_time, and the node publishes
/fold/result: loss = mean vertex distance (m) to the fold target, success = the
simulation succeeded and loss <= max_loss. With the same inputs this equals
`clothfold_ros.sim.runner.run_fold`. The cloth is not stepped while every gripper is
open (it rests; only the clock runs). Between folds the cloth and the composed target
are kept: a fold's target is fold_target(previous target, spec, thickness), so a
sequence of folds is scored like docs/method.md section 7. A failed step publishes a failed result
and the node keeps serving (the cloth stays in its last good state).

Publishes /cloth/state (clothfold_msgs/ClothState, latched), /cloth/marker
(visualization_msgs/Marker TRIANGLE_LIST) and /cloth/points (sensor_msgs/PointCloud2: the
visible top surface as perception.camera.DepthCamera sees it, 2 mm depth noise, 10 % dropout)
every `state_period` wall seconds while the cloth moves and after every fold.
"""
from __future__ import annotations

import math
import sys
import time

import numpy as np
from clothfold_msgs.msg import ClothState
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker

from . import conversions as rc
from ..materials import DEFAULT_FRICTION
from ..pose import Pose
from ..sim.config import SimConfig
from . import common, params
from .backend import LockStepBackend
from .params import Param

PARAMS = [
    params.SHAPE,
    Param("max_area", 5e-4, "mesh max triangle area (m^2); 5e-4 ~ 1.2K triangles, the study's is 5e-5",
          range=(1e-5, 1e-2), read_only=True),
    params.MATERIAL,
    Param("friction", DEFAULT_FRICTION, "friction coefficient of every contact (-)", range=(0.0, 2.0), read_only=True),
    Param("settle_time", 0.2, "settle time after release (s) when the fold spec gives none", range=(0.0, 10.0)),
    Param("newton_tol", SimConfig.newton_tol, "Newton stop: RMS(|dx|)/dt (m/s)", range=(1e-8, 1.0), read_only=True),
    Param("max_newton_iterations", SimConfig.max_newton_iterations, "Newton iterations per step", range=(1, 10000), read_only=True),
    Param("threads", 2, "solver threads (PARDISO, CCD; the numba kernels follow NUMBA_NUM_THREADS); results are "
          "bit-for-bit the same for any count", range=(1, 64), read_only=True),
    Param("max_loss", 0.05, "a fold with a larger loss (m) is reported as failed", range=(0.0, 10.0)),
    Param("state_period", 0.5, "publish the cloth state/marker/points at most this often (wall s)",
          range=(0.0, 60.0)),
]


class ClothSimNode(LockStepBackend):
    def __init__(self) -> None:
        super().__init__("cloth_sim_node", PARAMS)
        from ..sim.scene import SceneSettings, build_scene

        self.scene = build_scene(SceneSettings(**{k: params.value(self, k) for k in (
            "shape", "max_area", "material", "friction", "dt", "newton_tol", "max_newton_iterations", "threads")}))
        self.garment, self.material, self.config = self.scene.garment, self.scene.material, self.scene.config
        self.flat = self.scene.flat
        self.state_pub = self.create_publisher(ClothState, common.CLOTH_STATE, common.LATCHED)
        self.marker_pub = self.create_publisher(Marker, common.CLOTH_MARKER, common.STREAMED)
        self.points_pub = self.create_publisher(PointCloud2, common.CLOTH_POINTS, common.LATCHED)
        self.create_service(Trigger, "~/reset", self.on_reset)
        self.episode = None
        self.settle_pending = False
        self._last_state = 0.0
        self.reset()
        self.get_logger().info(
            f"cloth: shape {params.value(self, 'shape')}, {len(self.garment.vertices)} vertices, "
            f"{len(self.garment.triangles)} triangles, {self.material.name}, mu {params.value(self, 'friction'):g}, "
            f"dt {self.config.dt:g} s")

    # -- cloth ------------------------------------------------------------------------------
    def reset(self) -> None:
        """Flat shirt, target = the flat shirt (the base of the first fold)."""
        self.sim = self.scene.simulator()
        self.target_base = self.flat.copy()
        self.fold_specs: dict = {}  # fold name -> the FoldSpec of the last fold of that name started
        self.episode = None
        self.settle_pending = False
        self.publish_state(force=True)

    def on_reset(self, _req, resp):
        if self.ls.closed or self.settle_pending:
            resp.success, resp.message = False, "a fold is running"
            return resp
        self.reset()
        resp.success, resp.message = True, "cloth reset flat"
        return resp

    def publish_state(self, force: bool = False) -> None:
        wall = time.monotonic()
        if not force and wall - self._last_state < params.value(self, "state_period"):
            return
        self._last_state = wall
        x, now = self.sim.x, self.ls.now_ns
        self.state_pub.publish(rc.cloth_state_to_msg(x, self.garment.triangles, self.garment.keypoint_ids,
                                                     self.material.thickness, now, self.sim.grasped_vertex_ids()))
        self.marker_pub.publish(rc.mesh_marker(x, self.garment.triangles, now))
        if getattr(self, "camera", None) is None:  # /cloth/points: what a depth camera above the table sees
            from ..perception.camera import DepthCamera

            self.camera, self.camera_rng = DepthCamera(), np.random.default_rng(0)
        self.points_pub.publish(rc.mesh_points(self.camera.cloud(x, self.garment.triangles, self.camera_rng), now))

    # -- lock-step hooks ------------------------------------------------------------------------
    def heavy_steps(self) -> bool:
        return True

    def on_close(self, gripper: int, pose: Pose) -> None:
        from ..loss import fold_target
        from ..sim.episode import FoldEpisode

        if self.episode is None:
            if self.active is None:
                raise ValueError("a gripper closed but no fold spec was announced on /fold/active")
            plan = self.active
            if plan.spec.n_grippers > self.n:
                raise ValueError(f"fold {plan.spec.name} needs {plan.spec.n_grippers} grippers")
            settle = plan.settle_time if plan.settle_time > 0 else params.value(self, "settle_time")
            target = fold_target(self.base_for(plan), plan.spec, self.material.thickness)
            self.fold_specs[plan.spec.name] = plan.spec
            self.episode = FoldEpisode(self.sim, plan.spec, target, settle)
            self.get_logger().info(f"fold {plan.spec.name} (stage {plan.stage}) starts at {self.ls.now_ns * 1e-9:.3f} s")
        if gripper >= self.episode.spec.n_grippers:
            raise ValueError(f"gripper_{gripper} closed, but fold {self.episode.spec.name} uses "
                             f"{self.episode.spec.n_grippers} gripper(s)")
        ids = self.sim.grasp(gripper, pose)
        self.get_logger().info(f"gripper_{gripper} closed: {len(ids)} vertices held")

    def base_for(self, plan) -> np.ndarray:
        """The target a fold's target composes onto: the flat shirt with the folds its planner
        assumed made (plan.folds_done, as this node started them), so the loss follows the
        planner's history (keypoint_node's, where it adopted a failed fold the cloud shows);
        without that list, or naming a fold this node never started, the target of the folds
        whose simulation completed here."""
        from ..loss import composed_target

        done = plan.folds_done
        if done is None:
            return self.target_base
        unseen = [n for n in done if n not in self.fold_specs]
        if unseen:
            self.get_logger().warn(f"fold {plan.spec.name} was planned after folds {list(done)}, but this node "
                                   f"never simulated {unseen}: its target composes onto the folds completed here")
            return self.target_base
        base = composed_target(self.flat, [self.fold_specs[n] for n in done], self.material.thickness)
        if not np.array_equal(base, self.target_base):
            self.get_logger().info(f"fold {plan.spec.name}: target composed onto the planner's folds {list(done)}")
        return base

    def on_step(self, targets: dict[int, Pose]) -> None:
        ep = self.episode
        if ep is None:
            raise RuntimeError("a gripper is closed but no fold is running")
        # FoldEpisode.advance wants one pose per gripper of the spec; only closed ones are used
        poses = [targets.get(i, ep.spec.start_poses[i]) for i in range(ep.spec.n_grippers)]
        ep.advance(poses)
        # the mesh marker at every step (Foxglove shows the fold as it happens); state and points at state_period
        self.marker_pub.publish(rc.mesh_marker(self.sim.x, self.garment.triangles, self.ls.now_ns + self.ls.dt_ns))
        self.publish_state()

    def on_open(self, gripper: int) -> None:
        self.sim.release(gripper)

    def on_all_open(self) -> None:
        self.settle_pending = True  # settled by idle_work on the next tick

    def has_idle_work(self) -> bool:
        return self.settle_pending

    def idle_work(self) -> bool:
        if not self.settle_pending:
            return False
        self.settle_pending = False
        ep = self.episode
        n_settle = int(math.ceil(ep.settle_time / self.sim.dt - 1e-9))
        try:
            ep.settle()
        except Exception as err:  # noqa: BLE001 - recorded in the outcome below
            if ep.failure is None:
                ep.failure = f"{type(err).__name__}: {err}"
        self.ls.now_ns += n_settle * self.ls.dt_ns
        self.finish()
        return True

    def finish(self) -> None:
        ep, plan = self.episode, self.active
        out = ep.outcome()
        ok, reason = out.success, out.reason
        if ok and self.ended_early:  # grippers opened before the motion's end (a cancel): not this fold
            ok, reason = False, self.ended_early
        if ok and not out.loss <= params.value(self, "max_loss"):
            ok, reason = False, f"loss {out.loss:.4f} m > max_loss {params.value(self, 'max_loss'):g} m"
        if out.success and not self.ended_early:
            self.target_base = ep.target  # the next fold composes onto this target
        self.get_logger().info(f"fold {plan.spec.name if plan else '?'}: loss {out.loss:.6f} m, "
                               f"{'success' if ok else 'FAILED: ' + reason}, {out.steps} steps, "
                               f"{out.wall_time:.1f} s")
        self.publish_result(ok, reason, out.loss, out.steps, out.newton_iterations, out.wall_time)
        self.episode = None
        self.active = None
        self.publish_state(force=True)

    def on_abort(self) -> None:
        if self.episode is not None:
            for i in list(self.sim.grasps):
                self.sim.release(i)
        self.episode = None
        self.settle_pending = False
        self.publish_state(force=True)


def main(argv: list[str] | None = None) -> int:
    full = list(sys.argv if argv is None else ["cloth_sim_node", *argv])
    return common.run(ClothSimNode, full)


if __name__ == "__main__":
    sys.exit(main())
