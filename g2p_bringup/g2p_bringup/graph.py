"""The node graph's description (config/graph.yaml): which processes, with which parameters and remaps.

One description serves this project's bring-up (`bringup`, which starts each node as a process) and the
launch file for full ROS 2 installs (launch/g2p.launch.py). This module only reads and resolves it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import yaml
from ament_index_python.packages import get_package_share_directory

# The variables naming Fast DDS's XML profiles file: 3.x (Kilted and later) reads the first, 2.x (Jazzy)
# the second. Each reads only its own; setting both makes 3.x load the file twice and reject its profile.
PROFILE_VARIABLES = ("FASTDDS_DEFAULT_PROFILES_FILE", "FASTRTPS_DEFAULT_PROFILES_FILE")


def profile_variable() -> str:
    """The variable the installed Fast DDS reads its profiles file from.

    rmw_fastrtps 9 and later (Kilted on) are built on Fast DDS 3; rmw_fastrtps 8 (Jazzy) on Fast DDS 2.
    """
    package_xml = Path(get_package_share_directory("rmw_fastrtps_cpp")) / "package.xml"
    version = ElementTree.parse(package_xml).getroot().findtext("version", "0")
    return PROFILE_VARIABLES[0] if int(version.split(".")[0]) >= 9 else PROFILE_VARIABLES[1]


def profile_environment(environ: dict[str, str], profile: Path) -> dict[str, str]:
    """The variable to add to `environ` so that the installed Fast DDS loads `profile`.

    Nothing when the user named a profiles file already (in either variable): theirs is used.
    """
    if any(environ.get(name) for name in PROFILE_VARIABLES):
        return {}
    return {profile_variable(): str(profile)}


class GraphError(ValueError):
    """The graph description is invalid; the message names the file and the entry."""


@dataclass(frozen=True)
class NodeSpec:
    """One node of the graph, fully resolved.

    Attributes:
        name: node name (also the key of its parameters).
        package: ROS package of the executable.
        executable: executable name, as in `ros2 run <package> <executable>`.
        namespace: the node's namespace.
        parameters: ROS parameter overrides, name -> value.
        remappings: topic/service/action remappings, from -> to.
        arguments: extra command-line arguments before --ros-args.
        main: the graph ends when this node's process exits.
    """

    name: str
    package: str
    executable: str
    namespace: str
    parameters: dict[str, Any] = field(default_factory=dict)
    remappings: dict[str, str] = field(default_factory=dict)
    arguments: tuple[str, ...] = ()
    main: bool = False

    def parameters_yaml(self) -> str:
        """The node's parameters as a ROS 2 parameters file."""
        fqn = f"{self.namespace.rstrip('/')}/{self.name}"
        return yaml.safe_dump({fqn: {"ros__parameters": self.parameters}}, sort_keys=True)

    def ros_arguments(self, params_file: Path | None) -> list[str]:
        """`--ros-args ...` arguments giving the node its name, namespace, parameters and remaps."""
        args = ["--ros-args", "-r", f"__node:={self.name}", "-r", f"__ns:={self.namespace}"]
        if params_file is not None:
            args += ["--params-file", str(params_file)]
        for src, dst in self.remappings.items():
            args += ["-r", f"{src}:={dst}"]
        return args


@dataclass(frozen=True)
class Graph:
    """A resolved graph: the rig first, then the other nodes in start order.

    Attributes:
        namespace: namespace of every node.
        nodes: the rig, then the other nodes, in start order.
    """

    namespace: str
    nodes: tuple[NodeSpec, ...]

    @property
    def main(self) -> NodeSpec:
        """The node whose exit ends the graph (the last one when none is marked)."""
        return next((n for n in self.nodes if n.main), self.nodes[-1])


def load_graph(
    path: Path,
    rig: str | None = None,
    substitutions: dict[str, str] | None = None,
    overrides: dict[str, dict[str, Any]] | None = None,
) -> Graph:
    """Read a graph description and resolve it.

    Args:
        path: the YAML description.
        rig: which entry of `rigs` to use; the first when None.
        substitutions: values for `{name}` placeholders in string parameters and remappings.
        overrides: extra parameters per node name ("rig" addresses the rig), applied last.

    Raises:
        GraphError: the file is unreadable or invalid, the rig is unknown, or a placeholder has no value.
    """
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise GraphError(f"{path}: cannot read the graph description: {err}") from err
    if not isinstance(doc, dict) or not isinstance(doc.get("rigs"), dict) or not doc["rigs"]:
        raise GraphError(f"{path}: needs a 'rigs' mapping with at least one rig")
    namespace = str(doc.get("namespace", "/"))
    rig_name = rig or next(iter(doc["rigs"]))
    if rig_name not in doc["rigs"]:
        raise GraphError(f"{path}: unknown rig {rig_name!r}; choose one of {sorted(doc['rigs'])}")
    subs = substitutions or {}
    extra = overrides or {}
    rig_entry = doc["rigs"][rig_name]
    sim_time = bool(rig_entry.get("use_sim_time", False))
    entries = [("rig", {"name": rig_entry.get("name", rig_entry.get("executable")), **rig_entry})]
    entries += [(str(e.get("name")), e) for e in doc.get("nodes", [])]
    nodes = []
    for key, entry in entries:
        where = f"{path}: node {key!r}"
        try:
            params = {k: _substitute(v, subs, where) for k, v in (entry.get("parameters") or {}).items()}
            if key != "rig":  # the rig is the clock's source and must not subscribe to /clock itself
                params["use_sim_time"] = sim_time
            params.update(extra.get(key, {}))
            nodes.append(
                NodeSpec(
                    name=str(entry["name"]),
                    package=str(entry["package"]),
                    executable=str(entry["executable"]),
                    namespace=namespace,
                    parameters=params,
                    remappings={
                        str(k): str(_substitute(v, subs, where))
                        for k, v in (entry.get("remappings") or {}).items()
                    },
                    arguments=tuple(str(a) for a in entry.get("arguments", [])),
                    main=bool(entry.get("main", False)),
                )
            )
        except KeyError as err:
            raise GraphError(f"{where}: missing {err}") from err
    unknown = set(extra) - {"rig"} - {n.name for n in nodes[1:]}
    if unknown:
        raise GraphError(f"{path}: overrides for unknown nodes {sorted(unknown)}")
    return Graph(namespace, tuple(nodes))


def _substitute(value: Any, subs: dict[str, str], where: str) -> Any:
    if not isinstance(value, str):
        return value
    try:
        return value.format(**subs)
    except KeyError as err:
        raise GraphError(f"{where}: no value for placeholder {err} in {value!r}") from err
