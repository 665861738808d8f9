"""The Foxglove layout shipped for records (``docs/foxglove/swarm-layout.json``), built with
foxglove-sdk's layout types (:mod:`foxglove.layouts`): a 3-D panel on ``/scene``,
``/world/tf`` and ``/formation/desired``; a plot of the smallest pair distance and the
smallest barrier h (``/pairs``); a plot of each follower's position-estimate error
(``/agent/<id>/estimate.p_err_m``); a plot of each follower's safety-filter correction
(``/agent/<id>/qp.correction_m_s2``, ‖u − u_nom‖); and a Log panel on ``/events``.

    python -m gcs.records.layout [SCENARIO] > docs/foxglove/swarm-layout.json
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence

import foxglove.layouts as fl

from gcs.records import topics as tp

PALETTE = ("#4e79a7", "#f28e2b", "#e15759", "#76b7b2", "#59a14f", "#edc948", "#b07aa1",
           "#ff9da7", "#9c755f", "#bab0ac")


def swarm_layout(followers: Sequence[int]) -> fl.Layout:
    """The layout for a record whose followers have ids ``followers``."""
    scene = fl.ThreeDeePanel(title="swarm (ENU world)", config=fl.ThreeDeeConfig(
        follow_tf=tp.WORLD_FRAME, fixed_frame=tp.WORLD_FRAME, follow_mode="follow-none",
        topics={tp.SCENE: fl.BaseRendererSceneUpdateTopicSettings(visible=True),
                tp.DESIRED: fl.BaseRendererPosesTopicSettings(visible=True, type="axis",
                                                              axis_scale=0.3)}))
    safety = fl.PlotPanel(title="min distance (m) and min h (m^2)", config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=f"{tp.PAIRS}.min_distance_m", label="min distance (m)",
                             color=PALETTE[0], enabled=True),
               fl.PlotSeries(value=f"{tp.PAIRS}.min_h_m2", label="min h (m^2)",
                             color=PALETTE[2], enabled=True)]))
    est = fl.PlotPanel(title="estimate error ||p_est - p|| (m)", config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=f"{tp.estimate_topic(i)}.p_err_m", label=f"agent {i}",
                             color=PALETTE[k % len(PALETTE)], enabled=True)
               for k, i in enumerate(followers)]))
    corr = fl.PlotPanel(title="filter correction ||u - u_nom|| (m/s^2)", config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=f"{tp.qp_topic(i)}.correction_m_s2", label=f"agent {i}",
                             color=PALETTE[k % len(PALETTE)], enabled=True)
               for k, i in enumerate(followers)]))
    events = fl.LogPanel(title="events", config=fl.LogConfig(topic_to_render=tp.EVENTS,
                                                            min_log_level=1))
    right = fl.SplitContainer(direction="column", items=[
        fl.SplitItem(proportion=1, content=safety), fl.SplitItem(proportion=1, content=est),
        fl.SplitItem(proportion=1, content=corr), fl.SplitItem(proportion=1, content=events)])
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=3, content=scene), fl.SplitItem(proportion=2, content=right)]))


def layout_json(followers: Sequence[int]) -> str:
    """The layout as indented JSON (the shipped file's text)."""
    return json.dumps(json.loads(swarm_layout(followers).to_json()), indent=2) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Print the layout of a scenario's followers (default: scenarios/cube8.toml)."""
    from offboard.estimation.bearing import formation_from_scenario
    from swarm_common.scenario.model import load_scenario

    args = sys.argv[1:] if argv is None else argv
    sc = load_scenario(args[0] if args else "scenarios/cube8.toml")
    form = formation_from_scenario(sc)
    sys.stdout.write(layout_json([int(sc.ids[f]) for f in form.follower_idx]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
