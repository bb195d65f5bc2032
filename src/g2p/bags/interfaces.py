"""Message types for bags, built from the interface definitions installed in ament share directories.

The rosbags typestore that writes schemas and RIHS01 type hashes is filled from the same `.msg` and
`.action` files rosidl generated the ROS types from (`<prefix>/share/<package>/msg/<Name>.msg`), so the
schemas embedded in a bag and their hashes equal what the publishers use.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosbags.interfaces import Nodetype
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from g2p.bags.errors import InterfaceError

# The parts of an .action file, in file order, and the message type each becomes.
ACTION_PARTS = ("Goal", "Result", "Feedback")
_PRIMITIVES = frozenset(
    {
        "bool",
        "byte",
        "char",
        "float32",
        "float64",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "string",
        "wstring",
    }
)
_TYPENAME = re.compile(r"^(?P<pkg>[a-z][a-z0-9_]*)/(?P<kind>msg|action)/(?P<name>[A-Za-z][A-Za-z0-9_]*)$")


def ament_share_dirs(ament_prefix_path: str | None = None) -> list[Path]:
    """The `share` directories of an AMENT_PREFIX_PATH value, in search order.

    Args:
        ament_prefix_path: prefixes separated by os.pathsep; None reads the AMENT_PREFIX_PATH variable.
    """
    value = os.environ.get("AMENT_PREFIX_PATH", "") if ament_prefix_path is None else ament_prefix_path
    return [Path(prefix) / "share" for prefix in value.split(os.pathsep) if prefix]


@dataclass(frozen=True)
class TypeDefinition:
    """What a bag stores about a message type.

    Attributes:
        msgtype: the type name, "package/msg/Name".
        msgdef: the ros2msg schema text: the type's definition, then each dependency after a
            separator line and "MSG: package/Name".
        rihs01: the RIHS01 type description hash, "RIHS01_<64 hex digits>".
    """

    msgtype: str
    msgdef: str
    rihs01: str


class InterfaceLibrary:
    """The message and action definitions installed under some share directories.

    Args:
        share_dirs: directories holding `<package>/msg/*.msg` and `<package>/action/*.action`, searched in
            order (the first match wins, like the ament index).
    """

    def __init__(self, share_dirs: Sequence[Path]) -> None:
        self._share_dirs = [Path(d) for d in share_dirs]

    def definition_text(self, msgtype: str) -> str:
        """The message definition of `msgtype`, with bare type names qualified for action parts.

        Args:
            msgtype: "package/msg/Name", or "package/action/Name_Goal" (also _Result, _Feedback).

        Raises:
            InterfaceError: the name is malformed, or no installed file defines it.
        """
        match = _TYPENAME.match(msgtype)
        if match is None:
            raise InterfaceError(f"not a message type name (package/msg/Name): {msgtype!r}")
        pkg, kind, name = match["pkg"], match["kind"], match["name"]
        if kind == "msg":
            return self._read(pkg, "msg", name + ".msg", msgtype)
        base, _, part = name.rpartition("_")
        if part not in ACTION_PARTS or not base:
            raise InterfaceError(
                f"only the Goal, Result and Feedback messages of an action are supported: {msgtype!r}"
            )
        text = self._read(pkg, "action", base + ".action", msgtype)
        parts = re.split(r"^---[ \t]*$", text, flags=re.MULTILINE)
        if len(parts) != len(ACTION_PARTS):
            raise InterfaceError(f"action definition of {msgtype!r} has {len(parts)} parts, expected 3")
        return _qualify_bare_types(parts[ACTION_PARTS.index(part)], pkg)

    def _read(self, pkg: str, kind: str, filename: str, msgtype: str) -> str:
        for share in self._share_dirs:
            path = share / pkg / kind / filename
            if path.is_file():
                return path.read_text(encoding="utf-8")
        searched = ", ".join(str(d) for d in self._share_dirs) or "(no share directories)"
        raise InterfaceError(f"no installed definition of {msgtype} ({pkg}/{kind}/{filename}) in {searched}")


class TypeRegistry:
    """A rosbags typestore filled on demand from an InterfaceLibrary.

    Args:
        library: where definitions come from.
    """

    def __init__(self, library: InterfaceLibrary) -> None:
        self.library = library
        self.typestore: Typestore = get_typestore(Stores.EMPTY)
        self._registered: set[str] = set()

    def register(self, msgtype: str) -> None:
        """Register `msgtype` and every type it depends on.

        Raises:
            InterfaceError: a definition is missing or cannot be parsed.
        """
        pending, found = [msgtype], {}
        while pending:
            name = pending.pop()
            if name in found or name in self._registered:
                continue
            text = self.library.definition_text(name)
            try:
                types = get_types_from_msg(text, name)
            except Exception as err:  # rosbags raises its own parse errors for malformed definitions
                raise InterfaceError(f"cannot parse the definition of {name}: {err}") from err
            found.update(types)
            for _, fields in types.values():
                pending.extend(_referenced_types(desc for _, desc in fields))
        if found:
            try:
                self.typestore.register(found)
            except Exception as err:  # a type already registered with another definition
                raise InterfaceError(f"cannot register {msgtype}: {err}") from err
            self._registered.update(found)

    def reserialize(self, data: bytes, msgtype: str) -> bytes | None:
        """`data` decoded as one `msgtype` message and serialized again (exact length, zero padding).

        Returns None when `data` is not exactly one such message (the type must be registered).
        """
        try:
            decoded = self.typestore.deserialize_cdr(data, msgtype)
        except SerdeError:
            return None
        return bytes(self.typestore.serialize_cdr(decoded, msgtype))

    def definition(self, msgtype: str) -> TypeDefinition:
        """The schema text and RIHS01 hash of `msgtype`, registering it first if needed.

        Raises:
            InterfaceError: a definition is missing or cannot be parsed.
        """
        self.register(msgtype)
        msgdef, _ = self.typestore.generate_msgdef(msgtype, ros_version=2)
        return TypeDefinition(msgtype, msgdef, self.typestore.hash_rihs01(msgtype))


def _referenced_types(descs: Iterable[Any]) -> list[str]:
    """Names of the message types a list of rosbags field descriptions refers to."""
    names = []
    for desc in descs:
        node, detail = desc
        if node in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            names.extend(_referenced_types([detail[0]]))
        elif node == Nodetype.NAME:
            names.append(str(detail))
    return names


def _qualify_bare_types(text: str, pkg: str) -> str:
    """Prefix bare message type names (`RigSamples x`) with their package, as rosidl resolves them."""
    lines = []
    for line in text.splitlines():
        match = re.match(r"^(\s*)([A-Za-z][A-Za-z0-9_]*)(\s*(?:\[[^\]]*\])?\s+\S.*)$", line)
        if match and not line.lstrip().startswith("#"):
            typ = match[2]
            if typ not in _PRIMITIVES:
                line = f"{match[1]}{pkg}/{typ}{match[3]}"
        lines.append(line)
    return "\n".join(lines) + "\n"
