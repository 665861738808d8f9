"""gcs.scenario_gen: every shape gives a scenario the loader accepts, seeded starts, bad flags."""

from __future__ import annotations

import argparse
import tomllib

import numpy as np
import pytest

from gcs.scenario_gen import (
    JITTER,
    GenError,
    Shape,
    add_scenario_parser,
    build,
    cmd_scenario,
    pick_leaders,
    scrambled_starts,
    vertices,
)
from swarm_common.enums import GraphKind
from swarm_common.scenario.model import dump_toml, parse_scenario


def _args(*argv: str) -> argparse.Namespace:
    ap = argparse.ArgumentParser()
    add_scenario_parser(ap.add_subparsers(dest="command"))
    return ap.parse_args(["scenario", *argv])


def _load(text: str):
    return parse_scenario(tomllib.loads(text), "generated")


@pytest.mark.full
@pytest.mark.parametrize("shape", list(Shape))
@pytest.mark.parametrize(("n", "n_lead"), [(3, 2), (8, 2), (20, 3), (30, 4)])
def test_every_shape_loads(shape: Shape, n: int, n_lead: int) -> None:
    doc, k, _ = build(_args(str(shape), "--agents", str(n), "--leaders", str(n_lead),
                         "--scramble", "3"))
    sc = _load(dump_toml(doc))  # the written text, not the dict, passes every check
    assert sc.n == n and sc.leader_ids == list(range(1, n_lead + 1))
    assert sc.formation.graph is GraphKind.KNN and sc.formation.knn_k == k
    v, p = sc.vertices(), sc.initial_positions()
    d = np.linalg.norm(v[:, None] - v[None], axis=2)[np.triu_indices(n, 1)]
    assert d.min() == pytest.approx(3.0, abs=2e-3)  # default spacing
    assert v[:, 2].min() == pytest.approx(2.0)
    np.testing.assert_array_equal(p[:n_lead], v[:n_lead])  # leaders on their vertices
    dp = np.linalg.norm(p[:, None] - p[None], axis=2)[np.triu_indices(n, 1)]
    assert dp.min() >= (1 - 0.15 - 2 * np.sqrt(3) * JITTER) * 3.0 - 2e-3


def test_grid_sizes_and_leaders_spread() -> None:
    v = vertices(Shape.GRID, 64, 3.0)
    assert len({tuple(x) for x in v}) == 64
    assert np.ptp(v, axis=0).tolist() == [9.0, 9.0, 9.0]  # 4 x 4 x 4
    lead = pick_leaders(v, 2)
    assert np.linalg.norm(v[lead[0]] - v[lead[1]]) == pytest.approx(9.0 * np.sqrt(3))


@pytest.mark.full
def test_scramble_is_seeded() -> None:
    a = _args("grid", "--agents", "27", "--leaders", "4", "--scramble", "7")
    b = _args("grid", "--agents", "27", "--leaders", "4", "--scramble", "8")
    assert dump_toml(build(a)[0]) == dump_toml(build(a)[0])
    sa, sb = (_load(dump_toml(build(x)[0])) for x in (a, b))
    assert not np.allclose(sa.initial_positions(), sb.initial_positions())
    np.testing.assert_array_equal(sa.vertices(), sb.vertices())


def test_mix_and_shrink() -> None:
    sc = _load(dump_toml(build(_args("ring", "--agents", "12", "--leaders", "2",
                                     "--scramble", "1", "--shrink", "0"))[0]))
    err = np.abs(sc.initial_positions() - sc.vertices())
    assert err.max() <= JITTER * 3.0 + 1e-3  # default --mix 0: every follower near its vertex
    v = sc.vertices()
    shrunk = _load(dump_toml(build(_args("ring", "--agents", "12", "--leaders", "2",
                                         "--scramble", "1", "--shrink", "0.3"))[0]))
    r0 = np.linalg.norm(sc.initial_positions()[2:, :2] - v[:, :2].mean(axis=0), axis=1)
    r1 = np.linalg.norm(shrunk.initial_positions()[2:, :2] - v[:, :2].mean(axis=0), axis=1)
    assert np.all(r1 < r0)  # same jitter, pulled toward the centre
    full = _load(dump_toml(build(_args("ring", "--agents", "12", "--leaders", "2",
                                       "--scramble", "1", "--mix", "1"))[0]))
    assert np.abs(full.initial_positions() - full.vertices()).max() > 1.0


def _starts(shape: Shape, n: int, n_lead: int, seed: int) -> tuple[np.ndarray, ...]:
    """(vertices leaders first, starts, the plain shrink rule's starts, which followers
    start unshrunk) of the default shrink 0.15 at spacing 3 m. Every follower is within
    the jitter of its shrunk vertex or else of its vertex (checked); its jitter is read
    back from its start."""
    base = vertices(shape, n, 3.0)
    lead = pick_leaders(base, n_lead)
    v = base[lead + [i for i in range(n) if i not in lead]]
    p = scrambled_starts(v, n_lead, seed, 0.0, 0.15, 3.0)
    c = v.mean(axis=0)
    shrunk = c + 0.85 * (v - c)
    box = JITTER * 3.0 + 1e-3
    # within the jitter of its vertex, not of its shrunk vertex (near the centre both hold)
    unshrunk = np.abs(p - shrunk).max(axis=1) > box
    unshrunk[:n_lead] = False
    assert np.all(np.abs(p - v)[unshrunk].max(axis=1, initial=0.0) <= box)
    jitter = np.where(unshrunk[:, None], p - v, p - shrunk)
    plain = shrunk + jitter
    plain[:n_lead] = v[:n_lead]
    return v, p, plain, unshrunk


def _closest(p: np.ndarray) -> float:
    d = np.linalg.norm(p[:, None] - p[None], axis=2)
    return float(d[np.triu_indices(len(p), 1)].min())


def test_a_follower_the_shrink_puts_on_a_leader_starts_unshrunk() -> None:
    apart = (1 - 0.15 - 2 * np.sqrt(3) * JITTER) * 3.0
    v, p, plain, unshrunk = _starts(Shape.HELIX, 256, 16, 1)
    n_lead = 16
    assert _closest(plain) < 0.5  # the plain rule put a follower on a leader (32 turns)
    assert _closest(p) >= apart - 2e-3
    np.testing.assert_array_equal(p[:n_lead], v[:n_lead])
    assert 0 < unshrunk.sum() < 240  # only the clashing followers (and their clashes)


@pytest.mark.parametrize(("shape", "n", "n_lead"), [(Shape.GRID, 64, 4), (Shape.SPHERE, 100, 6),
                                                    (Shape.HELIX, 24, 3)])
def test_without_a_clash_the_starts_are_the_shrink_rules(shape: Shape, n: int,
                                                         n_lead: int) -> None:
    _, p, plain, unshrunk = _starts(shape, n, n_lead, 5)
    assert not unshrunk.any()
    np.testing.assert_allclose(p, plain, atol=1e-3)


def test_a_scrambled_start_is_sensed_whole_from_the_first_step() -> None:
    """With --mix > 0 followers cross the formation at speeds nothing bounds, so every
    pair is in sensing range from the start: the range is at least the widest pair, at
    the start or in the formation. Without --mix the range is the graph's."""
    def widest(p: np.ndarray) -> float:
        return float(np.max(np.linalg.norm(p[:, None] - p[None, :], axis=-1)))

    for mix in ("0.5", "1"):
        sc = _load(dump_toml(build(_args("grid", "--agents", "27", "--leaders", "3",
                                         "--scramble", "2", "--mix", mix))[0]))
        span = max(widest(sc.initial_positions()), widest(sc.vertices()))
        assert sc.formation.sensing_range_m >= span
    calm = _load(dump_toml(build(_args("grid", "--agents", "27", "--leaders", "3",
                                       "--scramble", "2"))[0]))
    assert calm.formation.sensing_range_m < widest(calm.vertices())
    forced = _load(dump_toml(build(_args("grid", "--agents", "27", "--leaders", "3",
                                         "--scramble", "2", "--mix", "1", "--range", "6"))[0]))
    assert forced.formation.sensing_range_m == 6.0  # --range is the user's: kept


@pytest.mark.full
def test_explicit_k_and_range_graph() -> None:
    doc, k, _ = build(_args("grid", "--agents", "27", "--leaders", "4", "--scramble", "1",
                         "--k", "8"))
    assert k == 8 and doc["formation"]["knn_k"] == 8
    doc, _, _ = build(_args("sphere", "--agents", "20", "--leaders", "3", "--scramble", "1",
                         "--graph", "range", "--range", "7"))
    assert _load(dump_toml(doc)).formation.graph is GraphKind.RANGE


@pytest.mark.parametrize(
    ("argv", "expect"),
    [
        (["grid", "--agents", "2", "--leaders", "1"], "--agents 2"),
        (["grid", "--agents", "8", "--leaders", "8"], "--leaders 8"),
        (["grid", "--agents", "8", "--leaders", "1"], "--leaders 1"),
        (["grid", "--agents", "3000", "--leaders", "4"], "--agents 3000"),
        (["grid", "--agents", "27", "--leaders", "4", "--k", "3"], "knn_k"),
        (["grid", "--agents", "8", "--leaders", "2", "--k", "8"], "--k 8"),
        (["grid", "--agents", "8", "--leaders", "2", "--graph", "range", "--k", "4"], "--k"),
        (["grid", "--agents", "27", "--leaders", "4", "--range", "1"], "sensing_range_m"),
    ],
)
def test_bad_flags_one_line(argv: list[str], expect: str, capsys) -> None:
    args = _args(*argv, "--scramble", "1")
    with pytest.raises(GenError, match=expect.replace("-", r"\-")):
        build(args)
    assert cmd_scenario(args) == 2
    err = capsys.readouterr()
    assert err.out == "" and len(err.err.strip().splitlines()) == 1


@pytest.mark.parametrize(
    "argv",
    [["cone", "--agents", "8", "--leaders", "2", "--scramble", "1"],
     ["grid", "--agents", "8", "--leaders", "2", "--scramble", "-1"],
     ["grid", "--agents", "8", "--leaders", "2", "--scramble", "1", "--spacing", "1.5"],
     ["grid", "--agents", "8", "--leaders", "2", "--scramble", "1", "--shrink", "0.5"]],
)
def test_bad_flag_values_exit_2(argv: list[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        _args(*argv)
    assert exc.value.code == 2


def test_short_range_gets_a_transient_limit_it_allows() -> None:
    """A 27-agent grid at its default range (1.2 × the longest edge, shorter than the
    swarm): the file carries the largest controller.max_transient_speed_mps (a multiple of
    0.05 m/s) that the range allows, and loads with no broken assumption (docs/safety.md
    §5i). A scrambled one is sensed whole (range ≥ its span): no limit is written."""
    from swarm_common.scenario.safety_check import allowed_transient_speed, safety_problems
    from swarm_common.scenario.transient_check import span

    doc, _, _ = build(_args("grid", "--agents", "27", "--leaders", "3", "--scramble", "2"))
    sc = _load(dump_toml(doc))
    v_t = sc.controller.max_transient_speed_mps
    assert sc.formation.sensing_range_m < span(sc)
    assert 0.0 < v_t <= allowed_transient_speed(sc) < v_t + 0.05
    assert safety_problems(sc) == []
    doc, _, _ = build(_args("grid", "--agents", "27", "--leaders", "3", "--scramble", "2",
                         "--mix", "1"))
    sc = _load(dump_toml(doc))
    assert sc.formation.sensing_range_m >= span(sc)
    assert sc.controller.max_transient_speed_mps == 0.0
    assert safety_problems(sc) == []


def test_few_leaders_for_a_large_grid_is_warned_and_still_written(capsys) -> None:
    """125 agents with 4 leaders: the desired-state observer's slowest channel is 0.41 1/s
    (gcs.mission.preflight.observer_problem); the file is written all the same, with one
    warning line. 27 agents with 4 leaders (2.4 1/s) get none."""
    assert cmd_scenario(_args("grid", "--agents", "125", "--leaders", "4", "--scramble", "1")) == 0
    out = capsys.readouterr()
    assert out.err.count("\n") == 1 and out.err.startswith("gcs scenario: warning: grid125")
    assert "decays at 0.41 1/s" in out.err
    assert _load(out.out).n == 125
    assert cmd_scenario(_args("grid", "--agents", "27", "--leaders", "4", "--scramble", "1")) == 0
    assert capsys.readouterr().err == ""


def test_the_knn_search_stops_after_k_tries(monkeypatch) -> None:
    """Without --k the generator tries K_TRIES values of knn_k from DEFAULT_K, each one a
    whole check of the graph, and then refuses in one line naming them (a 2,048-agent ring
    tried k = 6, 7, ... for more than fifteen minutes before)."""
    import gcs.scenario_gen as gen
    from swarm_common.scenario.model import ScenarioError

    tried: list[int] = []

    def never_rigid(doc, where, *args, **kwargs):
        tried.append(int(doc["formation"]["knn_k"]))
        raise ScenarioError(f'{where}: formation.graph = "knn": not rigid')

    monkeypatch.setattr(gen, "parse_scenario", never_rigid)
    with pytest.raises(GenError, match=r"not rigid \(knn_k 6\.\.15 tried; give --k to try "
                       r"another\)$") as err:
        build(_args("ring", "--agents", "40", "--leaders", "4", "--scramble", "1"))
    assert tried == list(range(gen.DEFAULT_K, gen.DEFAULT_K + gen.K_TRIES)) == list(range(6, 16))
    assert "\n" not in str(err.value)
    tried.clear()
    with pytest.raises(GenError, match=r"not rigid$"):  # --k: that one only, no suffix
        build(_args("ring", "--agents", "40", "--leaders", "4", "--scramble", "1", "--k", "7"))
    assert tried == [7]


def test_an_unsafe_file_is_refused_without_a_flag_the_generator_lacks(capsys) -> None:
    """The loader's "pass --allow-unsafe to run it anyway" names a flag of the runs; the
    generator's one line says the file is not written instead."""
    rc = cmd_scenario(_args("ring", "--agents", "40", "--leaders", "3", "--scramble", "1",
                            "--range", "25"))
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    assert "unsafe:" in err[0] and "to run it anyway" not in err[0]
    assert "not written" in err[0] and "--allow-unsafe" in err[0]

