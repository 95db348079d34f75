"""The package's shape (issues 19 and 28).

- No import cycle between modules, and none between folders (``train`` -> ``detector`` -> ``train`` is one
  even when no module cycle closes it).
- Layers (:data:`LAYERS`): a module imports only from its own layer or a lower one. The lowest two are the
  vocabulary and the runtime (what runs on the car); the tools (data formats, evaluation, calibrate,
  synth, train, replay, bench, the fuzz and live-replay players, commands) sit above them, so the runtime
  imports nothing of the tools; what both need sits in the runtime or in ``data/``.
- Importing the runtime's mapping, attitude, tracking or ``data/`` loads no torch.
- Only ``cli.py`` and the commands import from ``commands/``; no command imports a sibling command (shared
  argparse helpers live in ``commands/_args.py``); tests reach the core, not the commands (CLI tests go
  through ``cli.main``).
- Imports sit at the top of a module; one inside a function is for an optional dependency or a heavy tool
  (counted: :data:`MAX_IMPORTS_IN_FUNCTIONS`).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "cone_perception"


def _modules() -> dict[str, Path]:
    out = {}
    for f in PKG.rglob("*.py"):
        parts = list(f.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """The package's modules that ``path`` imports anywhere (top level or inside functions)."""
    pkg = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    for n in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(n, ast.ImportFrom):
            base = ".".join(pkg[: len(pkg) - (n.level - 1)] + ([n.module] if n.module else [])) if n.level else (n.module or "")
            cands = [f"{base}.{a.name}" for a in n.names] + [base]
        elif isinstance(n, ast.Import):
            cands = [a.name for a in n.names]
        else:
            continue
        for t in cands:
            while t and t not in MODULES:
                t = t.rpartition(".")[0]
            if t and t != name:
                found.add(t)
    return found


GRAPH = {m: _imports(m, f) for m, f in MODULES.items()}


def _cycles(graph: dict[str, set[str]] = GRAPH) -> list[list[str]]:
    """Strongly connected components of more than one node (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


#: Lowest first. A module imports from its own layer or a lower one. Names are the first part below
#: ``cone_perception`` (a top-level module or a folder), or a module of a folder placed apart.
LAYERS: list[tuple[str, set[str]]] = [
    ("vocabulary", {"cone_perception", "classes", "errors", "records", "resources", "words", "timing", "stats"}),
    ("runtime", {"adapter", "crop", "imageheader", "geometry", "attitude", "mapping", "tracking", "model", "detector",
                 "params", "pipeline", "vis", "ros_env", "nodes"}),
    ("data", {"data"}),
    ("evaluation, calibration, synthesis", {"evaluation", "calibrate", "synth"}),
    ("training, replay, benchmarks, ROS players", {"train", "replay", "bench", "nodes.live_replay", "nodes.fuzz",
                                                   "nodes.soak", "nodes.startup"}),
    ("commands", {"commands"}),
    ("cli", {"cli"}),
]
RUNTIME_LAYERS = 2  # the first two: what runs on the car


def _unit(module: str) -> str:
    """The layer unit of a module: ``nodes.fuzz`` where a unit names it, else its top-level name."""
    parts = module.split(".")[1:]
    for k in range(len(parts), 0, -1):
        name = ".".join(parts[:k])
        if any(name in units for _, units in LAYERS):
            return name
    return "cone_perception" if not parts else parts[0]


def _layer(module: str) -> int:
    unit = _unit(module)
    return next((i for i, (_, units) in enumerate(LAYERS) if unit in units), -1)


def _folder(module: str) -> str:
    """The folder (or top-level module) a module belongs to: ``cone_perception.train.loader`` -> ``train``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "cone_perception"


FOLDER_GRAPH: dict[str, set[str]] = {}
for _m, _ts in GRAPH.items():
    FOLDER_GRAPH.setdefault(_folder(_m), set()).update(_folder(t) for t in _ts if _folder(t) != _folder(_m))


def test_every_module_has_a_layer() -> None:
    assert [m for m in MODULES if _layer(m) < 0] == []


def test_the_runtime_imports_no_tool() -> None:
    bad = sorted(f"{m} -> {t}" for m, ts in GRAPH.items() if _layer(m) < RUNTIME_LAYERS
                 for t in ts if _layer(t) >= RUNTIME_LAYERS)
    assert bad == [], "the runtime imports a tool; move what both need into the runtime or data/"


def test_no_upward_import() -> None:
    bad = sorted(f"{m} ({LAYERS[_layer(m)][0]}) -> {t} ({LAYERS[_layer(t)][0]})"
                 for m, ts in GRAPH.items() for t in ts if _layer(t) > _layer(m))
    assert bad == []


def test_no_folder_cycle() -> None:
    assert _cycles(FOLDER_GRAPH) == []


def test_the_checker_sees_folder_cycles() -> None:
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [["a", "b"]]
    assert FOLDER_GRAPH["train"] >= {"data", "detector"} and "train" not in FOLDER_GRAPH["data"]


def test_mapping_tracking_and_data_load_no_torch() -> None:
    """The car's mapping and tracking, and the formats the tools share, import without torch (no model)."""
    names = ["cone_perception.mapping", "cone_perception.attitude", "cone_perception.tracking",
             "cone_perception.geometry.calib"] + sorted(m for m in MODULES if m.startswith("cone_perception.data"))
    code = (f"import importlib, sys\nfor n in {names!r}:\n    importlib.import_module(n)\n"
            "print(sorted(m for m in sys.modules if m == 'torch' or m.startswith('torch.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"


def imports_in_functions(path: Path) -> list[int]:
    """Line numbers of the import statements inside function bodies (nested functions counted once)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    lines = set()
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            lines.update(n.lineno for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom)))
    return sorted(lines)


#: The most import statements inside functions (issue 28: about 220 before, at most 40): each one for an
#: optional dependency or a heavy tool, with a comment saying which.
MAX_IMPORTS_IN_FUNCTIONS = 40


def test_imports_sit_at_the_top() -> None:
    found = {str(f.relative_to(ROOT)): imports_in_functions(f) for f in sorted(PKG.rglob("*.py"))}
    total = sum(len(v) for v in found.values())
    assert total <= MAX_IMPORTS_IN_FUNCTIONS, "imports inside functions: " + ", ".join(
        f"{k} ({len(v)})" for k, v in sorted(found.items(), key=lambda kv: -len(kv[1])) if v)


#: A module a reader can hold in mind, and few enough modules at the package's top (issue 28).
MAX_MODULE_LINES = 500
MAX_TOP_LEVEL_MODULES = 15


def test_no_module_over_500_lines() -> None:
    long = {str(f.relative_to(ROOT)): n for f in PKG.rglob("*.py")
            if (n := len(f.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES}
    assert long == {}


def test_few_modules_at_the_top() -> None:
    top = sorted(f.name for f in PKG.glob("*.py") if f.name != "__init__.py")
    assert len(top) <= MAX_TOP_LEVEL_MODULES, top


def test_the_import_counter_counts_nested_functions_once(tmp_path) -> None:
    f = tmp_path / "m.py"
    f.write_text("import os\ndef a():\n    import json\n    def b():\n        import re\n")
    assert imports_in_functions(f) == [3, 5]


def test_the_checker_sees_imports() -> None:
    assert "cone_perception.replay.detect" in GRAPH["cone_perception.commands.detect"]
    assert "cone_perception.commands._args" in GRAPH["cone_perception.commands.detect"]


def test_no_import_cycle() -> None:
    assert _cycles() == []


def test_only_the_cli_imports_commands() -> None:
    bad = sorted(f"{m} -> {t}" for m, ts in GRAPH.items() for t in ts
                 if t.startswith("cone_perception.commands") and not m.startswith("cone_perception.commands")
                 and m != "cone_perception.cli")
    assert bad == []


def test_no_command_imports_a_sibling() -> None:
    shared = {"cone_perception.commands", "cone_perception.commands._args"}
    bad = sorted(f"{m} -> {t}" for m, ts in GRAPH.items() if m.startswith("cone_perception.commands.")
                 for t in ts if t.startswith("cone_perception.commands") and t not in shared)
    assert bad == []


def test_tests_do_not_import_commands() -> None:
    bad = [f.name for f in (ROOT / "tests").glob("*.py")
           if "cone_perception.commands" in f.read_text(encoding="utf-8") and f.name not in ("test_package.py", "test_layout.py")]
    assert bad == []
