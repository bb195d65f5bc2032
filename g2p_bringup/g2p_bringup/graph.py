"""The node graph's description (config/graph.yaml): which processes, with which parameters and remaps.

One description serves this project's bring-up (`bringup`, which starts each node as a process) and the
launch file for full ROS 2 installs (launch/g2p.launch.py). This module only reads and resolves it.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

# The hosts a graph may span: the rig's (the Raspberry Pi, or the machine running the simulator) and the
# workstation's (the learner). On one host, both are this host.
HOSTS = ("rig", "workstation")


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
        optional: started only when asked for (load_graph's `optional`).
        host: which host of a two-host graph runs the node (one of HOSTS); the rig always runs on "rig".
    """

    name: str
    package: str
    executable: str
    namespace: str
    parameters: dict[str, Any] = field(default_factory=dict)
    remappings: dict[str, str] = field(default_factory=dict)
    arguments: tuple[str, ...] = ()
    main: bool = False
    optional: bool = False
    host: str = "rig"

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
    """A resolved graph (or one host's part of it): the rig first, then the other nodes in start order.

    Attributes:
        namespace: namespace of every node.
        nodes: the nodes, in start order.
    """

    namespace: str
    nodes: tuple[NodeSpec, ...]

    @property
    def main(self) -> NodeSpec | None:
        """The node whose exit ends the graph, the marked one.

        None when this part has none: the rig host's part of a two-host graph serves until it is stopped.
        """
        return next((n for n in self.nodes if n.main), None)


def load_graph(
    path: Path,
    rig: str | None = None,
    substitutions: dict[str, str] | None = None,
    overrides: dict[str, dict[str, Any]] | None = None,
    host: str | None = None,
    optional: frozenset[str] = frozenset(),
    parameters: Callable[[NodeSpec], Collection[str] | None] | None = None,
) -> Graph:
    """Read a graph description and resolve it.

    Args:
        path: the YAML description.
        rig: which entry of `rigs` to use; the first when None.
        substitutions: values for `{name}` placeholders in string parameters and remappings.
        overrides: extra parameters per node name ("rig" addresses the rig), applied last.
        host: only the nodes of this host (one of HOSTS); every node when None (one host).
        optional: names of the optional nodes to start too (e.g. {"viewer"}).
        parameters: every parameter a node's executable declares, None when unknown; each of `overrides`
            must name one of them (checked for the nodes of every host).

    Raises:
        GraphError: the file is unreadable or invalid, the rig or host is unknown, an optional node asked
            for is not an optional node of the file, a placeholder has no value, or an override names a
            parameter its node does not have (the message names the nearest ones).
    """
    if host is not None and host not in HOSTS:
        raise GraphError(f"unknown host {host!r}; choose one of {list(HOSTS)}")
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
    nodes: list[NodeSpec] = []
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
                    optional=bool(entry.get("optional", False)),
                    host="rig" if key == "rig" else str(entry.get("host", "rig")),
                )
            )
        except KeyError as err:
            raise GraphError(f"{where}: missing {err}") from err
        if nodes[-1].host not in HOSTS:
            raise GraphError(f"{where}: unknown host {nodes[-1].host!r}; choose one of {list(HOSTS)}")
    known_optional = {n.name for n in nodes if n.optional}
    if optional - known_optional:
        raise GraphError(
            f"{path}: no optional nodes {sorted(optional - known_optional)}; it has {sorted(known_optional)}"
        )
    nodes = [n for n in nodes if not n.optional or n.name in optional]
    unknown = set(extra) - {"rig"} - {n.name for n in nodes[1:]}
    if unknown:
        hint = [n for n in sorted(unknown) if n in known_optional]
        why = f" (start {hint} with it: bringup --view)" if hint else ""
        raise GraphError(f"{path}: overrides for unknown nodes {sorted(unknown)}{why}")
    if parameters is not None:
        for key, spec in [("rig", nodes[0]), *((n.name, n) for n in nodes[1:])]:
            _check_overrides(key, spec, extra.get(key, {}), parameters)
    if host is not None:
        nodes = [n for n in nodes if n.host == host]
    return Graph(namespace, tuple(nodes))


def _check_overrides(
    key: str,
    spec: NodeSpec,
    overrides: dict[str, Any],
    parameters: Callable[[NodeSpec], Collection[str] | None],
) -> None:
    """Raise GraphError for the first of `overrides` (of the node addressed as `key`) naming no parameter."""
    known = parameters(spec) if overrides else None
    if known is None:
        return
    for name in overrides:
        if name not in known:
            nearest = difflib.get_close_matches(name, list(known), n=3)
            hint = f"; nearest: {', '.join(f'{key}.{n}' for n in nearest)}" if nearest else ""
            raise GraphError(
                f"override {key}.{name}: node {key!r} ({spec.package} {spec.executable}) has no parameter "
                f"{name!r}{hint}"
            )


def _substitute(value: Any, subs: dict[str, str], where: str) -> Any:
    if not isinstance(value, str):
        return value
    try:
        return value.format(**subs)
    except KeyError as err:
        raise GraphError(f"{where}: no value for placeholder {err} in {value!r}") from err
