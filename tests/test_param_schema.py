"""Issue 28/30: one schema for every node parameter (cone_perception/params.py). The tables of docs/nodes.md and
the node docstrings are generated from it and checked here; launch parameter files name only its
parameters; every node executable answers --help from it without importing rclpy. No ROS here (the
nodes' declarations against the schema: tests/test_params.py)."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from cone_perception.cli import main
from cone_perception.params import COMMON_PARAMS, NODES, PARAMS, ParamSpec, help_text, node_params

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
REGENERATE = "cone-perception params --write"


# -- the generated docs ---------------------------------------------------------------------------
def test_readme_tables_and_node_docstrings_match_the_schema(capsys):
    rc = main(["params", "--check", "--root", str(ROOT)])
    err = capsys.readouterr().err
    assert rc == 0, f"{err.strip()} (generated from cone_perception/params.py: run `{REGENERATE}`)"


def _copy_checkout(dst: Path) -> Path:
    shutil.copy(ROOT / "README.md", dst / "README.md")
    shutil.copytree(ROOT / "docs", dst / "docs")
    (dst / "cone_perception" / "nodes").mkdir(parents=True)
    for node in NODES:
        shutil.copy(ROOT / "cone_perception" / "nodes" / f"{node}.py", dst / "cone_perception" / "nodes")
    return dst


def test_a_drifted_table_or_docstring_fails_the_check_and_write_repairs_it(tmp_path, capsys):
    root = _copy_checkout(tmp_path)
    tables = root / "docs" / "nodes.md"
    readme = tables.read_text()
    row = "| `conf` | double | `0.25` |"
    assert row in readme
    tables.write_text(readme.replace(row, "| `conf` | double | `0.3` |"))
    node = root / "cone_perception" / "nodes" / "cone_tracker.py"
    node.write_text(node.read_text().replace("odom_max_age_s (double, default 0.1", "odom_max_age_s (double, default 0.2"))
    capsys.readouterr()
    assert main(["params", "--check", "--root", str(root)]) == 1
    err = capsys.readouterr().err
    assert "docs/nodes.md" in err and "cone_perception/nodes/cone_tracker.py" in err and REGENERATE in err
    assert "detection.py" not in err  # only what drifted is named

    assert main(["params", "--write", "--root", str(root)]) == 0
    assert tables.read_text() == readme
    assert main(["params", "--check", "--root", str(root)]) == 0


def test_a_tables_file_without_a_node_block_is_refused(tmp_path, capsys):
    root = _copy_checkout(tmp_path)
    tables = root / "docs" / "nodes.md"
    text = tables.read_text()
    start = text.index("<!-- params:mapping ")
    end = text.index("<!-- /params -->", start) + len("<!-- /params -->")
    tables.write_text(text[:start] + text[end:])
    assert main(["params", "--check", "--root", str(root)]) == 2
    assert "no <!-- params:NODE --> block for mapping" in capsys.readouterr().err


def test_every_node_table_is_complete_and_consistent():
    assert set(NODES) == {"driver_adapter", "detection", "mapping", "pipeline", "cone_tracker"}
    for node in NODES:
        specs = node_params(node)
        assert all(p.name in specs for p in COMMON_PARAMS), node
        for name, spec in specs.items():
            assert spec.name == name and spec.description, (node, name)
            assert spec.check(spec.default) is None, (node, name)
            assert name in PARAMS, f"{node}: {name} is not in PARAMS"
    # the pipeline declares what the three nodes and the tracker declare; its calibration is the
    # adapter's (required), not the detection node's (optional)
    pipe = node_params("pipeline")
    for other in ("driver_adapter", "detection", "mapping", "cone_tracker"):
        assert set(node_params(other)) <= set(pipe), other
    assert pipe["calibration"] is PARAMS["calibration"] and node_params("detection")["calibration"].default == ""


def test_no_node_declares_a_parameter_outside_the_schema():
    """Only nodes/_params.py calls declare_parameter; every declare(node, "name") names a schema parameter."""
    names = {n for node in NODES for n in node_params(node)}
    for f in (ROOT / "cone_perception" / "nodes").glob("*.py"):
        for n in ast.walk(ast.parse(f.read_text())):
            if not isinstance(n, ast.Call):
                continue
            fn = n.func.attr if isinstance(n.func, ast.Attribute) else getattr(n.func, "id", "")
            if fn == "declare_parameter":
                assert f.name == "_params.py", f"{f.name} declares a parameter outside the schema"
            elif fn == "declare" and len(n.args) == 2 and isinstance(n.args[1], ast.Constant):
                assert n.args[1].value in names, f"{f.name}: declare({n.args[1].value!r}) is not in the schema"


# -- the checks of a value ---------------------------------------------------------------------------
@pytest.mark.parametrize(("name", "value", "words"), [
    ("odom_max_age_s", 0.0, "> 0.0"),
    ("odom_type", "pose", "one of odometry, twist"),
    ("attitude", "gyro", "one of '', fixed, image, imu, fused"),
    ("imu_rest_deg", [1.0], "a list of 2 numbers"),
    ("imu_rest_deg", [1.0, float("nan")], "imu_rest_deg[1] must be finite"),
    ("imu_rest_deg", "0 0", "a list of 2 numbers"),
    ("input_timeout_s", -1.0, ">= 0.0"),
])
def test_schema_check_names_the_reason(name, value, words):
    why = PARAMS[name].check(value)
    assert why is not None and words in why, why


def test_schema_accepts_good_values_and_words_its_ranges():
    assert PARAMS["imu_rest_deg"].check([0.5, -1]) is None and PARAMS["imu_rest_deg"].ros_type == "double[2]"
    assert PARAMS["imu_rest_deg"].ros_default == [0.0, 0.0]
    assert PARAMS["attitude"].check("") is None and PARAMS["odom_max_age_s"].check(0.05) is None
    assert PARAMS["odom_max_age_s"].range_text() == "> 0.0" and PARAMS["input_rate_hz"].range_text() == ">= 0.0"
    assert ParamSpec("x", "", "d", choices=("", "a")).range_text() == '"" | a'


# -- launch parameter files --------------------------------------------------------------------------
def _param_files() -> list[Path]:
    return sorted((ROOT / "launch_configs").glob("*.yaml")) + sorted((ROOT / "calib").glob("*.params.yaml"))


def test_launch_parameter_files_name_only_schema_parameters():
    files = _param_files()
    assert files
    for f in files:
        doc = yaml.safe_load(f.read_text())
        for section, body in doc.items():
            params = body["ros__parameters"]
            if section == "/**":  # every node: each name must be some node's, and good for each that has it
                tables = [node_params(n) for n in NODES]
                for name, value in params.items():
                    having = [t[name] for t in tables if name in t]
                    assert having, f"{f.name}: {section}: {name} is no node's parameter"
                    assert all(s.check(value) is None for s in having), f"{f.name}: {name}: {value!r}"
                continue
            assert section.strip("/") in NODES, f"{f.name}: no node {section}"
            table = node_params(section.strip("/"))
            for name, value in params.items():
                assert name in table, f"{f.name}: {section}: {name} is not a parameter of {section}"
                assert table[name].check(value) is None, f"{f.name}: {section}: {table[name].check(value)}"


# -- --help of the node executables ------------------------------------------------------------------
@pytest.fixture(scope="module")
def no_rclpy(tmp_path_factory) -> dict:
    """An environment in which importing rclpy (or creating a DDS participant through it) fails loudly."""
    d = tmp_path_factory.mktemp("no_rclpy")
    (d / "rclpy").mkdir()
    (d / "rclpy" / "__init__.py").write_text("raise SystemExit('rclpy imported by --help')\n")
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(d), os.environ.get("PYTHONPATH", "")])}


@pytest.mark.parametrize("node", sorted(NODES))
@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_node_executable_help_prints_usage_parameters_and_topics_without_rclpy(node, flag, no_rclpy):
    exe = BIN / node
    assert exe.is_file(), f"{exe}: install the package (make setup)"
    p = subprocess.run([str(exe), flag], env=no_rclpy, capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert p.stdout == help_text(node)
    assert f"usage: ros2 run cone_perception {node}" in p.stdout
    for name in node_params(node):
        assert f"\n  {name} (" in p.stdout, name
    assert "subscribed:" in p.stdout and "published:" in p.stdout and "/diagnostics" in p.stdout


@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_the_command_answers_help_without_rclpy_too(flag, no_rclpy):
    for argv in ([flag], ["params", flag], ["params", "pipeline"]):
        p = subprocess.run([str(BIN / "cone-perception"), *argv], env=no_rclpy, capture_output=True, text=True,
                           timeout=60)
        assert p.returncode == 0 and p.stdout.startswith("usage:"), (argv, p.stderr)
    assert p.stdout == help_text("pipeline")


def test_help_is_checked_in_process_too_and_ros_args_pass_through(monkeypatch, capsys):
    """Without help the node module gets argv untouched (--ros-args included); -h inside --ros-args is ROS's."""
    code = ("import sys; from cone_perception.nodes.executables import launch; rc = launch('pipeline', "
            "['pipeline', '--ros-args', '-p', 'conf:=0.3', '--', '--help']); "
            "assert 'rclpy' not in sys.modules, 'rclpy imported'; sys.exit(rc)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0 and "far_rows (string" in p.stdout, p.stderr

    from cone_perception.nodes import executables

    seen = []

    class FakeNodeModule:
        @staticmethod
        def main(argv):
            seen.append(argv)
            return 0

    monkeypatch.setattr(executables.importlib, "import_module", lambda name: FakeNodeModule)
    argv = ["mapping", "--ros-args", "-h", "-p", "calibration:=x", "-r", "__node:=m2"]
    assert executables.launch("mapping", argv) == 0 and seen == [argv]
    assert capsys.readouterr().out == ""
    assert executables.wants_help(["--ros-args", "-r", "a:=b", "--", "-h"])
    assert not executables.wants_help(["--ros-args", "--help"])
