"""Node parameters declared from one table: descriptor (description, range) for ``ros2 param
describe``, and the same check at start-up and on ``ros2 param set``, with a message naming the
parameter and the allowed range.

Numbers accept ints where floats are meant (``-p publish_rate:=500`` just works).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NoReturn, TypeVar

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)

from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException

from ..physics.errors import ImpactArmError

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    from ..physics.scene import Scene


class ParameterError(ImpactArmError, ValueError):
    """A parameter value outside what the node accepts."""


@dataclass(frozen=True)
class Param:
    name: str
    default: object
    description: str
    kind: str = 'float'
    low: float | None = None  # inclusive bounds
    high: float | None = None
    choices: tuple[str, ...] = ()
    size: int | None = None  # arrays: required length (None: any, >= 1)
    read_only: bool = False  # start-up only (changing it needs a restart)
    open_low: bool = False  # low bound excluded (e.g. rates > 0)
    # for the generated tables of docs/*.md (param_docs.py), not for ``ros2 param describe``:
    doc: str = ''  # what the documentation says beyond the description (markdown)
    shown_default: str = ''  # the default in words, where the scene or the time sets it
    # a 'str' parameter naming a member of this TextEnum: read as the member (its text on
    # the wire and in files), so the node compares members, never text
    enum: type | None = None

    def allowed(self) -> str:
        if self.choices:
            return 'one of ' + ', '.join(repr(c) for c in self.choices)
        if self.low is not None and self.high is not None:
            return f'{"(" if self.open_low else "["}{self.low:g}, {self.high:g}]'
        if self.low is not None:
            return f'{">" if self.open_low else ">="} {self.low:g}'
        if self.high is not None:
            return f'<= {self.high:g}'
        return {
            'floats': 'a list of numbers',
            'strs': 'a list of strings',
            'str': 'a string',
            'bool': 'true or false',
            'int': 'an integer',
            'float': 'a number',
        }[self.kind]

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(
            description=f'{self.description} (allowed: {self.allowed()})',
            read_only=self.read_only,
            dynamic_typing=True,
        )
        if self.kind == 'float' and self.low is not None and self.high is not None:
            d.floating_point_range = [
                FloatingPointRange(from_value=float(self.low), to_value=float(self.high))
            ]
        elif self.kind == 'int' and self.low is not None and self.high is not None:
            d.integer_range = [IntegerRange(from_value=int(self.low), to_value=int(self.high))]
        return d

    def check(self, value: Any) -> Any:
        """The value converted to the parameter's type, or ParameterError."""

        def fail(why: str) -> NoReturn:
            raise ParameterError(
                f'parameter {self.name} = {value!r}: {why}; allowed: {self.allowed()}'
            )

        if self.kind in ('float', 'int'):
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                fail('not a number')
            if self.kind == 'int' and not float(value).is_integer():
                fail('not an integer')
            number = float(value) if self.kind == 'float' else int(value)
            unbounded = (number == math.inf and self.high == math.inf) or (
                number == -math.inf and self.low == -math.inf
            )
            if not math.isfinite(number) and not unbounded:
                fail('not finite')
            self._range(number, fail)
            return number
        if self.kind == 'floats':
            if isinstance(value, (str, bytes)) or not hasattr(value, '__len__'):
                fail('not a list of numbers')
            if any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value):
                fail('not a list of numbers')
            out = [float(v) for v in value]
            if self.size is not None and len(out) != self.size:
                fail(f'needs {self.size} values')
            if not out:
                fail('empty')
            if any(math.isnan(v) for v in out):
                fail('NaN')
            for v in out:
                self._range(v, fail)
            return out
        if self.kind == 'strs':
            if isinstance(value, str) or not all(isinstance(v, str) for v in value):
                fail('not a list of strings')
            out = list(value)
            if self.size is not None and len(out) != self.size:
                fail(f'needs {self.size} values')
            return out
        if self.kind == 'bool':
            if not isinstance(value, bool):
                fail('not true/false')
            return value
        if not isinstance(value, str):
            fail('not a string')
        if self.choices and value not in self.choices:
            fail('unknown value')
        return self.enum(value) if self.enum is not None else value

    def _range(self, number: float, fail: Callable[[str], NoReturn]) -> None:
        if self.low is not None and (number < self.low or (self.open_low and number == self.low)):
            fail('out of range')
        if self.high is not None and number > self.high:
            fail('out of range')


def scene_joint_names(scene: Scene) -> list[str]:
    """The joint names of ``scene``'s arm, base first (``Scene.joint_names``: a URDF arm's
    own, else joint1..N): every node names the joints by this one function."""
    return list(scene.joint_names)


def check_joints(
    given: Sequence[str], names: Sequence[str], parameter: str = 'joints'
) -> list[int]:
    """The one joint check of every node: ``given`` (a node's joint order parameter) must
    name each of ``names`` (the scene's joints) exactly once. Returns, for each position of
    ``given``, the index of that joint in ``names``; ParameterError naming the parameter."""
    if sorted(given) != sorted(names):
        raise ParameterError(
            f"parameter {parameter} = {list(given)}: must name each of the scene's "
            f'{len(names)} joints {list(names)} once (the order of the command array)'
        )
    return [list(names).index(j) for j in given]


def startup_scene(node: Node, default: str = 'paper') -> tuple[str, Scene]:
    """(path, scene) of the node's ``scene`` parameter as given at start-up (declared from
    the command line or parameter file by ``NODE_OPTIONS``), before the node's table is
    declared: the scene sets defaults of the table (joint names, gains). Empty: ``default``."""
    from ..physics.scene import load_scene, resolve_scene_path

    name = node.get_parameter('scene').value if node.has_parameter('scene') else ''
    if name is not None and not isinstance(name, str):
        raise ParameterError(f'parameter scene = {name!r}: not a string; allowed: a str')
    name = name or default
    path = resolve_scene_path(name)
    return path, load_scene(path)


# Node options of a node whose parameters ``declare`` and ``refuse_unknown`` handle: every
# value given at start-up (command line, parameter file) arrives as a parameter, so both can
# see what was given through rclpy's public API.
NODE_OPTIONS: dict[str, Any] = dict(automatically_declare_parameters_from_overrides=True)


_Values = TypeVar('_Values')


def declare(node: Node, table: Sequence[Param], cls: Callable[..., _Values]) -> _Values:
    """Declare every parameter of ``table`` on a node made with ``NODE_OPTIONS``; returns
    the checked values as ``cls``, the node's class of param_types.py (one field per
    parameter, read as ``p.publish_rate``; a change makes a new one with ``p.replace``).
    Raises ParameterError for the first bad value, naming it and its range."""
    values: dict[str, object] = {}
    for p in table:
        default = list(p.default) if isinstance(p.default, tuple) else p.default
        given = None
        if node.has_parameter(p.name):
            # declared from the start-up value without our descriptor: declare it again
            # with the descriptor (rclpy then takes the start-up value again)
            given = node.get_parameter(p.name).value
            node.undeclare_parameter(p.name)
        try:
            value: object = node.declare_parameter(p.name, default, p.descriptor()).value
        except (InvalidParameterValueException, InvalidParameterTypeException) as exc:
            # rclpy checks the descriptor's range itself; say it the way the rest of us do
            shown = given if given is not None else '?'
            raise ParameterError(
                f'parameter {p.name} = {shown!r}: out of range; allowed: {p.allowed()}'
            ) from exc
        values[p.name] = p.check(value)
    return cls(**values)


def validator(
    table: Sequence[Param], apply: Callable[[dict[str, Any]], None]
) -> Callable[[list[Parameter]], SetParametersResult]:
    """An on-set-parameters callback: refuse bad or read-only values (with the reason ``ros2
    param set`` prints), else pass the checked values to ``apply(dict)``."""
    by_name = {p.name: p for p in table}

    def callback(parameters: list[Parameter]) -> SetParametersResult:
        checked: dict[str, Any] = {}
        for param in parameters:
            if not param.name.strip():
                # rclpy would store it as an undeclared parameter nobody can read back
                return SetParametersResult(
                    successful=False, reason='a parameter name must not be empty'
                )
            spec = by_name.get(param.name)
            if spec is None:
                continue
            if spec.read_only:
                return SetParametersResult(
                    successful=False, reason=f'{param.name} is fixed at start-up'
                )
            try:
                checked[param.name] = spec.check(param.value)
            except ParameterError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        if checked:
            try:
                apply(checked)
            except ParameterError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    return callback


def refuse_unknown(node: Node, table: Sequence[Param]) -> None:
    """ROS ignores parameters a node never declares; a typo in a parameter file or on the
    command line would then silently change nothing. Refuse them instead (``node`` made with
    ``NODE_OPTIONS``, ``table`` declared)."""
    declared = set(node.get_parameters_by_prefix(''))
    known_names = {p.name for p in table} | _declared_by_ros(node.context)
    unknown = sorted(declared - known_names)
    if unknown:
        known = ', '.join(sorted(known_names))
        raise ParameterError(
            f'unknown parameter(s) {", ".join(unknown)} for node {node.get_name()}; known: {known}'
        )


def _declared_by_ros(context: Context) -> set[str]:
    """The parameters rclpy declares on every node (use_sim_time, ...): those of a bare node."""
    from rclpy.node import Node

    # not renamed by a global __node remap (launch gives one), so it never shares a name
    bare = Node(
        '_impact_arm_parameter_probe',
        context=context,
        start_parameter_services=False,
        enable_rosout=False,
        use_global_arguments=False,
    )
    try:
        return set(bare.get_parameters_by_prefix(''))
    finally:
        bare.destroy_node()
