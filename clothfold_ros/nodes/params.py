"""Typed, range-checked ROS parameters for the clothfold nodes.

Each node lists its parameters as `Param`s; `declare()` declares them with a
ParameterDescriptor (FloatingPointRange / IntegerRange, read-only flag, description) and
installs a set-parameters callback that refuses bad values with a clear reason (range,
choices, finiteness, array length, cross checks). Values from a `--params-file` go through
the same checks at start-up: a bad file stops the node with the reason. A whole number given
at start-up for a double parameter (`lookahead:=0`) is taken as that double.
"""
from __future__ import annotations

import array
import math
from dataclasses import dataclass
from typing import Any, Callable, Sequence

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

Value = bool | int | float | str | list


@dataclass(frozen=True)
class Param:
    """One parameter: default (its type fixes the parameter type), description with units,
    optional inclusive range, choices for strings, fixed array length, read-only flag."""

    name: str
    default: Value
    description: str
    range: tuple[float, float] | None = None
    choices: tuple[str, ...] | None = None
    length: int | None = None  # for double arrays
    read_only: bool = False

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(name=self.name, description=self.description, read_only=self.read_only)
        if self.choices:
            d.additional_constraints = "one of: " + ", ".join(self.choices)
        if self.range is not None:
            lo, hi = self.range
            if isinstance(self.default, bool):
                pass
            elif isinstance(self.default, int):
                d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
            elif isinstance(self.default, float):
                d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
            else:
                d.additional_constraints = f"each element in [{lo}, {hi}]"
        return d

    def check(self, value: Any) -> str | None:
        """Reason the value is refused, or None if it is acceptable."""
        if isinstance(self.default, bool):
            return None if isinstance(value, bool) else f"{self.name} must be a bool, got {value!r}"
        if isinstance(self.default, (int, float)):
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                return f"{self.name} must be a number, got {value!r}"
            if not math.isfinite(value):
                return f"{self.name} must be finite, got {value}"
            if isinstance(self.default, int) and not isinstance(value, int):
                return f"{self.name} must be an integer, got {value!r}"
            return self._in_range(value)
        if isinstance(self.default, str):
            if self.choices and value not in self.choices:
                return f"{self.name} must be one of {', '.join(self.choices)}; got {value!r}"
            return None
        values = list(value)
        if self.length is not None and len(values) != self.length:
            return f"{self.name} must have {self.length} elements, got {len(values)}"
        for v in values:
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                return f"{self.name} elements must be finite numbers, got {values}"
            reason = self._in_range(v)
            if reason:
                return reason
        return None

    def _in_range(self, value: float) -> str | None:
        if self.range is None:
            return None
        lo, hi = self.range
        if not lo <= value <= hi:
            return f"{self.name} = {value} is out of range [{lo}, {hi}] ({self.description})"
        return None


CrossCheck = Callable[[dict[str, Value], Sequence[str]], str | None]
# set on every node by rclpy or the ROS tooling, never reported as unknown
STANDARD = ("use_sim_time", "start_type_description_service")


def declare(node: Node, params: Sequence[Param], cross_check: CrossCheck | None = None) -> list[str]:
    """Declare `params` on `node` and refuse bad values (now and on every later set).

    cross_check(values, changed) sees all values after a change of the names in `changed`
    and returns a reason to refuse it (e.g. workspace min < max). Raises rclpy's
    InvalidParameterValueException (or ValueError for a cross check) at start-up.
    Parameters given to the node (params file, -p) that it does not declare - usually a
    misspelt name - are logged as a warning with the known names; returns them.
    """
    by_name = {p.name: p for p in params}
    declaring = [True]  # the cross check runs once everything is declared (see below)

    def on_set(changes: list[Parameter]) -> SetParametersResult:
        values = {n: node.get_parameter(n).value for n in by_name if node.has_parameter(n)}
        for change in changes:
            p = by_name.get(change.name)
            if p is None:
                continue
            reason = p.check(change.value)
            if reason:
                node.get_logger().error(f"parameter refused: {reason}")
                return SetParametersResult(successful=False, reason=reason)
            values[change.name] = change.value
        if cross_check and not declaring[0] and all(n in values for n in by_name):
            reason = cross_check(values, [c.name for c in changes])
            if reason:
                node.get_logger().error(f"parameter refused: {reason}")
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)
    _integers_as_doubles(node, params)
    node.declare_parameters("", [(p.name, p.default, p.descriptor()) for p in params])
    declaring[0] = False
    if cross_check:
        given = [n for n in by_name if n in (getattr(node, "_parameter_overrides", {}) or {})]
        reason = cross_check({p.name: node.get_parameter(p.name).value for p in params}, given)
        if reason:
            raise ValueError(f"bad parameters: {reason}")
    unknown = unknown_overrides(node)
    for name in unknown:
        node.get_logger().warning(f"unknown parameter {name!r} ignored (misspelt?); {node.get_name()} declares: "
                                  f"{', '.join(sorted(n for n in by_name))}")
    return unknown


def _integers_as_doubles(node: Node, params: Sequence[Param]) -> None:
    """Take a whole number given for a double parameter (`-p lookahead:=0`, `lookahead: 0` in a
    params file, `[0, 0, 1, 1, 0, 0, 0]` for a double array) as that double: rclpy would refuse
    it as an INTEGER and stop the node. Mixed lists (`[0, 0.5]`) are refused by rcl's parser
    before the node starts; write `0.0` there."""
    overrides = getattr(node, "_parameter_overrides", None)
    if not overrides:
        return
    for p in params:
        given = overrides.get(p.name)
        if given is None or isinstance(p.default, bool):
            continue
        if isinstance(p.default, float) and given.type_ == Parameter.Type.INTEGER:
            overrides[p.name] = Parameter(p.name, Parameter.Type.DOUBLE, float(given.value))
        elif isinstance(p.default, list) and p.default and all(isinstance(v, float) for v in p.default) \
                and given.type_ == Parameter.Type.INTEGER_ARRAY:
            overrides[p.name] = Parameter(p.name, Parameter.Type.DOUBLE_ARRAY, [float(v) for v in given.value])


def unknown_overrides(node: Node) -> list[str]:
    """Names given to the node (params file, -p) that it has not declared."""
    overrides = getattr(node, "_parameter_overrides", {}) or {}
    return sorted(n for n in overrides if not node.has_parameter(n) and n not in STANDARD
                  and not n.startswith("qos_overrides."))


def value(node: Node, name: str) -> Any:
    """Current value of a declared parameter (double arrays as lists)."""
    v = node.get_parameter(name).value
    return list(v) if isinstance(v, (list, tuple, array.array)) else v


# -- parameters shared by several nodes ----------------------------------------------------
SHAPE = Param("shape", 1, "shirt shape preset of docs/method.md section 1 (1, 2 or 3)", range=(1, 3), read_only=True)
MATERIAL = Param("material", "cotton", "cloth material preset", read_only=True,
                 choices=("cotton", "wool", "polyester", "thin_cotton", "thick_cotton"))
N_GRIPPERS = Param("n_grippers", 2, "number of grippers (topics /gripper_<i>/...)", range=(1, 2), read_only=True)
REAL_TIME_FACTOR = Param("real_time_factor", 1.0, "sim seconds per wall second while idle (upper bound in "
                         "lock-step)", range=(0.01, 100.0))
