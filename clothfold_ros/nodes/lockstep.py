"""Lock-step bookkeeping shared by the backends (cloth_sim_node, kinematic_robot_node). Pure: no rclpy.

The backend owns simulated time (integer nanoseconds, published on /clock). It holds
each gripper's commanded target poses by stamp and the pending open/close commands, and
decides what to do next:

- a command is applied once the clock has reached its stamp (a close also needs the
  target pose stamped at that time: the gripper grasps there);
- while any gripper is closed, the backend steps from t to t + dt only once it has the
  target pose stamped t + dt for every closed gripper (exact stamp, or interpolated
  between two bracketing samples when the stream rate does not divide dt), so a run
  never depends on message timing;
- while every gripper is open the clock runs freely (the caller paces it), but never
  past the stamp of a pending command or of an announced fold start (`hold_until`).
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass, field

import numpy as np

from ..pose import Pose, slerp

STAMP_TOLERANCE_NS = 1_000  # 1 us: stamps closer than this are the same instant


@dataclass(order=True)
class Command:
    """Open (closed=False) or close gripper `gripper` at `stamp_ns`."""

    stamp_ns: int
    gripper: int = field(compare=False)
    closed: bool = field(compare=False)


class PoseBuffer:
    """Target poses of one gripper, sorted by stamp (ns)."""

    def __init__(self) -> None:
        self.stamps: list[int] = []
        self.poses: list[Pose] = []

    def add(self, stamp_ns: int, pose: Pose) -> None:
        i = bisect.bisect_left(self.stamps, stamp_ns)
        if i < len(self.stamps) and abs(self.stamps[i] - stamp_ns) <= STAMP_TOLERANCE_NS:
            self.poses[i] = pose  # a re-sent sample replaces the old one
            return
        self.stamps.insert(i, stamp_ns)
        self.poses.insert(i, pose)

    def at(self, stamp_ns: int) -> Pose | None:
        """Pose at stamp_ns: the sample with that stamp, else interpolated between the two
        bracketing samples (linear position, slerp orientation), else None (not there yet)."""
        i = bisect.bisect_left(self.stamps, stamp_ns - STAMP_TOLERANCE_NS)
        if i < len(self.stamps) and abs(self.stamps[i] - stamp_ns) <= STAMP_TOLERANCE_NS:
            return self.poses[i]
        if 0 < i < len(self.stamps):
            a, b = self.stamps[i - 1], self.stamps[i]
            u = (stamp_ns - a) / (b - a)
            pa, pb = self.poses[i - 1], self.poses[i]
            return Pose((1 - u) * pa.position + u * pb.position, np.asarray(slerp(pa, pb, u)).reshape(4))
        return None

    def latest(self) -> Pose | None:
        return self.poses[-1] if self.poses else None

    def drop_before(self, stamp_ns: int) -> None:
        """Forget samples older than stamp_ns, keeping the last one before it (for interpolation)."""
        i = bisect.bisect_left(self.stamps, stamp_ns - STAMP_TOLERANCE_NS)
        if i > 1:
            del self.stamps[: i - 1]
            del self.poses[: i - 1]

    def clear(self) -> None:
        self.stamps.clear()
        self.poses.clear()


class LockStep:
    """Clock, target poses and gripper commands of a lock-step backend."""

    def __init__(self, n_grippers: int, dt: float) -> None:
        if n_grippers < 1:
            raise ValueError(f"n_grippers must be >= 1, got {n_grippers}")
        if not dt > 0:
            raise ValueError(f"dt must be > 0 s, got {dt}")
        self.n = n_grippers
        self.dt_ns = int(round(dt * 1e9))
        self.now_ns = 0
        self.targets = [PoseBuffer() for _ in range(n_grippers)]
        self.closed: set[int] = set()
        self.pending: list[Command] = []
        self.hold_until: int | None = None  # announced fold start: the free clock stops there

    # -- input ---------------------------------------------------------------------------
    def add_target(self, gripper: int, stamp_ns: int, pose: Pose) -> None:
        self._check_gripper(gripper)
        if stamp_ns < self.now_ns - STAMP_TOLERANCE_NS and gripper in self.closed:
            raise ValueError(f"gripper_{gripper} target stamped {stamp_ns * 1e-9:.3f} s arrived after the clock "
                             f"passed it ({self.now_ns * 1e-9:.3f} s)")
        self.targets[gripper].add(stamp_ns, pose)

    def add_command(self, gripper: int, stamp_ns: int, closed: bool) -> None:
        """Queue an open/close command; ValueError when its stamp is already in the past."""
        self._check_gripper(gripper)
        if stamp_ns < self.now_ns - STAMP_TOLERANCE_NS:
            raise ValueError(f"gripper_{gripper} {'close' if closed else 'open'} command stamped "
                             f"{stamp_ns * 1e-9:.3f} s arrived after the clock passed it ({self.now_ns * 1e-9:.3f} s); "
                             f"start folds further ahead (trajectory_node start_delay)")
        bisect.insort(self.pending, Command(int(stamp_ns), gripper, closed))

    def _check_gripper(self, gripper: int) -> None:
        if not 0 <= gripper < self.n:
            raise ValueError(f"gripper index {gripper} out of range (this backend has {self.n} grippers)")

    # -- decisions -------------------------------------------------------------------------
    def due_command(self) -> Command | None:
        """The next command whose stamp the clock has reached (not removed)."""
        if self.pending and self.pending[0].stamp_ns <= self.now_ns + STAMP_TOLERANCE_NS:
            return self.pending[0]
        return None

    def pop_command(self) -> Command:
        return self.pending.pop(0)

    def target_now(self, gripper: int) -> Pose | None:
        return self.targets[gripper].at(self.now_ns)

    def step_targets(self) -> dict[int, Pose] | None:
        """Target pose at now + dt of every closed gripper, or None while one is missing."""
        t = self.now_ns + self.dt_ns
        out = {}
        for g in sorted(self.closed):
            p = self.targets[g].at(t)
            if p is None:
                return None
            out[g] = p
        return out

    def free_advance_limit(self) -> int | None:
        """The latest time the free-running clock may reach (None: no limit)."""
        limits = [c.stamp_ns for c in self.pending[:1]]
        if self.hold_until is not None:
            limits.append(self.hold_until)
        return min(limits) if limits else None

    def advance_free(self, ns: int) -> None:
        """Advance the idle clock by up to ns, stopping at the next command or announced start."""
        limit = self.free_advance_limit()
        new = self.now_ns + max(0, int(ns))
        self.now_ns = max(self.now_ns, min(new, limit) if limit is not None else new)

    def stepped(self) -> None:
        """The backend completed one dt step."""
        self.now_ns += self.dt_ns
        for b in self.targets:
            b.drop_before(self.now_ns)

    def close(self, gripper: int) -> None:
        self.closed.add(gripper)
        if self.hold_until is not None and self.hold_until <= self.now_ns + STAMP_TOLERANCE_NS:
            self.hold_until = None

    def open(self, gripper: int) -> None:
        self.closed.discard(gripper)
        if not self.closed:
            for b in self.targets:
                b.drop_before(self.now_ns)

    def abort(self) -> None:
        """Open everything and forget pending commands and targets (after a failure)."""
        self.closed.clear()
        self.pending.clear()
        self.hold_until = None
        for b in self.targets:
            b.clear()
