"""Node parameters with validation: :func:`declare` (a descriptor and its range or choices) and
:func:`add_parameter_check` (a check over several parameters). A bad start-up value makes the
node exit with code 2, a bad ``ros2 param set`` is refused with the reason (docs/ros.md, "Nodes")."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, cast

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

__all__ = ["declare", "add_parameter_check"]

Check = Callable[[Any], str | None]
JointCheck = Callable[[dict[str, Any]], str | None]


class _ParameterChecks:
    """The node's one on-set-parameters callback: per-parameter checks (choices) and joint
    checks over all values. rclpy also calls it while a parameter is declared, so a bad
    start-up value raises InvalidParameterValueException (exit code 2 in :func:`run_node`)."""

    ATTR = "_contgrasp_parameter_checks"

    def __init__(self, node: Node) -> None:
        self._node = node
        self.single: dict[str, Check] = {}
        self.joint: list[JointCheck] = []
        node.add_on_set_parameters_callback(self)

    @classmethod
    def of(cls, node: Node) -> _ParameterChecks:
        checks = getattr(node, cls.ATTR, None)
        if checks is None:
            checks = cls(node)
            setattr(node, cls.ATTR, checks)
        return checks

    def __call__(self, params: list[Parameter]) -> SetParametersResult:
        try:
            for p in params:
                check = self.single.get(p.name)
                reason = check(p.value) if check is not None else None
                if reason:
                    return SetParametersResult(successful=False, reason=f"{p.name}: {reason}")
            if self.joint:
                # (rclpy annotates the values as parameter values; they are Parameter objects)
                current = cast("dict[str, Parameter]", self._node.get_parameters_by_prefix(""))
                values = {name: p.value for name, p in current.items()}
                values.update({p.name: p.value for p in params})
                for joint in self.joint:
                    if reason := joint(values):
                        return SetParametersResult(successful=False, reason=reason)
        except Exception as exc:  # a check must never take the parameter service down
            return SetParametersResult(successful=False, reason=f"internal error checking parameters: {type(exc).__name__}: {exc}")
        return SetParametersResult(successful=True)


def _choice_check(choices: Sequence[str]) -> Check:
    return lambda v: None if v in choices else f"must be one of {', '.join(map(repr, choices))}, got {v!r}"


def declare(
    node: Node,
    name: str,
    default: Any,
    description: str,
    *,
    lo: float | None = None,
    hi: float | None = None,
    read_only: bool = False,
    choices: Sequence[str] | None = None,
) -> Any:
    """Declare a parameter with a descriptor and its validation; return its value.

    The type is fixed by ``default`` (rclpy refuses other types), numbers get the range
    ``[lo, hi]`` (NaN/Inf are out of range) and strings may be restricted to ``choices``
    (checks over several parameters: :func:`add_parameter_check`). rclpy enforces all of it
    both for the start-up value (params file / overrides: the node refuses to start) and for
    ``ros2 param set`` at run time (refused with the reason, the old value stays);
    ``read_only`` parameters cannot be changed at run time at all.
    """
    desc = ParameterDescriptor(description=description, read_only=read_only)
    if lo is not None and hi is not None:
        if isinstance(default, bool):
            pass
        elif isinstance(default, int):
            desc.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
        elif isinstance(default, float):
            desc.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
    if choices:
        desc.additional_constraints = f"one of: {', '.join(choices)}"
        _ParameterChecks.of(node).single[name] = _choice_check(choices)
    return node.declare_parameter(name, default, desc).value


def add_parameter_check(node: Node, check: JointCheck) -> None:
    """Add a check over several parameters: ``check(values)`` gets every declared parameter's
    value with the proposed changes applied and returns the reason to refuse them (or None).
    Register it after the parameters it reads are declared."""
    _ParameterChecks.of(node).joint.append(check)
