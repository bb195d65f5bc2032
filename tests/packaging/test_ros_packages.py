"""The ROS packages are laid out as colcon and `ros2 run` expect, and each declares what its code imports."""

from __future__ import annotations

import ast
import configparser
import sys
from pathlib import Path
from xml.etree import ElementTree

import pytest
from ament_index_python.packages import get_packages_with_prefixes

ROOT = Path(__file__).resolve().parents[2]
PYTHON_PACKAGES = sorted(p.parent.name for p in ROOT.glob("g2p_*/setup.py"))
# Python libraries the nodes import directly, by their rosdep keys. Everything else they use comes through
# the core library `g2p`, a pip package with extras (pyproject.toml), which has no rosdep key.
ROSDEP_KEYS = {"numpy": "python3-numpy", "yaml": "python3-yaml"}
# ROS packages that a full ROS install has and the PyPI wheels here do not.
ROS_ONLY_ON_FULL_INSTALLS = {"launch", "launch_ros"}


def imported_top_level_modules(package_dir: Path) -> set[str]:
    """Top-level names of every absolute import in the package's modules and launch files."""
    names: set[str] = set()
    for path in [*package_dir.glob(f"{package_dir.name}/**/*.py"), *package_dir.glob("launch/*.py")]:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
    return names


def declared_dependencies(package_dir: Path) -> set[str]:
    root = ElementTree.parse(package_dir / "package.xml").getroot()
    return {e.text or "" for tag in ("depend", "exec_depend") for e in root.iter(tag)}


def expected_dependencies(package_dir: Path) -> set[str]:
    ros_packages = set(get_packages_with_prefixes()) | ROS_ONLY_ON_FULL_INSTALLS
    expected = set()
    for name in imported_top_level_modules(package_dir) - {package_dir.name, "g2p"}:
        if name in sys.stdlib_module_names or name == "__future__":
            continue
        if name in ROSDEP_KEYS:
            expected.add(ROSDEP_KEYS[name])
        else:
            assert name in ros_packages or name.startswith("g2p_"), (
                f"{package_dir.name} imports {name}, which is neither a ROS package nor a rosdep key known "
                "here: import it through the core library g2p, or add its key to ROSDEP_KEYS"
            )
            expected.add(name)
    return expected


def test_every_ament_python_package_is_found() -> None:
    assert PYTHON_PACKAGES == [
        "g2p_bringup",
        "g2p_driver",
        "g2p_learner",
        "g2p_recorder",
        "g2p_ros",
        "g2p_sim",
        "g2p_viewer",
    ]


@pytest.mark.parametrize("package", PYTHON_PACKAGES)
def test_package_xml_declares_every_package_its_code_imports(package: str) -> None:
    package_dir = ROOT / package
    missing = expected_dependencies(package_dir) - declared_dependencies(package_dir)
    assert not missing, f"{package}/package.xml lacks <exec_depend> for {sorted(missing)}"


def test_bringup_depends_on_every_package_it_starts() -> None:
    graph = (ROOT / "g2p_bringup" / "config" / "graph.yaml").read_text()
    started = {
        line.split(":", 1)[1].strip() for line in graph.splitlines() if line.strip().startswith("package:")
    }
    assert started <= declared_dependencies(ROOT / "g2p_bringup")


@pytest.mark.parametrize("package", PYTHON_PACKAGES)
def test_each_executable_module_has_the_executable_name(package: str) -> None:
    """As in ros2/demos (`talker = demo_nodes_py.topics.talker:main`)."""
    setup = (ROOT / package / "setup.py").read_text()
    tree = ast.parse(setup)
    scripts = [
        n.value
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant)
        and isinstance(n.value, str)
        and " = " in n.value
        and ":main" in n.value
    ]
    for script in scripts:
        name, target = (s.strip() for s in script.split("="))
        module = target.split(":")[0]
        assert module == f"{package}.{name}", (
            f"{package}: {script!r} should be {name} = {package}.{name}:main"
        )
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / package / "setup.cfg")
    assert cfg["install"]["install_scripts"] == f"$base/lib/{package}"  # where `ros2 run` looks
