"""Core configuration dataclasses as ROS parameters, one parameter per field.

Defaults live in the dataclass; YAML files and `--ros-args -p` only override them. Nested dataclass
fields become dotted names (`leg.tick_hz`). The field's line in the class docstring's `Attributes:`
section becomes the parameter's description (`ros2 param describe`). An override naming no declared
parameter is refused (`refuse_undeclared_overrides`), not ignored.
"""

from __future__ import annotations

import dataclasses
import difflib
import enum
import json
import re
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, TypeVar

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException
from rclpy.node import Node
from rclpy.publisher import Publisher
from std_msgs.msg import String

from g2p.validation import ConfigError
from g2p_ros.contract import qos

# The latched `~/config` topic: late subscribers (the recorder) still get the one message.
CONFIG_QOS = qos(1, latched=True)

T = TypeVar("T")

# An executable's exit status for a parameter it cannot use.
INVALID_PARAMETER_EXIT = 2
# rclpy's own parameters, which it declares on every node.
RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")


def report_invalid_parameter(program: str, err: ConfigError) -> int:
    """Print `program: invalid parameter <what and why>` to stderr; returns the exit status (2)."""
    print(f"{program}: invalid parameter {err}", file=sys.stderr)
    return INVALID_PARAMETER_EXIT


def declare_config(node: Node, cls: type[T], prefix: str = "", exclude: tuple[str, ...] = ()) -> T:
    """Declare one read-only parameter per field of the dataclass `cls` and build it from their values.

    Args:
        node: the node to declare the parameters on.
        cls: a dataclass whose fields all have defaults.
        prefix: prepended to every parameter name (e.g. "leg.").
        exclude: fields left at their defaults and not declared (set by the node from other parameters).

    Raises:
        g2p.validation.ConfigError: a value is invalid or of the wrong type (the message names the field).
    """
    docs = _attribute_docs(cls)
    values: dict[str, Any] = {}
    for f, default in _parameter_fields(cls, exclude):
        name = prefix + f.name
        if dataclasses.is_dataclass(default):
            values[f.name] = declare_config(node, type(default), name + ".")
            continue
        descriptor = ParameterDescriptor(description=docs.get(f.name, ""), read_only=True)
        try:
            node.declare_parameter(name, _to_ros(default), descriptor)
        except InvalidParameterTypeException as err:  # e.g. 0 for a float: ROS does not convert
            hint = " (a float needs its decimal point: 1.0, not 1)" if isinstance(default, float) else ""
            raise ConfigError(f"{name}: wrong type{hint}: {err}") from err
        try:
            values[f.name] = _from_ros(node.get_parameter(name).value, default)
        except ValueError as err:  # e.g. an enum's unknown value
            raise ConfigError(f"{name}: {err}") from err
    try:
        return cls(**values)
    except ConfigError as err:  # the dataclass names its field; the user writes the parameter's name
        raise ConfigError(f"{prefix}{err}") from err


def parameter_names(cls: type, prefix: str = "", exclude: tuple[str, ...] = ()) -> list[str]:
    """The names of the parameters `declare_config(node, cls, prefix, exclude)` declares, without a node."""
    names: list[str] = []
    for f, default in _parameter_fields(cls, exclude):
        if dataclasses.is_dataclass(default):
            names += parameter_names(type(default), prefix + f.name + ".")
        else:
            names.append(prefix + f.name)
    return names


def refuse_undeclared_overrides(node: Node) -> None:
    """Refuse the parameter overrides (`-p`, `--params-file`) that name no parameter `node` declared.

    Nodes do not allow undeclared parameters, so rclpy keeps such an override and ignores it without a
    word: `-p search.treshold_mm:=64.0` would run with the default threshold. Call it once the node has
    declared all its parameters (`g2p_ros.executable.run_node` does, after building the node).

    Raises:
        g2p.validation.ConfigError: the message names each such override, the node and the nearest names
            it declared.
    """
    declared = node.get_parameters_by_prefix("")
    # rclpy has no public accessor for the overrides it was given; Jazzy's and Kilted's keep them here.
    overrides: dict[str, Any] = node._parameter_overrides
    unknown = sorted(name for name in overrides if name not in declared)
    if unknown:
        where = node.get_fully_qualified_name()
        raise ConfigError("; ".join(unknown_parameter(name, where, declared) for name in unknown))


def unknown_parameter(name: str, node: str, known: Iterable[str]) -> str:
    """`<name>: not a parameter of <node> (nearest: <the closest of known>)`, for a name `node` lacks."""
    nearest = difflib.get_close_matches(name, list(known), n=3)
    return f"{name}: not a parameter of {node}" + (f" (nearest: {', '.join(nearest)})" if nearest else "")


def config_as_dict(config: object) -> dict[str, Any]:
    """A configuration dataclass as plain JSON-compatible values, nested dataclasses as dicts."""

    def plain(v: Any) -> Any:
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v)}
        if isinstance(v, enum.Enum):
            return v.value
        if isinstance(v, tuple | list):
            return [plain(x) for x in v]
        if isinstance(v, Path):
            return str(v)
        return v

    return plain(config)  # type: ignore[no-any-return]


def publish_config(node: Node, document: dict[str, Any]) -> Publisher:
    """Publish a node's resolved configuration, once, on its latched `~/config` topic (JSON, sorted keys).

    Every G2P node does this, so that a recorded run holds the settings of every node that produced it.
    Keep the publisher: destroying it ends the latching.
    """
    publisher = node.create_publisher(String, "~/config", CONFIG_QOS)
    publisher.publish(String(data=json.dumps(document, sort_keys=True)))
    return publisher


def _parameter_fields(cls: type, exclude: tuple[str, ...]) -> Iterator[tuple[dataclasses.Field[Any], Any]]:
    """The fields of the dataclass `cls` that become parameters (or sections of them), with their defaults."""
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        if f.init and f.name not in exclude:
            yield f, _default_of(f)


def _default_of(f: dataclasses.Field[Any]) -> Any:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    raise TypeError(f"configuration field {f.name} needs a default to become a ROS parameter")


def _to_ros(value: Any) -> Any:
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, tuple):
        return list(value)
    return value


def _from_ros(value: Any, default: Any) -> Any:
    if isinstance(default, enum.Enum):
        return type(default)(value)
    if isinstance(default, Path):
        return Path(value)
    if isinstance(default, tuple):
        return tuple(value)
    return value


def _attribute_docs(cls: type) -> dict[str, str]:
    """Field descriptions from the Google-style `Attributes:` docstring sections of `cls` and its bases."""
    docs: dict[str, str] = {}
    for base in reversed(cls.__mro__):
        docs.update(_own_attribute_docs(base))
    return docs


def _own_attribute_docs(cls: type) -> dict[str, str]:
    doc = cls.__dict__.get("__doc__") or ""
    section = doc.split("Attributes:", 1)
    if len(section) < 2:
        return {}
    docs: dict[str, str] = {}
    current = None
    for line in section[1].splitlines():
        m = re.match(r"^\s{4,8}(\w+)(?: \(.*?\))?: (.*)$", line)
        if m:
            current = m.group(1)
            docs[current] = m.group(2).strip()
        elif current and line.strip():
            docs[current] += " " + line.strip()
        elif not line.strip() and current:
            current = None
    return docs
