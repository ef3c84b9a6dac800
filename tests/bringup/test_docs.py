"""The documentation is true of the code: links resolve, every node page names what the running node
declares, parameter tables match config/, and no page carries development history."""
from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from conftest import DMG, REPO, RosTestNode
from dmg_bringup.docs import project_nodes, stale_pages

PAGES = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]
FENCED_CODE = re.compile(r"^(```|~~~).*?^\1", re.MULTILINE | re.DOTALL)
INLINE_CODE = re.compile(r"`[^`\n]*`")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
# A numbered step of past work, a work branch, or an issue number: history belongs in git, not in the docs.
HISTORY = re.compile(r"\bstops?\s+\d+(?![.\d]|\s*(?:mm|cm|m|ms|s|deg|°|%|N|px)\b)|\bwip/|\bissue\s+#?\d+"
                     r"|\btried and not kept\b", re.IGNORECASE)


def _prose(text: str) -> str:
    """Markdown without code blocks and inline code (links inside code are examples, not links)."""
    return INLINE_CODE.sub("", FENCED_CODE.sub("", text))


def _anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*]|<[^>]+>", "", heading.strip().lower())
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    headings = re.findall(r"^#{1,6}\s+(.+?)\s*#*$", FENCED_CODE.sub("", page.read_text()), re.MULTILINE)
    return {_anchor(h) for h in headings}


def test_pages_exist():
    assert (REPO / "docs").is_dir()
    assert len(PAGES) > 10, [p.name for p in PAGES]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_resolves(page):
    broken = []
    for target in LINK.findall(_prose(page.read_text())):
        if re.match(r"^[a-z]+:", target):  # http(s), mailto: not ours to check offline
            continue
        path_part, _, anchor = target.partition("#")
        resolved = (page.parent / path_part).resolve() if path_part else page
        if not resolved.exists():
            broken.append(f"{target}: no {resolved}")
        elif anchor and resolved.suffix == ".md" and anchor not in _anchors(resolved):
            broken.append(f"{target}: no heading #{anchor} in {resolved.name}")
    assert not broken, f"{page.relative_to(REPO)}: " + "; ".join(broken)


@pytest.mark.parametrize("path", [*PAGES, *sorted((REPO / "config").rglob("*.yaml"))],
                         ids=lambda p: str(p.relative_to(REPO)))
def test_no_development_history(path):
    hits = [line.strip()[:120] for line in path.read_text().splitlines() if HISTORY.search(line)]
    assert not hits, f"{path.relative_to(REPO)} mentions work history: {hits}"


def test_history_pattern_catches_what_it_is_for():
    assert HISTORY.search("measured at stop 37 on the box")
    assert HISTORY.search("kept on wip/edge-corners")
    assert HISTORY.search("the look (stop 44) and issue #9")
    assert not HISTORY.search("the push stops 2 mm short; a stop of 3 s; it stops 0.5 s later")


def test_readme_is_short_and_starts_with_the_two_commands():
    text = (REPO / "README.md").read_text()
    assert len(text.splitlines()) <= 300
    first_block = FENCED_CODE.search(text).group(0)
    commands = [line.split("#")[0].strip() for line in first_block.splitlines()[1:-1] if line.split("#")[0].strip()]
    assert commands == ["make demo", "make test"], commands


def test_readme_links_every_node_page():
    links = set(LINK.findall((REPO / "README.md").read_text()))
    nodes = project_nodes()
    assert {n.executable for n in nodes} == {"planner_node", "perception_node", "executor_node", "sim_bridge_node"}
    missing = [n.page for n in nodes if f"docs/nodes/{n.page.name}" not in links]
    assert not missing, f"README.md does not link {missing}"


def test_parameter_tables_match_config():
    assert not stale_pages(), "run `dmg docs` to regenerate the parameter tables"


# --- the running nodes against their pages -----------------------------------------------------------------

# What every rclpy node has, which no page needs to name.
INFRASTRUCTURE_TOPICS = {"/rosout", "/parameter_events"}
PARAMETER_SERVICES = ("describe_parameters", "get_parameter_types", "get_parameters", "get_type_description",
                      "list_parameters", "set_parameters", "set_parameters_atomically")
INFRASTRUCTURE_PARAMETERS = {"use_sim_time", "start_type_description_service"}


def _declared(probe, name: str) -> dict[str, set[str]]:
    """The topics, services and actions the node `name` has in the live ROS graph."""
    from rclpy.action import get_action_client_names_and_types_by_node, get_action_server_names_and_types_by_node

    node = probe.node
    names = {
        "publishes": {t for t, _ in node.get_publisher_names_and_types_by_node(name, "/")},
        "subscribes": {t for t, _ in node.get_subscriber_names_and_types_by_node(name, "/")},
        "serves": {s for s, _ in node.get_service_names_and_types_by_node(name, "/")},
        "calls": {s for s, _ in node.get_client_names_and_types_by_node(name, "/")},
        "action server": {a for a, _ in get_action_server_names_and_types_by_node(node, name, "/")},
        "action client": {a for a, _ in get_action_client_names_and_types_by_node(node, name, "/")},
    }
    def own_infrastructure(n: str) -> bool:
        return (n in INFRASTRUCTURE_TOPICS or "/_action/" in n
                or (n.startswith(f"/{name}/") and n.rsplit("/", 1)[-1] in PARAMETER_SERVICES))

    names = {kind: {n for n in found if not own_infrastructure(n)} for kind, found in names.items()}
    # A node on simulated time subscribes to /clock through rclpy's time source, not by its own code.
    names["subscribes"].discard("/clock")
    return names


def _parameters(probe, name: str) -> set[str]:
    from rcl_interfaces.srv import ListParameters

    client = probe.node.create_client(ListParameters, f"/{name}/list_parameters")
    response = probe.call(client, ListParameters.Request())
    return {p for p in response.result.names if p not in INFRASTRUCTURE_PARAMETERS and not p.startswith("qos_overrides")}


@pytest.mark.ros
@pytest.mark.sim
def test_node_pages_name_every_interface_and_parameter_of_the_running_nodes(processes, tmp_path):
    nodes = project_nodes()
    entries = []
    for node in nodes:
        parameters = {} if node.package == "dmg_sim_bridge" else {"use_sim_time": True}
        if node.config == "perception":
            parameters["debug_image"] = True  # its optional topic is documented too
        entries.append({"name": node.config, "package": node.package, "executable": node.executable,
                        "parameters": parameters})
    launch = tmp_path / "cell.yaml"
    launch.write_text(yaml.safe_dump({"nodes": entries}))
    cell = processes.start_logged("cell", [DMG, "up", "--config", str(launch)])
    probe = RosTestNode("docs_probe")
    try:
        expected = {n.config for n in nodes}
        probe.wait_for(lambda: expected <= set(probe.node.get_node_names()), timeout=120, what=f"nodes {expected}")
        parameters = {node.config: _parameters(probe, node.config) for node in nodes}  # each node is spinning
        probe.spin(3.0)  # and every endpoint of theirs is discovered
        gaps = []
        for node in nodes:
            declared = _declared(probe, node.config)
            assert declared["publishes"], f"{node.config}: no publishers seen"
            page = node.page.read_text()
            for kind, names in declared.items():
                gaps += [f"{node.page.name}: {kind} `{n}`" for n in sorted(names) if f"`{n}`" not in page]
            gaps += [f"{node.page.name}: parameter `{p}`" for p in sorted(parameters[node.config]) if f"`{p}`" not in page]
        assert not gaps, "undocumented:\n" + "\n".join(gaps)
    finally:
        probe.close()
        assert cell.poll() is None, processes.output(cell)
