# mypy: disallow-untyped-calls=False
# rclpy is only partly annotated: calling its untyped functions is expected here.
"""What both nodes share: QoS profiles, parameter declaration from a table, the entry point.

Parameters are declared from a table of :class:`ParamSpec` rows, each with a
``ParameterDescriptor`` (description, numeric range, read-only flag); ``config/<node>.yaml``
repeats the defaults for ``--params-file`` and a test keeps the two in agreement.

ROS 2 cannot type an empty array: rclpy takes ``[]`` for a byte array and rcl's YAML parser
reads ``[]`` as no value at all. A number-array parameter is therefore declared with dynamic
typing, and :meth:`ParamSpec.problem` (run at start-up and on every ``ros2 param set``)
accepts only numbers, in one of its allowed counts.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import rclpy
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor, ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import try_shutdown

from linelaser_calib.core.errors import CalibrationError
from linelaser_calib.settings import Front, render

#: History of the profile subscription: a backlog this long is absorbed.
INPUT_DEPTH = 1000
#: History of the pose subscriptions (flange poses, joint states, /tf): an arm streams them
#: at up to 500 Hz, so while the collector validates a dense profile (or its machine is
#: busy) hundreds queue up; 1,000 overflowed at a 10x replay of 125 Hz poses on a loaded
#: two-core runner (a reliable keep-last queue drops its oldest message when full). Poses
#: are small: this is about 2 MB at most.
POSE_INPUT_DEPTH = 20000
#: Topics of the collected samples (published by the collector, read by the service).
SAMPLE_PROFILE_TOPIC = "linelaser_calib/samples/profile"
SAMPLE_POSE_TOPIC = "linelaser_calib/samples/flange_pose"
#: The collector's current session directory (std_msgs/String, latched).
SESSION_TOPIC = "linelaser_calib/session"
#: The collector's clock offset (std_msgs/Float64MultiArray, latched): [offset it adds to
#: profile stamps for pairing (s), live estimate (s), its 1 sigma (s), batches, then the rest
#: of its pairing: sync tolerance (s), speed limits (m/s, rad/s), speed window (s)]; NaN where
#: there is no estimate (yet) or fewer than two batches (:mod:`.clock_offset` writes and
#: reads it).
CLOCK_OFFSET_TOPIC = "linelaser_calib/clock_offset"
#: Results of the calibration service.
HAND_EYE_TOPIC = "linelaser_calib/hand_eye"
MARKERS_TOPIC = "linelaser_calib/markers"
#: The service (std_srvs/Trigger) that runs a calibration; relative, so it follows namespaces.
CALIBRATE_SERVICE = "calibrate"


def input_qos(reliable: bool, depth: int = INPUT_DEPTH) -> QoSProfile:
    """QoS of the ``profile`` and ``flange_pose`` subscriptions, keeping the last ``depth``.

    Best effort (the sensor-data profile with a deep history) matches every publisher;
    reliable loses nothing while the backlog stays under ``depth``, but needs a reliable
    publisher.
    """
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.VOLATILE,
    )


def latched_qos(depth: int) -> QoSProfile:
    """Reliable, transient_local, keep-last ``depth``: late joiners get the last ``depth``."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


PARAMETER_TABLE_HEADER = "| name | default | allowed | read | description |\n|---|---|---|---|---|"


def markdown_parameter_table(specs: Sequence[ParamSpec]) -> str:
    """A node's parameters as a Markdown table (the README's parameter reference)."""
    return "\n".join([PARAMETER_TABLE_HEADER, *(spec.markdown_row() for spec in specs)])


@dataclass(frozen=True)
class ParamSpec:
    """One declared parameter.

    Attributes
    ----------
    name : str
    default : bool, int, float, str or tuple of float
        Its type is the parameter's type (write floats as ``0.0`` in YAML); a tuple is a
        number array (``[x, y, z]`` in YAML).
    description : str
        Shown by ``ros2 param describe``; give the unit.
    bounds : (low, high) or None
        Inclusive numeric range, enforced by rclpy.
    choices : tuple of str
        Allowed values of a string parameter.
    read_only : bool
        True when the node uses the value only at start-up.
    sizes : tuple of int
        Allowed element counts of a number array (e.g. ``(0, 3)``: empty or a 3-vector).
    """

    name: str
    default: bool | int | float | str | tuple[float, ...]
    description: str
    bounds: tuple[float, float] | None = None
    choices: tuple[str, ...] = ()
    read_only: bool = False
    sizes: tuple[int, ...] = ()

    @property
    def is_array(self) -> bool:
        """True for a number-array parameter."""
        return isinstance(self.default, tuple)

    def markdown_row(self) -> str:
        """This parameter as a row of the README's parameter tables."""
        default = repr(self.default)
        if isinstance(self.default, tuple):
            default = "[" + ", ".join(str(v) for v in self.default) + "]"
        allowed = ""
        if self.choices:
            allowed = " \\| ".join(f"`{c}`" for c in self.choices)
        elif self.bounds is not None:
            allowed = f"{self.bounds[0]:g} to {self.bounds[1]:g}"
        elif self.sizes:
            allowed = " or ".join(f"{n} numbers" for n in self.sizes)
        when = "start-up" if self.read_only else "any time"
        text = self.description.replace("|", "\\|")
        return f"| `{self.name}` | `{default}` | {allowed} | {when} | {text} |"

    def descriptor(self) -> ParameterDescriptor:
        """The ``ParameterDescriptor`` declared for this parameter."""
        text = self.description
        if self.choices:
            text += f" One of: {', '.join(self.choices)}."
        descriptor = ParameterDescriptor(
            description=text, read_only=self.read_only, dynamic_typing=self.is_array
        )
        if self.bounds is not None and isinstance(self.default, float):
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=self.bounds[0], to_value=self.bounds[1], step=0.0)
            ]
        elif self.bounds is not None and isinstance(self.default, int):
            descriptor.integer_range = [
                IntegerRange(from_value=int(self.bounds[0]), to_value=int(self.bounds[1]), step=1)
            ]
        return descriptor

    def problem(self, value: Any) -> str | None:
        """What is wrong with ``value`` for this parameter, or None when it is acceptable.

        rclpy checks types and ranges itself; this checks string choices and number arrays
        (``None`` is rcl's reading of an empty YAML array).
        """
        if self.choices and value not in self.choices:
            return f"{self.name} is {value!r}; it must be one of {list(self.choices)}"
        if not self.is_array or value is None:
            return None
        numbers = (
            isinstance(value, Sequence)
            and not isinstance(value, str)
            and all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                for v in value
            )
        )
        if numbers and len(value) in self.sizes:
            return None
        shown = list(value) if isinstance(value, Sequence) and not isinstance(value, str) else value
        allowed = " or ".join(
            "[]" if n == 0 else f"an array of {n} finite numbers" for n in self.sizes
        )
        return f"{self.name} is {shown!r}; it must be {allowed}"

    def value(self, raw: Any) -> Any:
        """The value the node uses: a number array as a tuple of float, others unchanged."""
        if not self.is_array:
            return raw
        return () if raw is None else tuple(float(v) for v in raw)


def declare_parameters(node: Node, specs: Sequence[ParamSpec]) -> dict[str, Any]:
    """Declare every parameter, check it (:meth:`ParamSpec.problem`), return the values in effect.

    A later ``ros2 param set`` with a value that :meth:`ParamSpec.problem` refuses is refused.

    Raises
    ------
    CalibrationError
        When a value given at start-up (``--params-file``, ``-p``) is not acceptable.
    """
    for spec in specs:
        default = list(spec.default) if isinstance(spec.default, tuple) else spec.default
        node.declare_parameter(spec.name, default, spec.descriptor())
    by_name = {spec.name: spec for spec in specs}

    def check(parameters: list[Parameter]) -> SetParametersResult:
        for parameter in parameters:
            spec = by_name.get(parameter.name)
            problem = None if spec is None else spec.problem(parameter.value)
            if problem is not None:
                return SetParametersResult(successful=False, reason=problem)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(check)
    for spec in specs:
        problem = spec.problem(node.get_parameter(spec.name).value)
        if problem is not None:
            raise CalibrationError(f"parameter {problem}")
    return parameter_values(node, specs)


def parameter_values(node: Node, specs: Sequence[ParamSpec]) -> dict[str, Any]:
    """Current values of the declared parameters, by name (see :meth:`ParamSpec.value`)."""
    return {spec.name: spec.value(node.get_parameter(spec.name).value) for spec in specs}


def run_node(
    make_node: Callable[[], Node],
    make_executor: Callable[[], Executor],
    args: list[str] | None = None,
) -> int:
    """Entry point body: init, build the node, spin it on its executor, clean up.

    Ctrl-C and external shutdown end the spin quietly. A :class:`CalibrationError` or a
    rejected parameter while the node starts is printed as one line; the exit status is 1.
    """
    rclpy.init(args=args)
    node: Node | None = None
    status = 0
    try:
        node = make_node()
        executor = make_executor()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (CalibrationError, ParameterException) as err:
        print(f"error: {render(str(err), Front.NODE)}", file=sys.stderr)
        status = 1
    finally:
        if node is not None:
            node.destroy_node()
        try_shutdown()
    return status
