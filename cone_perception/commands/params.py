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
import sys
from pathlib import Path

from ..data import paramdocs
from ..errors import ConfigError
from ..params import NODES, REGENERATE, help_text


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


def run(args: argparse.Namespace) -> int:
    unknown = [n for n in args.nodes if n not in NODES]
    if unknown:
        raise ConfigError("NODE", None, f"unknown node {', '.join(unknown)}; known: {', '.join(NODES)}")
    root = args.root.resolve()
    if args.check:
        bad = paramdocs.stale(root)
        if bad:
            print(f"out of date with cone_perception/params.py: {', '.join(str(f.relative_to(root)) for f in bad)}; "
                  f"run `{REGENERATE}`", file=sys.stderr)
            return 1
        print("the parameter tables (docs/nodes.md) and node docstrings match cone_perception/params.py")
        return 0
    if args.write:
        for f in paramdocs.write(root):
            print(f"wrote {f.relative_to(root)}")
        return 0
    sys.stdout.write("\n".join(help_text(n) for n in (args.nodes or NODES)))
    return 0
