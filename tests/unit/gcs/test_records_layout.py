"""The shipped Foxglove layout (docs/foxglove/swarm-layout.json) is what
gcs.records.layout builds for cube8, and its panels name topics the record writes."""

from __future__ import annotations

import json

import pytest
from conftest import CUBE8, ROOT

from gcs.records import topics as tp
from gcs.records.layout import layout_json
from offboard.estimation.bearing import formation_from_scenario
from swarm_common.scenario.model import load_scenario

pytestmark = pytest.mark.unit
SHIPPED = ROOT / "docs" / "foxglove" / "swarm-layout.json"


def _panels(node: dict) -> list[dict]:
    if node.get("type") == "panel":
        return [node]
    return [p for it in node.get("items", []) for p in _panels(it["content"])]


def test_shipped_layout_is_generated_and_names_record_topics() -> None:
    sc = load_scenario(CUBE8)
    form = formation_from_scenario(sc)
    followers = [int(sc.ids[f]) for f in form.follower_idx]
    assert SHIPPED.read_text() == layout_json(followers)
    doc = json.loads(SHIPPED.read_text())
    panels = {p["panelType"]: p for p in _panels(doc["content"])}
    assert set(panels) == {"ThreeDee", "Plot", "Log"}
    topics = tp.all_topics(list(sc.ids))
    assert set(panels["ThreeDee"]["config"]["topics"]) <= set(topics)
    assert panels["Log"]["config"]["topicToRender"] == tp.EVENTS
    plots = [p for p in _panels(doc["content"]) if p["panelType"] == "Plot"]
    values = [s["value"] for p in plots for s in p["config"]["paths"]]
    assert f"{tp.PAIRS}.min_distance_m" in values and f"{tp.PAIRS}.min_h_m2" in values
    for v in values:  # every series is topic.field of a topic and a field the record has
        topic, field = v.rsplit(".", 1)
        assert topic in topics
        names = {n for n, _, _ in {tp.ESTIMATE_SCHEMA: tp.ESTIMATE_FIELDS,
                                   tp.QP_SCHEMA: tp.QP_FIELDS}.get(topics[topic],
                                                                   tp.pairs_fields(1))}
        assert field in names
    assert sum(v.endswith(".p_err_m") for v in values) == len(followers)
    assert sum(v.endswith(".correction_m_s2") for v in values) == len(followers)
