"""The generated parts of the docs, from the nodes' parameter schema (:mod:`cone_perception.params`).

In a source checkout: the topic lists and tables of docs/nodes.md (and any in README.md or another docs/*.md)
between ``<!-- params:NODE -->`` and ``<!-- /params -->`` (NODE :data:`~cone_perception.params.EVERY_NODE`: the
parameters every node has), and the "Parameters (generated ...)" block of each node module's docstring.
``cone-perception params --write`` rewrites them (:func:`write`), ``--check`` names those that differ (:func:`stale`).
"""

from __future__ import annotations

import re
from pathlib import Path

from ..errors import ConfigError
from ..params import EVERY_NODE, NODES, REGENERATE, docstring_block, markdown_block

_BLOCK = re.compile(r"<!-- params:(\w+)[^\n]*-->\n.*?<!-- /params -->", re.S)
_DOC_BLOCK = re.compile(r"^Parameters \(generated[^\n]*\n(?:  [^\n]*\n)*", re.M)


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


def write(root: Path) -> list[Path]:
    """Rewrite the files whose generated parts differ from the schema; those files."""
    written = []
    for f, (now, new) in regenerate(root).items():
        if now != new:
            f.write_text(new, encoding="utf-8")
            written.append(f)
    return written
