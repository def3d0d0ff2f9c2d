"""ROS messages <-> core types. Thin, validating, no geometry logic.

Frames: everything is in the table frame (metres, z up, `TABLE_FRAME`). Quaternions are
(x, y, z, w). Stamps are handled as integer nanoseconds (`time_to_ns`, `ns_to_time`) so
lock-step stamps match exactly. Every `*_from_msg` raises ValueError with a clear message
for NaN/inf values or malformed arrays.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from clothfold_msgs.msg import ClothState, FoldSpec as FoldSpecMsg, GripperCommand, Keypoints
from geometry_msgs.msg import Point, Pose as PoseMsg, PoseStamped, Quaternion, Vector3
from nav_msgs.msg import Path
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker

from ..folding import FOLD_NAMES, FoldSpec
from . import limits
from ..plan import FoldPlan
from ..pose import Pose

TABLE_FRAME = "table"
NS_PER_S = 1_000_000_000


# -- time -------------------------------------------------------------------------------
def ns_to_time(ns: int) -> Time:
    """builtin_interfaces/Time from integer nanoseconds (>= 0)."""
    ns = int(ns)
    if ns < 0:
        raise ValueError(f"time must be >= 0 ns, got {ns}")
    return Time(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)


def time_to_ns(t: Time) -> int:
    return int(t.sec) * NS_PER_S + int(t.nanosec)


def stamp_ns(h: Header, what: str) -> int:
    """A message header's stamp in ns; ValueError for a stamp before 0 (no clock gives one)."""
    ns = time_to_ns(h.stamp)
    if ns < 0:
        raise ValueError(f"{what} stamp is negative ({h.stamp.sec} s, {h.stamp.nanosec} ns)")
    return ns


def seconds_to_ns(s: float) -> int:
    ns = s * NS_PER_S
    if not math.isfinite(ns):
        raise ValueError(f"time must be finite, got {s} s")
    return int(round(ns))


def header(stamp_ns: int, frame_id: str = TABLE_FRAME) -> Header:
    return Header(stamp=ns_to_time(stamp_ns), frame_id=frame_id)


# -- vectors and poses ------------------------------------------------------------------
def _finite(values: Sequence[float], what: str) -> np.ndarray:
    a = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what} is not finite: {a.tolist()}")
    return a


def point_to_msg(p: Sequence[float]) -> Point:
    x, y, z = _finite(p, "point").reshape(3)
    return Point(x=float(x), y=float(y), z=float(z))


def point_from_msg(m: Point | Vector3, what: str = "point") -> np.ndarray:
    return _finite([m.x, m.y, m.z], what)


def vector_to_msg(v: Sequence[float]) -> Vector3:
    x, y, z = _finite(v, "vector").reshape(3)
    return Vector3(x=float(x), y=float(y), z=float(z))


def pose_to_msg(pose: Pose) -> PoseMsg:
    q = pose.quaternion
    return PoseMsg(position=point_to_msg(pose.position),
                   orientation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))


def pose_from_msg(m: PoseMsg, what: str = "pose") -> Pose:
    """Core Pose from geometry_msgs/Pose; ValueError for NaN or a zero quaternion."""
    p = _finite([m.position.x, m.position.y, m.position.z], f"{what} position")
    q = _finite([m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w], f"{what} orientation")
    if np.linalg.norm(q) < 1e-6:
        raise ValueError(f"{what} orientation is a zero quaternion")
    return Pose(p, q)


def pose_stamped(pose: Pose, stamp_ns: int, frame_id: str = TABLE_FRAME) -> PoseStamped:
    return PoseStamped(header=header(stamp_ns, frame_id), pose=pose_to_msg(pose))


def path_msg(stamps_ns: Sequence[int], poses: Sequence[Pose], frame_id: str = TABLE_FRAME) -> Path:
    """nav_msgs/Path of one gripper; header stamped at the first pose."""
    if len(stamps_ns) != len(poses) or not poses:
        raise ValueError("a path needs as many stamps as poses (at least one)")
    return Path(header=header(stamps_ns[0], frame_id),
                poses=[pose_stamped(p, s, frame_id) for s, p in zip(stamps_ns, poses)])


def gripper_command(gripper: int, position: float, max_effort: float, stamp_ns: int) -> GripperCommand:
    """Open/close command: position = finger opening (m), 0 = closed; executes at stamp."""
    if not (math.isfinite(position) and position >= 0.0):
        raise ValueError(f"gripper position must be >= 0 m, got {position}")
    return GripperCommand(header=header(stamp_ns), gripper=f"gripper_{gripper}", position=float(position),
                          max_effort=float(max_effort))


# -- keypoints ----------------------------------------------------------------------------
def keypoints_to_msg(keypoints: Mapping[str, Sequence[float]], stamp_ns: int,
                     vertex_ids: Mapping[str, int] | None = None, frame_id: str = TABLE_FRAME,
                     folds: Sequence[str] | None = None) -> Keypoints:
    """folds: the folds the keypoints follow, in order ([] = flat; None = not tracked)."""
    names = list(keypoints)
    ids = [int(vertex_ids[n]) if vertex_ids and n in vertex_ids else -1 for n in names]
    return Keypoints(header=header(stamp_ns, frame_id), names=names,
                     points=[point_to_msg(keypoints[n]) for n in names], vertex_ids=ids,
                     folds_known=folds is not None, folds=list(folds or []))


def fold_names(known: bool, folds: list[str], what: str, field_name: str) -> list[str] | None:
    """A message's list of fold names (None when `known` is false); ValueError on an unknown or
    repeated name, or names listed while `known` is false."""
    if not known:
        if folds:
            raise ValueError(f"{what} lists {field_name} {folds} but folds_known is false")
        return None
    unknown = [f for f in folds if f not in FOLD_NAMES]
    if unknown:
        raise ValueError(f"{what} lists unknown folds {unknown} in {field_name}; known folds: {', '.join(FOLD_NAMES)}")
    if len(set(folds)) != len(folds):
        raise ValueError(f"{what} lists a fold twice in {field_name}: {folds}")
    return folds


def keypoint_folds_from_msg(m: Keypoints) -> list[str] | None:
    """The folds a Keypoints message says its keypoints follow (None: not tracked); ValueError
    on an unknown or repeated fold name."""
    return fold_names(m.folds_known, list(m.folds), "keypoints message", "folds")


def check_table_frame(header, what: str) -> None:
    """ValueError unless `header.frame_id` is the table frame (or empty: taken as the table's);
    there is no tf here to transform anything else."""
    if header.frame_id not in ("", TABLE_FRAME):
        raise ValueError(f"{what} frame is {header.frame_id!r}; expected {TABLE_FRAME!r} (no tf here)")


def keypoints_from_msg(m: Keypoints) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """(name -> (3,) m, name -> vertex id (-1 = none)); ValueError on a frame other than the
    table frame, NaN, duplicates or mismatched array lengths."""
    check_table_frame(m.header, "keypoints")
    names = list(m.names)
    if not names:
        raise ValueError("keypoints message has no keypoints")
    if len(m.points) != len(names):
        raise ValueError(f"keypoints message has {len(names)} names but {len(m.points)} points")
    if len(m.vertex_ids) not in (0, len(names)):
        raise ValueError(f"keypoints message has {len(names)} names but {len(m.vertex_ids)} vertex ids")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"keypoints message has duplicate names: {', '.join(dup)}")
    pts = {n: point_from_msg(p, f"keypoint {n!r}") for n, p in zip(names, m.points)}
    ids = {n: int(i) for n, i in zip(names, m.vertex_ids)} if len(m.vertex_ids) else {n: -1 for n in names}
    return pts, ids


# -- fold specification ----------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PlannedFold(FoldPlan):
    """A FoldSpec message in core types: the core FoldPlan (checked when built) and its stamp
    (for /fold/active: when the motion starts)."""

    stamp_ns: int = 0
    extra: dict = field(default_factory=dict)
    folds_done: tuple[str, ...] | None = None  # the folds the plan assumes made before it (None: not given)


def fold_spec_to_msg(fold: PlannedFold, frame_id: str = TABLE_FRAME) -> FoldSpecMsg:
    s = fold.spec
    return FoldSpecMsg(
        header=header(fold.stamp_ns, frame_id), fold_name=s.name, stage=int(fold.stage),
        line_point=point_to_msg(s.line_point), line_direction=vector_to_msg(s.line_direction),
        start_poses=[pose_to_msg(p) for p in s.start_poses], end_poses=[pose_to_msg(p) for p in s.end_poses],
        tilt_signs=[float(x) for x in s.tilt_signs], height_ratio=float(fold.height_ratio),
        tilt_deg=float(fold.tilt_deg), duration=float(fold.duration), settle_time=float(fold.settle_time),
        layer_offset_factor=float(s.layer_offset_factor), folds_known=fold.folds_done is not None,
        folds_done=list(fold.folds_done or ()))


def fold_spec_from_msg(m: FoldSpecMsg) -> PlannedFold:
    """PlannedFold from clothfold_msgs/FoldSpec; ValueError on NaN, inconsistent arrays or a plan
    that is not valid (FoldPlan's checks)."""
    check_table_frame(m.header, "fold spec")
    if not m.fold_name:
        raise ValueError("fold spec has no fold_name")
    scalars = {"height_ratio": m.height_ratio, "tilt_deg": m.tilt_deg, "duration": m.duration,
               "settle_time": m.settle_time, "layer_offset_factor": m.layer_offset_factor}
    for k, v in scalars.items():
        if not math.isfinite(v):
            raise ValueError(f"fold spec {k} is not finite: {v}")
    for k, (lo, hi) in (("duration", limits.DURATION_RANGE), ("settle_time", limits.SETTLE_RANGE)):
        if not lo <= scalars[k] <= hi:
            raise ValueError(f"fold spec {k} = {scalars[k]:g} s is outside [{lo:g}, {hi:g}] s")
    starts = tuple(pose_from_msg(p, f"start pose {i}") for i, p in enumerate(m.start_poses))
    ends = tuple(pose_from_msg(p, f"end pose {i}") for i, p in enumerate(m.end_poses))
    signs = _finite(list(m.tilt_signs), "tilt_signs")
    spec = FoldSpec(m.fold_name, point_from_msg(m.line_point, "fold line point"),
                    point_from_msg(m.line_direction, "fold line direction"), starts, ends, tuple(signs.tolist()),
                    float(m.layer_offset_factor))
    done = fold_names(m.folds_known, list(m.folds_done), "fold spec", "folds_done")
    if done is not None and m.fold_name in done:
        raise ValueError(f"fold spec {m.fold_name!r} lists itself among the folds made before it: {done}")
    return PlannedFold(spec, float(m.height_ratio), float(m.tilt_deg), float(m.duration), float(m.settle_time),
                       int(m.stage), stamp_ns(m.header, "fold spec"),
                       folds_done=None if done is None else tuple(done))


# -- cloth mesh ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class ClothStateData:
    """ClothState in core types: vertices (N, 3) m, triangles (M, 3), keypoint ids."""

    vertices: np.ndarray
    triangles: np.ndarray
    keypoint_ids: dict[str, int]
    thickness: float
    grasped_vertex_ids: np.ndarray
    stamp_ns: int = 0

    def keypoints(self) -> dict[str, np.ndarray]:
        return {n: self.vertices[i].copy() for n, i in self.keypoint_ids.items()}


def cloth_state_to_msg(vertices: np.ndarray, triangles: np.ndarray, keypoint_ids: Mapping[str, int],
                       thickness: float, stamp_ns: int, grasped: Sequence[int] = (),
                       frame_id: str = TABLE_FRAME) -> ClothState:
    v = np.asarray(vertices, dtype=float)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (N, 3), got {v.shape}")
    m = ClothState(header=header(stamp_ns, frame_id), thickness=float(thickness))
    m.positions = v.astype(np.float32).ravel()
    m.triangles = np.asarray(triangles, dtype=np.uint32).ravel()
    m.keypoint_names = list(keypoint_ids)
    m.keypoint_vertex_ids = np.asarray(list(keypoint_ids.values()), dtype=np.uint32)
    m.grasped_vertex_ids = np.asarray(grasped, dtype=np.uint32).ravel()
    return m


def cloth_state_from_msg(m: ClothState) -> ClothStateData:
    """ClothStateData from a ClothState; ValueError on NaN, bad lengths or ids out of range."""
    check_table_frame(m.header, "cloth state")
    pos = np.asarray(m.positions, dtype=float)
    if pos.size == 0 or pos.size % 3:
        raise ValueError(f"cloth state has {pos.size} position values (need a positive multiple of 3)")
    v = pos.reshape(-1, 3)
    bad = ~np.all(np.isfinite(v), axis=1)
    if bad.any():
        raise ValueError(f"cloth state has {int(bad.sum())} non-finite vertices (first: {int(np.argmax(bad))})")
    tri = np.asarray(m.triangles, dtype=np.int64)
    if tri.size % 3:
        raise ValueError(f"cloth state has {tri.size} triangle indices (need a multiple of 3)")
    if tri.size and tri.max() >= len(v):
        raise ValueError(f"cloth state triangle index {int(tri.max())} out of range ({len(v)} vertices)")
    names = list(m.keypoint_names)
    ids = np.asarray(m.keypoint_vertex_ids, dtype=np.int64)
    if len(ids) != len(names):
        raise ValueError(f"cloth state has {len(names)} keypoint names but {len(ids)} keypoint vertex ids")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"cloth state has duplicate keypoint names: {', '.join(dup)}")
    if len(ids) and ids.max() >= len(v):
        raise ValueError(f"cloth state keypoint vertex id {int(ids.max())} out of range ({len(v)} vertices)")
    if not math.isfinite(m.thickness) or m.thickness < 0:
        raise ValueError(f"cloth state thickness must be finite and >= 0, got {m.thickness}")
    grasped = np.asarray(m.grasped_vertex_ids, dtype=np.int64)
    return ClothStateData(v, tri.reshape(-1, 3), dict(zip(names, ids.tolist())), float(m.thickness), grasped,
                          stamp_ns(m.header, "cloth state"))


def mesh_marker(vertices: np.ndarray, triangles: np.ndarray, stamp_ns: int, frame_id: str = TABLE_FRAME,
                ns: str = "cloth", rgba: Sequence[float] = (0.2, 0.5, 0.9, 1.0)) -> Marker:
    """visualization_msgs/Marker TRIANGLE_LIST of the mesh (3 points per triangle)."""
    v = np.asarray(vertices, dtype=float)
    tri = np.asarray(triangles, dtype=np.int64)
    r, g, b, a = (float(c) for c in rgba)
    m = Marker(header=header(stamp_ns, frame_id), ns=ns, id=0, type=Marker.TRIANGLE_LIST, action=Marker.ADD,
               color=ColorRGBA(r=r, g=g, b=b, a=a))
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = 1.0
    m.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in v[tri.ravel()].tolist()]
    return m


def mesh_points(vertices: np.ndarray, stamp_ns: int, frame_id: str = TABLE_FRAME,
                rgb: np.ndarray | None = None) -> PointCloud2:
    """sensor_msgs/PointCloud2 with float32 x, y, z per vertex (dense, little endian); with
    `rgb` ((N, 3), 0-255) also PCL's packed colour, a FLOAT32 field `rgb` holding 0x00RRGGBB."""
    v = np.ascontiguousarray(np.asarray(vertices, dtype=np.float32).reshape(-1, 3))
    fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, n in enumerate("xyz")]
    if rgb is None:
        return PointCloud2(header=header(stamp_ns, frame_id), height=1, width=len(v), fields=fields,
                           is_bigendian=False, point_step=12, row_step=12 * len(v), data=v.tobytes(), is_dense=True)
    from ..perception.colour import pack_rgb

    packed = pack_rgb(np.asarray(rgb).reshape(-1, 3))
    if len(packed) != len(v):
        raise ValueError(f"{len(packed)} colours for {len(v)} points")
    rec = np.empty(len(v), dtype=[("xyz", "<f4", 3), ("rgb", "<u4")])
    rec["xyz"], rec["rgb"] = v, packed
    fields.append(PointField(name="rgb", offset=12, datatype=PointField.FLOAT32, count=1))
    return PointCloud2(header=header(stamp_ns, frame_id), height=1, width=len(v), fields=fields,
                       is_bigendian=False, point_step=16, row_step=16 * len(v), data=rec.tobytes(), is_dense=True)
