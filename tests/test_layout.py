"""The package's shape (issue 19): no import cycle; only ``cli.py`` and the commands import from
``commands/``; no command imports a sibling command (shared argparse helpers live in ``commands/_args.py``);
tests reach the core, not the commands (CLI tests go through ``cli.main``)."""

from __future__ import annotations

import ast
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


def _cycles() -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in GRAPH[v]:
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

    for v in GRAPH:
        if v not in index:
            visit(v)
    return out


def test_the_checker_sees_imports() -> None:
    assert "cone_perception.sources" in GRAPH["cone_perception.commands.detect"]
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
