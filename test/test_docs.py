"""The docs: the parameter reference matches what the nodes declare, the README is short and
starts with its two commands, every relative link resolves, and no page is a diary."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter
from ros_helpers import domain

from rozyn_estimator.ros.estimator_node import EstimatorNode
from rozyn_estimator.ros.recorder_node import BagRecorder
from rozyn_estimator.tools import param_tables
from sim_node.node import SimNode

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), ROOT / "bags" / "README.md"]
BUILT_IN = {"use_sim_time", "start_type_description_service"}


def test_the_parameter_tables_are_generated_from_the_descriptions():
    page = param_tables.PAGE.read_text()
    assert param_tables.render(page) == page, "run: python -m rozyn_estimator.tools.param_tables --write"


@pytest.mark.ros
@pytest.mark.parametrize(("node_class", "table"), [(EstimatorNode, "estimator_node"), (SimNode, "sim_node"),
                                                   (BagRecorder, "bag_recorder")])
def test_nodes_declare_what_the_tables_describe(node_class, table, tmp_path):
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain("docs"))
    try:
        kwargs = {"parameter_overrides": [Parameter("output", value=str(tmp_path / "bag"))]} \
            if node_class is BagRecorder else {}
        node = node_class(context=ctx, **kwargs)
        declared = {name: node.describe_parameter(name) for name in node.get_parameters_by_prefix("")
                    if name not in BUILT_IN}
        node.destroy_node()
    finally:
        rclpy.shutdown(context=ctx)
    described = param_tables.node_parameters()
    expected = {p.name: p for p in described[table]}
    if table != "bag_recorder":
        expected |= {p.name: p for p in described["vehicle"]}
    assert set(declared) == set(expected)
    for name, d in declared.items():
        spec = expected[name].spec
        assert d.description == spec.description + (f" [{spec.unit}]" if spec.unit else ""), name
        assert d.read_only == spec.read_only, name
        assert spec.description and not spec.description.startswith("see "), name


def test_topics_and_commands_are_documented():
    for topic in ("accel/front", "accel/rear", "inertia", "inertia/covariance", "/diagnostics",
                  "sim/ground_truth", "sim/speed", "/clock"):
        assert f"`{topic}`" in README, topic
    first_block = README.split("```bash\n", 1)[1].split("```", 1)[0].splitlines()
    commands = [line.split("#")[0].strip() for line in first_block]
    assert commands == ["scripts/demo", "scripts/test"]  # the two commands, first
    assert "scripts/test" in (ROOT / ".ci" / "run").read_text()  # CI runs the README's command
    for script in re.findall(r"^(scripts/[\w.]+)", README, flags=re.M):
        assert (ROOT / script).exists(), script


def test_the_readme_is_short_and_starts_with_its_two_commands():
    lines = README.splitlines()
    assert len(lines) <= 300, len(lines)
    assert "scripts/demo" in "\n".join(lines[:12]) and "scripts/test" in "\n".join(lines[:12])


def _slug(heading: str) -> str:
    """A heading's anchor as GitHub makes it: lower case, punctuation dropped, spaces to '-'."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.M | re.S)  # no headings in code
    return {_slug(m.group(1)) for m in re.finditer(r"^#{1,6}\s+(.+?)\s*$", text, flags=re.M)}


def _links(page: Path) -> list[str]:
    text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.M | re.S)
    text = re.sub(r"`[^`\n]*`", "", text)  # inline code is not a link
    return re.findall(r"\]\(([^)\s]+)\)", text)


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_every_relative_link_resolves(page):
    broken = []
    for link in _links(page):
        if re.match(r"^[a-z]+:", link):
            continue  # http(s), mailto: not ours to check offline
        path, _, anchor = link.partition("#")
        target = (page.parent / path).resolve() if path else page
        if not target.exists() or (anchor and target.suffix == ".md" and anchor not in _anchors(target)):
            broken.append(link)
    assert not broken, broken


DIARY = re.compile(r"\b(session|today|yesterday|issue \d+|issue's|20\d\d-\d\d-\d\d)\b", re.I)


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_no_page_is_a_development_diary(page):
    """The docs say what is true now: no dates, work periods or issue numbers (history is git's)."""
    found = [line.strip()[:80] for line in page.read_text().splitlines() if DIARY.search(line)]
    assert not found, found
