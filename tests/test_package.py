"""Package hygiene: the ROS-free core, package.xml dependencies, installed executables and data."""

from __future__ import annotations

import ast
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "cone_perception"
ROS_MODULES = {"rclpy", "std_msgs", "sensor_msgs", "geometry_msgs", "visualization_msgs", "diagnostic_msgs", "nav_msgs",
               "builtin_interfaces", "launch", "launch_ros", "ament_index_python", "rcl_interfaces"}
# import name -> rosdep key in package.xml
ROSDEP = {"numpy": "python3-numpy", "cv2": "python3-opencv", "yaml": "python3-yaml", "tqdm": "python3-tqdm",
          "matplotlib": "python3-matplotlib", "scipy": "python3-scipy"}
# installed with pip on the car because rosdep has no valid key (README "On the car")
PIP_ONLY = {"torch", "rosbags", "onnxruntime", "onnx", "pycocotools"}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), str(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def _package_xml_deps() -> set[str]:
    root = ET.parse(ROOT / "package.xml").getroot()
    return {e.text.strip() for tag in ("exec_depend", "depend", "test_depend") for e in root.iter(tag)}


#: the folders that may import rclpy and message classes: the nodes, and the ROS tools that drive them
ROS_FOLDERS = ("nodes", "rostools")


def test_core_modules_never_import_ros() -> None:
    offenders = {}
    for path in PKG.rglob("*.py"):
        if path.relative_to(PKG).parts[0] in ROS_FOLDERS:
            continue
        bad = _imports(path) & ROS_MODULES
        if bad:
            offenders[str(path.relative_to(ROOT))] = sorted(bad)
    assert not offenders, f"core modules import ROS (only cone_perception/nodes/ and rostools/ may): {offenders}"


def test_package_xml_lists_every_imported_dependency() -> None:
    deps = _package_xml_deps()
    stdlib = set(sys.stdlib_module_names)
    missing = {}
    for path in list(PKG.rglob("*.py")) + list((ROOT / "launch_configs").glob("*.py")):
        for name in _imports(path) - stdlib - {"cone_perception", "setuptools"}:
            key = name if name in ROS_MODULES else ROSDEP.get(name)
            if name in PIP_ONLY:
                continue
            if key is None or key not in deps:
                missing.setdefault(name, []).append(str(path.relative_to(ROOT)))
    assert not missing, f"imports without a package.xml dependency (or PIP_ONLY entry): {missing}"


def test_every_node_has_an_executable_and_every_shipped_file_is_installed() -> None:
    from cone_perception.nodes import executables
    from cone_perception.params import NODES

    setup_py = (ROOT / "setup.py").read_text()
    nodes = {node.stem for node in (PKG / "nodes").glob("[!_]*.py") if "\ndef main(" in node.read_text()}
    assert nodes == set(NODES), "every node module (one with main()) has its table in params.NODES, and only those"
    for stem in nodes:  # the executable starts in nodes/executables.py: --help without rclpy
        assert f'"{stem} = cone_perception.nodes.executables:{stem}"' in setup_py, f"no console script for {stem}"
        assert callable(getattr(executables, stem))
    assert '"cone-perception = cone_perception.cli:main"' in setup_py
    for folder, patterns in {"calib": ("*.yaml", "*.md"), "launch_configs": ("*.py", "*.yaml", "*.rviz")}.items():
        for pattern in patterns:
            assert f'share("{folder}/{pattern}")' in setup_py
    assert (PKG / "config" / "fastdds_localhost_shm.xml").is_file() and (PKG / "config" / "fastdds_shm.xml").is_file()
    assert (ROOT / "resource" / "cone_perception").is_file()


def test_commands_are_registered_and_importable() -> None:
    import importlib

    from cone_perception.cli import COMMANDS

    files = {p.stem for p in (PKG / "commands").glob("[!_]*.py")}
    assert files == {mod for mod, _ in COMMANDS.values()}, "every commands/*.py is registered in cli.COMMANDS"
    for mod, _ in COMMANDS.values():
        m = importlib.import_module(f"cone_perception.commands.{mod}")
        assert callable(m.add_arguments) and callable(m.run)
