"""The typestore built from installed definitions hashes every type exactly as rosidl did (known answers)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from g2p.bags import InterfaceError, InterfaceLibrary, TypeRegistry, ament_share_dirs


def _rosidl_hashes(package: str) -> dict[str, str]:
    """type name -> RIHS01 hash, from the type description JSON files rosidl generated for `package`."""
    hashes: dict[str, str] = {}
    for share in ament_share_dirs():
        for path in sorted((share / package).glob("*/*.json")):
            for entry in json.loads(path.read_text())["type_hashes"]:
                hashes.setdefault(entry["type_name"], entry["hash_string"])
    return hashes


G2P_HASHES = _rosidl_hashes("g2p_interfaces")
SUPPORTED = sorted(
    t
    for t in G2P_HASHES
    if t.startswith("g2p_interfaces/") and ("/msg/" in t or t.endswith(("_Goal", "_Result", "_Feedback")))
)


def test_rosidl_hashes_found() -> None:
    assert "g2p_interfaces/msg/LearnerEvent" in G2P_HASHES
    assert "g2p_interfaces/action/RunActivations_Result" in G2P_HASHES


@pytest.mark.parametrize("msgtype", SUPPORTED)
def test_hash_equals_rosidl(registry: TypeRegistry, msgtype: str) -> None:
    assert registry.definition(msgtype).rihs01 == G2P_HASHES[msgtype]


@pytest.mark.parametrize(
    "msgtype",
    [
        "sensor_msgs/msg/JointState",
        "rosgraph_msgs/msg/Clock",
        "diagnostic_msgs/msg/DiagnosticArray",
        "std_msgs/msg/String",
        "rcl_interfaces/msg/Log",
    ],
)
def test_hash_of_rig_and_graph_types(registry: TypeRegistry, msgtype: str) -> None:
    pkg = msgtype.split("/")[0]
    assert registry.definition(msgtype).rihs01 == _rosidl_hashes(pkg)[msgtype]


def test_schema_embeds_dependencies(registry: TypeRegistry) -> None:
    msgdef = registry.definition("g2p_interfaces/msg/InverseMapWeights").msgdef
    assert msgdef.startswith("std_msgs/Header header\n")
    assert "\nMSG: g2p_interfaces/NamedArray\n" in msgdef
    assert "\nMSG: builtin_interfaces/Time\n" in msgdef


def test_action_parts_resolve_bare_names(registry: TypeRegistry) -> None:
    msgdef = registry.definition("g2p_interfaces/action/RunActivations_Result").msgdef
    assert msgdef.startswith("g2p_interfaces/RigSamples samples\n")


def test_missing_type_names_the_search_path(tmp_path: Path) -> None:
    registry = TypeRegistry(InterfaceLibrary([tmp_path]))
    with pytest.raises(
        InterfaceError, match=r"no installed definition of nope_msgs/msg/Nope .*" + str(tmp_path)
    ):
        registry.definition("nope_msgs/msg/Nope")


@pytest.mark.parametrize(
    "name",
    [
        "Clock",
        "rosgraph_msgs/Clock",
        "g2p_interfaces/action/RunActivations",
        "g2p_interfaces/action/RunActivations_FeedbackMessage",
    ],
)
def test_unsupported_names_are_rejected(registry: TypeRegistry, name: str) -> None:
    with pytest.raises(InterfaceError):
        registry.definition(name)


def test_share_dirs_from_prefix_path() -> None:
    assert ament_share_dirs("/a:/b/c:") == [Path("/a/share"), Path("/b/c/share")]
