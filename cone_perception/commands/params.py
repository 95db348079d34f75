"""``cone-perception params``: the nodes' parameters, and the docs generated from their schema.

  cone-perception params                 # every node's usage, topics and parameters (as NODE --help)
  cone-perception params pipeline        # one node
  cone-perception params --write         # rewrite the tables of docs/nodes.md and the node docstrings
  cone-perception params --check         # exit 1, naming the files, when they differ from the schema

One home: cone_perception/params.py (name, type, default, range, description, set at run time or
not, per node). Generated from it, in a source checkout: the topic lists and tables of docs/nodes.md (and any
in README.md or another docs/*.md) between <!-- params:NODE --> and <!-- /params --> (NODE every_node: the parameters every
node has), and the "Parameters (generated ...)" block of each node module's docstring. A test runs
--check (tests/test_param_schema.py).
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from ..errors import ConfigError
from ..params import EVERY_NODE, NODES, REGENERATE, docstring_block, help_text, markdown_block

_BLOCK = re.compile(r"<!-- params:(\w+)[^\n]*-->\n.*?<!-- /params -->", re.S)
_DOC_BLOCK = re.compile(r"^Parameters \(generated[^\n]*\n(?:  [^\n]*\n)*", re.M)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.description = __doc__.split(": ", 1)[1].strip()
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument("nodes", nargs="*", metavar="NODE", help=f"node(s) to print: {', '.join(NODES)} (default: all)")
    what = p.add_mutually_exclusive_group()
    what.add_argument("--write", action="store_true", help="rewrite the generated parts of README.md, docs/*.md and "
                      "cone_perception/nodes/<node>.py")
    what.add_argument("--check", action="store_true", help="exit 1 when a generated part differs from the schema")
    p.add_argument("--root", type=Path, default=Path(__file__).resolve().parents[2],
                   help="the source checkout (default: the one this package runs from)")


def regenerate(root: Path) -> dict[Path, tuple[str, str]]:
    """``file -> (text now, text generated)`` for every file with generated parts under ``root``."""
    tables = root / "docs" / "nodes.md"  # the home of the tables; README.md and other docs may hold blocks too
    if not tables.is_file():
        raise ConfigError(str(root), None, "no docs/nodes.md: not a source checkout of cone_perception (--root)")
    out = {}
    for f in [root / "README.md", *sorted((root / "docs").glob("*.md"))]:
        if not f.is_file():
            continue
        text = f.read_text(encoding="utf-8")

        def block(m: re.Match, f=f) -> str:
            key = m.group(1)
            if key != EVERY_NODE and key not in NODES:
                raise ConfigError(str(f), f"params:{key}", f"no such node; known: {', '.join(NODES)}, {EVERY_NODE}")
            return (f"<!-- params:{key} (generated from cone_perception/params.py by `{REGENERATE}`) -->\n"
                    f"{markdown_block(key)}<!-- /params -->")

        out[f] = (text, _BLOCK.sub(block, text))
    missing = [k for k in (*NODES, EVERY_NODE) if f"<!-- params:{k} " not in out[tables][0]]
    if missing:
        raise ConfigError(str(tables), None, f"no <!-- params:NODE --> block for {', '.join(missing)}")
    for node in NODES:
        f = root / "cone_perception" / "nodes" / f"{node}.py"
        text = f.read_text(encoding="utf-8")
        if not _DOC_BLOCK.search(text):
            raise ConfigError(str(f), "docstring", "no 'Parameters (generated ...)' block to regenerate")
        out[f] = (text, _DOC_BLOCK.sub(lambda m, node=node: docstring_block(node), text, count=1))
    return out


def stale(root: Path) -> list[Path]:
    """The files whose generated parts differ from the schema."""
    return [f for f, (now, new) in regenerate(root).items() if now != new]


def run(args: argparse.Namespace) -> int:
    unknown = [n for n in args.nodes if n not in NODES]
    if unknown:
        raise ConfigError("NODE", None, f"unknown node {', '.join(unknown)}; known: {', '.join(NODES)}")
    root = args.root.resolve()
    if args.check:
        bad = stale(root)
        if bad:
            print(f"out of date with cone_perception/params.py: {', '.join(str(f.relative_to(root)) for f in bad)}; "
                  f"run `{REGENERATE}`", file=sys.stderr)
            return 1
        print("the parameter tables (docs/nodes.md) and node docstrings match cone_perception/params.py")
        return 0
    if args.write:
        for f, (now, new) in regenerate(root).items():
            if now != new:
                f.write_text(new, encoding="utf-8")
                print(f"wrote {f.relative_to(root)}")
        return 0
    sys.stdout.write("\n".join(help_text(n) for n in (args.nodes or NODES)))
    return 0
