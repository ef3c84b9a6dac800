"""`dmg docs`: the parameter tables of docs/nodes/<node>.md, generated from config/<node>.yaml.

The YAML a node declares its parameters from is the one source of their defaults, ranges and
descriptions; each node page carries a copy of it as a table between two marker lines, and
`dmg docs` rewrites that copy (`--check` only reports pages that are out of date, for CI).
Nodes are found from the `dmg.nodes` entry points, so a new node needs no list kept here.
"""
from __future__ import annotations

import argparse
import re
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

from dmg_common.config import REPO_ROOT, load_parameter_spec

BEGIN = "<!-- parameters: begin (generated from config/{config}.yaml by `dmg docs`; do not edit) -->"
END = "<!-- parameters: end -->"


@dataclass(frozen=True)
class NodeDoc:
    """A ROS node of the project and where its documentation and parameters live."""

    package: str
    executable: str

    @property
    def config(self) -> str:
        """config/<config>.yaml holds its parameters: the executable's name without `_node`."""
        return self.executable.removesuffix("_node")

    @property
    def page(self) -> Path:
        return REPO_ROOT / "docs" / "nodes" / f"{self.executable}.md"


def project_nodes() -> list[NodeDoc]:
    """Every node the project installs (`[project.entry-points."dmg.nodes"]` in pyproject.toml)."""
    nodes = [NodeDoc(*entry.name.split("/", 1)) for entry in entry_points(group="dmg.nodes")]
    return sorted(nodes, key=lambda node: node.executable)


def _cell(value: Any) -> str:
    if isinstance(value, str):
        text = f"`{value}`" if value else '`""`'
    elif isinstance(value, bool):
        text = f"`{str(value).lower()}`"
    elif isinstance(value, list):
        text = "`[" + ", ".join(str(item) for item in value) + "]`"
    else:
        text = f"`{value}`"
    return text.replace("|", "\\|")


def parameter_table(config: str) -> str:
    """A Markdown table of every parameter in config/<config>.yaml, in the file's order."""
    rows = ["| parameter | default | range | set | description |", "|---|---|---|---|---|"]
    for name, entry in load_parameter_spec(config).items():
        low_high = entry.get("range")
        span = f"{low_high[0]} … {low_high[1]}" if low_high else ""
        when = "at start" if entry.get("read_only") else "any time"
        description = " ".join(str(entry.get("description", "")).split()).replace("|", "\\|")
        rows.append(f"| `{name}` | {_cell(entry['value'])} | {span} | {when} | {description} |")
    return "\n".join(rows)


def render(page_text: str, config: str) -> str:
    """`page_text` with the table between its parameter markers made from config/<config>.yaml."""
    begin = BEGIN.format(config=config)
    pattern = re.compile(re.escape(begin) + r"\n.*?" + re.escape(END), re.DOTALL)
    if not pattern.search(page_text):
        raise ValueError(f"no parameter markers for config/{config}.yaml: the page needs the lines\n{begin}\n{END}")
    return pattern.sub(lambda _: f"{begin}\n{parameter_table(config)}\n{END}", page_text, count=1)


def stale_pages() -> list[Path]:
    """Node pages whose parameter table differs from their YAML (or that are missing)."""
    stale = []
    for node in project_nodes():
        if not node.page.exists() or render(node.page.read_text(), node.config) != node.page.read_text():
            stale.append(node.page)
    return stale


def run(args: argparse.Namespace) -> int:
    if args.check:
        stale = stale_pages()
        for page in stale:
            print(f"dmg docs: {page.relative_to(REPO_ROOT)} is out of date: run `dmg docs`")
        return 1 if stale else 0
    for node in project_nodes():
        try:
            text = node.page.read_text()
            node.page.write_text(render(text, node.config))
        except (OSError, ValueError) as exc:
            print(f"dmg docs: error: {node.page.relative_to(REPO_ROOT)}: {exc}")
            return 2
        print(f"dmg docs: {node.page.relative_to(REPO_ROOT)} <- config/{node.config}.yaml")
    return 0


def register(subparsers) -> None:
    parser = subparsers.add_parser("docs", help="write the node pages' parameter tables from config/<node>.yaml")
    parser.add_argument("--check", action="store_true", help="only report pages that are out of date (exit 1)")
    parser.set_defaults(handler=run)
