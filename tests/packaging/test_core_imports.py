"""The core library's modules import each other without a cycle (lazy imports inside functions included)."""

from __future__ import annotations

import ast
from pathlib import Path

import g2p

SRC = Path(g2p.__file__).resolve().parent


def module_name(path: Path) -> str:
    parts = path.relative_to(SRC.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(path: Path, modules: set[str]) -> set[str]:
    """The g2p modules `path` imports anywhere in its code, at module level or inside a function."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            # `from g2p.x import y` imports g2p.x, or the module g2p.x.y
            names = [f"{node.module}.{alias.name}" for alias in node.names] + [node.module]
        else:
            continue
        found |= {name for name in names if name in modules}
    return found


def graph() -> dict[str, set[str]]:
    paths = sorted(SRC.rglob("*.py"))
    modules = {module_name(p) for p in paths}
    graph = {module_name(p): imports_of(p, modules) - {module_name(p)} for p in paths}
    # A package's own __init__ importing its submodules is not a cycle: Python runs the package first.
    return {m: {d for d in deps if not d.startswith(m + ".")} for m, deps in graph.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}  # 1: on the stack, 2: done
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for d in sorted(graph.get(m, ())):
            if state.get(d) == 1:
                return [*stack[stack.index(d) :], d]
            if d not in state and (cycle := visit(d)) is not None:
                return cycle
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state and (cycle := visit(m)) is not None:
            return cycle
    return None


def test_the_cycle_finder_finds_a_known_cycle() -> None:
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_no_import_cycle_in_the_core() -> None:
    g = graph()
    assert "g2p.inverse_map.config" in g["g2p.inverse_map.training"]  # the graph sees imports
    assert find_cycle(g) is None, " -> ".join(find_cycle(g) or [])


# The core's top level: its layers as subpackages, and the few modules every layer uses.
TOP_LEVEL_MODULES = {"g2p.plant", "g2p.safety", "g2p.validation", "g2p.files"}


def layer_of(module: str) -> str:
    """The top-level module or subpackage `module` belongs to (g2p.rig.envelope -> g2p.rig)."""
    return ".".join(module.split(".")[:2])


def may_import(package: str) -> set[str]:
    """The subpackages a subpackage's docstring says it may import (its line "May import: ...")."""
    init = SRC / package.split(".")[1] / "__init__.py"
    doc = ast.get_docstring(ast.parse(init.read_text())) or ""
    lines = [line for line in doc.splitlines() if line.startswith("May import:")]
    assert len(lines) == 1, f"{init}: the docstring needs one line 'May import: ...'"
    return {word.strip(" .,") for word in lines[0].split() if word.startswith("g2p.")}


def test_the_top_level_holds_subpackages_and_the_shared_modules() -> None:
    modules = {f"g2p.{p.stem}" for p in SRC.glob("*.py") if p.name != "__init__.py"}
    assert modules == TOP_LEVEL_MODULES


def test_each_layer_imports_only_what_its_docstring_allows() -> None:
    g = graph()
    packages = {f"g2p.{p.parent.name}" for p in SRC.glob("*/__init__.py")}
    assert {"g2p.rig", "g2p.learning", "g2p.hardware", "g2p.sim"} <= packages
    allowed = {p: may_import(p) | {p} | TOP_LEVEL_MODULES for p in packages}
    for p, rule in allowed.items():
        assert rule - TOP_LEVEL_MODULES - {p} <= packages, f"{p} names a package that does not exist"
    # The shared modules import only each other.
    allowed |= {m: TOP_LEVEL_MODULES for m in TOP_LEVEL_MODULES}
    broken = [
        f"{module} imports {dep}"
        for module, deps in g.items()
        if module != "g2p"
        for dep in deps
        if layer_of(dep) not in allowed[layer_of(module)]
    ]
    assert not broken, "\n".join(broken)


def test_the_rule_catches_a_forbidden_import() -> None:
    assert "g2p.rig" not in may_import("g2p.hardware")
    assert "g2p.sim" not in may_import("g2p.hardware") and "g2p.hardware_fake" not in may_import(
        "g2p.hardware"
    )
    assert layer_of("g2p.rig.envelope") == "g2p.rig" and layer_of("g2p.plant") == "g2p.plant"
