"""``gcs scenario grid|ring|sphere|helix``: formations of any size as scenario files.

``gcs scenario grid --agents 64 --leaders 4 --scramble 1 > grid64.toml`` writes a scenario
that :func:`swarm_common.scenario.model.load_scenario` accepts (docs/scenarios.md, "Generated
formations"):

* **vertices** of the shape, in metres, scaled so that the closest two are ``--spacing`` m
  apart, the lowest ``BASE_ALT_M`` above the ground;
* **leaders** (ids 1..L) spread over the shape by farthest-point sampling, starting on
  their own vertices, so the leaders' separation is the formation's scale (Departure 1);
* a **sparse graph** (``--graph knn`` by default): without ``--k`` the smallest
  ``knn_k`` ≥ ``DEFAULT_K`` (at most ``K_TRIES`` values) whose graph passes the loader's
  rigidity and observability check (docs/graphs.md); the sensing range is the longest
  edge plus ``RANGE_MARGIN``, and
  with ``--mix`` > 0 at least the swarm's span (start or formation) times it;
* **follower starts**, seeded by ``--scramble SEED``: a fraction ``--mix`` (default 0) of
  the followers permuted over each other's vertices, every follower vertex shrunk by
  ``--shrink`` (default 0.15) toward the formation's centroid and moved by a jitter of at
  most ``JITTER`` · spacing per axis. Two follower starts are then at least
  (1 − shrink − 2√3·``JITTER``) · spacing ≥ 0.35 · 2 m apart (above
  ``controller.d_safe_m``). With ``--mix 0`` every graph edge starts about as long as in
  the formation, so the observers sense their graph neighbours from the start; a permuted
  follower starts away from its graph neighbours and its observer has no bearing to them
  until it is back in sensing range (docs/scenarios.md).

Everything else (vehicle, observer and controller gains, the leaders' trajectory) is the
tuned set of ``scenarios/grid27_knn.toml``, but for ``[sensing] noise_draws = "in_range"``:
a sensor draws noise for the agents in its range only, so a step's cost follows the
neighbours, not the swarm's size (docs/scenarios.md). Bad flags: one line on stderr, exit 2.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
from typing import Any

import numpy as np

from gcs.exit_codes import EXIT_USAGE
from swarm_common.enums import GraphKind, Role, Shape
from swarm_common.inputs import one_line
from swarm_common.scenario.files import (
    ALLOW_INFEASIBLE_FLAG,
    ALLOW_UNSAFE_FLAG,
    run_anyway_hint,
    swarm_name_problem,
)
from swarm_common.scenario.model import Scenario, ScenarioError, dump_toml, parse_scenario

# in process; a distributed run takes MAVLink's system ids, 1..255 (Scenario.process_problem)
from swarm_common.scenario.schema import MAX_AGENTS

BASE_ALT_M = 2.0  # lowest vertex altitude (m); the leaders' trajectory only climbs (A_z > 0)
JITTER = 0.1  # start jitter per axis, as a fraction of the spacing
RANGE_MARGIN = 1.2  # sensing range = longest graph edge × this
TRANSIENT_STEP = 0.05  # m/s: the written max_transient_speed_mps is a multiple of this
DEFAULT_K = 6  # first knn_k tried when --k is not given
# the knn_k tried without --k: DEFAULT_K and the K_TRIES - 1 after it. Each try checks the
# graph (at 2,048 agents up to a minute: a ring's spectrum goes dense, docs/graphs.md), and
# the generated shapes that form take at most 10 (a 128-agent ring); past that --k decides
K_TRIES = 10
HELIX_PER_TURN = 8  # vertices per helix turn


GRAPHS = (GraphKind.KNN, GraphKind.RANGE, GraphKind.COMPLETE)


class GenError(ValueError):
    """A flag or flag combination that cannot give a valid scenario (one line)."""


def shape_vertices(shape: Shape, n: int) -> np.ndarray:
    """(n, 3) unscaled vertices of ``shape`` (any units; :func:`vertices` rescales)."""
    if shape is Shape.GRID:
        nx = math.ceil(n ** (1 / 3) - 1e-9)
        ny = math.ceil(math.sqrt(n / nx) - 1e-9)
        pts = [(x, y, z) for z in range(math.ceil(n / (nx * ny)))
               for y in range(ny) for x in range(nx)]
        return np.array(pts[:n], dtype=float)
    k = np.arange(n, dtype=float)
    if shape is Shape.RING:
        a = 2 * math.pi * k / n
        return np.stack([np.cos(a), np.sin(a), np.zeros(n)], axis=1)
    if shape is Shape.SPHERE:
        z = 1 - 2 * (k + 0.5) / n
        r = np.sqrt(1 - z**2)
        a = math.pi * (3 - math.sqrt(5)) * k  # golden angle
        return np.stack([r * np.cos(a), r * np.sin(a), z], axis=1)
    a = 2 * math.pi * k / HELIX_PER_TURN
    radius = 1 / (2 * math.sin(math.pi / HELIX_PER_TURN))  # neighbours 1 apart on the circle
    return np.stack([radius * np.cos(a), radius * np.sin(a), k / HELIX_PER_TURN], axis=1)


def vertices(shape: Shape, n: int, spacing: float) -> np.ndarray:
    """Vertices in metres: closest pair ``spacing`` apart, centred in x/y, lowest at
    ``BASE_ALT_M``; rounded to the millimetre."""
    v = shape_vertices(shape, n)
    d = np.linalg.norm(v[:, None] - v[None], axis=2)
    v = v * (spacing / float(d[np.triu_indices(n, 1)].min()))
    v[:, :2] -= v[:, :2].mean(axis=0)
    v[:, 2] += BASE_ALT_M - v[:, 2].min()
    return np.round(v, 3)


def pick_leaders(v: np.ndarray, n_leaders: int) -> list[int]:
    """Farthest-point sampling from vertex 0: indices of ``n_leaders`` spread vertices."""
    chosen = [0]
    dmin = np.linalg.norm(v - v[0], axis=1)
    while len(chosen) < n_leaders:
        k = int(np.argmax(dmin))
        chosen.append(k)
        dmin = np.minimum(dmin, np.linalg.norm(v - v[k], axis=1))
    return chosen


def scrambled_starts(v: np.ndarray, n_leaders: int, seed: int, mix: float, shrink: float,
                     spacing: float) -> np.ndarray:
    """Start positions (m): leaders (rows < n_leaders) on their vertices; a seeded fraction
    ``mix`` of the followers on each other's vertices (a random permutation of that subset),
    every follower shrunk by ``shrink`` toward the centroid of all vertices and jittered by
    at most ``JITTER``·spacing per axis.

    The shrink keeps followers apart from each other (their distances scale by
    1 − ``shrink``) but not from the leaders, which stay put: on a large or tall shape a
    follower moves metres and may land on a leader (a 256-agent helix put one 0.33 m from a
    leader). Such a follower starts unshrunk, on its own start vertex with the same jitter,
    and so does any shrunk follower then too close to it, until none is
    (:func:`_unshrink_clashes`). Without a clash the starts are those of the plain rule."""
    rng = np.random.default_rng(seed)
    p = v.copy()
    f = np.arange(n_leaders, len(v))
    moved = rng.choice(f, size=int(round(mix * len(f))), replace=False)
    p[moved] = v[rng.permutation(moved)]
    c = v.mean(axis=0)
    jitter = rng.uniform(-JITTER * spacing, JITTER * spacing, size=(len(f), 3))
    unshrunk = p[f] + jitter
    p[f] = c + (1.0 - shrink) * (p[f] - c)
    p[f] += jitter
    apart = (1.0 - shrink - 2.0 * math.sqrt(3.0) * JITTER) * spacing
    if apart > 0.0:
        _unshrink_clashes(p, unshrunk, n_leaders, apart)
    return np.round(p, 3)


def _unshrink_clashes(p: np.ndarray, unshrunk: np.ndarray, n_leaders: int,
                      apart: float) -> None:
    """Move to its ``unshrunk`` start (rows of ``p`` from ``n_leaders`` on) every shrunk
    follower closer than ``apart`` (m) to an agent that is not shrunk (a leader, or a
    follower moved here), until none is. It ends: every follower unshrunk is a start of
    the unshrunk rule, whose agents are about a spacing apart."""
    from scipy.spatial import cKDTree

    fixed = np.zeros(len(p), dtype=bool)
    fixed[:n_leaders] = True
    while True:
        shrunk = np.flatnonzero(~fixed)
        if len(shrunk) == 0:
            return
        near = cKDTree(p[fixed]).query(p[shrunk], distance_upper_bound=apart)[0]
        clash = shrunk[near < apart]
        if len(clash) == 0:
            return
        p[clash] = unshrunk[clash - n_leaders]
        fixed[clash] = True


def _template(name: str, seed: int, duration: float, deadline: float) -> dict[str, Any]:
    """Every section but [formation] and the agents: the tuned set of grid27_knn."""
    return {
        "scenario": {"name": name, "seed": seed, "duration_s": duration, "physics_hz": 200,
                     "control_hz": 50, "formation_deadline_s": deadline},
        "vehicle": {"mass_kg": 1.8, "gravity_mps2": 9.81, "thrust_max_n": 52.92,
                    "tilt_max_deg": 30.0, "tau_rollpitch_s": 0.15, "tau_yaw_s": 0.15,
                    "tau_thrust_s": 0.03, "collision_radius_m": 0.3},
        "disturbance": {"amplitude_n": 0.2, "omega_rad_s": 1.0},
        "unmodeled": {"zeta_nominal": [0.05, 0.10, 0.03, 0.01, 0.50, 0.05],
                      "zeta_spread": 0.2, "ground_effect_height_m": 0.8},
        "leader_trajectory": {"frequency_hz": 0.2, "amplitude_m": [0.8, 0.4, 0.2]},
        "sensing": {"bearing_noise_rad": 0.001, "bearing_rate_noise_radps": 0.002,
                    "distance_noise_m": 0.005, "range_rate_noise_mps": 0.005,
                    "dropout_prob": 0.0, "noise_draws": "in_range"},
        "communication": {"outages_s": [[5.0, 5.5], [15.0, 15.5], [40.0, 40.5]],
                          "max_age_s": 1.0},
        "observer": {"beta": [24.0, 108.0, 108.0], "mu": 0.005, "sigma": 0.15, "substeps": 4,
                     "reference_gain": 4.0, "init_pos_error_m": 0.3,
                     "init_vel_error_mps": 0.1, "leader_anchor": 1.0,
                     "velocity_gain": [1.0, 4.0]},
        "controller": {"method": "dcbf", "kp": 0.5, "kd": 0.1, "clf_lambda": 1.0,
                       "clf_c": 1.0, "rho": 10.0, "u_max_mps2": 8.0, "gamma": 0.6,
                       "tau_safe_s": 0.8, "d_safe_m": 0.5, "apf_gain": 4.0,
                       "apf_velocity_gain": 1.0, "apf_radius_m": 1.5, "leader_kp": 4.0,
                       "leader_kd": 3.0, "ks": 2.0, "deadlock_gain": 1.0,
                       "deadlock_h_m2": 3.0, "dcbf_gamma_lin": 0.3, "dcbf_gamma_cubic": 0.05,
                       "dcbf_accel_error_mps2": 2.0, "dcbf_cone_sides": 8,
                       "dcbf_ground_clearance_m": 0.5},
    }


def _longest_edge(v: np.ndarray, graph: GraphKind, k: int) -> float:
    from swarm_common.scenario import graphs
    spec = graphs.GraphSpec(kind=str(graph), knn_k=k)
    try:
        edges = graphs.build_edges(v, spec, list(range(1, len(v) + 1)))
    except ValueError as exc:  # past the scenario's edge limit: a denser graph won't do
        raise GenError(str(exc)) from None
    return max(float(np.linalg.norm(v[i] - v[j])) for i, j in edges)


def _formation(v: np.ndarray, n_leaders: int, graph: GraphKind, k: int,
               range_m: float | None, span_m: float = 0.0) -> dict[str, Any]:
    """The ``[formation]`` table. Without ``range_m``: every graph edge sensed in the
    formation, with a margin, and at least ``span_m`` (m; a scrambled start's)."""
    fm: dict[str, Any] = {"leaders": list(range(1, n_leaders + 1)), "graph": str(graph)}
    if graph is GraphKind.KNN:
        fm["knn_k"] = k
    if range_m is None:
        need = max(_longest_edge(v, graph, k) * RANGE_MARGIN, span_m)
        range_m = math.ceil(need * 10) / 10
    fm["sensing_range_m"] = range_m
    return fm


def _transient_speed(doc: dict[str, Any], where: str) -> None:
    """Write ``controller.max_transient_speed_mps``: the largest the sensing range allows,
    floored to TRANSIENT_STEP, when pairs come into range in flight (the range is shorter
    than the swarm; docs/safety.md §5i); without it the load check (b) refuses the file.
    A range too short for any limit is a :class:`GenError` naming ``--range``."""
    # the check needs scipy and numba: loaded here, not when gcs builds its parser
    from swarm_common.scenario.safety_check import allowed_transient_speed, pairs_enter

    doc["controller"].pop("max_transient_speed_mps", None)
    off = logging.root.manager.disable
    logging.disable(logging.WARNING)  # the first parse only measures: no warnings
    try:
        sc = parse_scenario(doc, where, allow_unsafe=True)
    finally:
        logging.disable(off)
    if not pairs_enter(sc):
        return
    x = math.floor(allowed_transient_speed(sc) / TRANSIENT_STEP) * TRANSIENT_STEP
    if x <= 0.0:
        raise GenError(f"--range {sc.formation.sensing_range_m:g}: too short for any "
                       "controller.max_transient_speed_mps (docs/safety.md 5i)")
    doc["controller"]["max_transient_speed_mps"] = round(x, 2)


def build(args: argparse.Namespace) -> tuple[dict[str, Any], int, Scenario]:
    """The scenario document of the flags, the knn_k used and the scenario it loads as."""
    # the DESO gain check needs scipy and numba: loaded here, not when gcs builds its parser
    from offboard.estimation.deso_gains import scenario_gain_problem
    from swarm_common.scenario.transient_check import widest

    n, n_lead = args.agents, args.leaders
    if n < 3:
        raise GenError(f"--agents {n}: need at least 3 (2 leaders and a follower)")
    if n > MAX_AGENTS:
        raise GenError(f"--agents {n}: at most {MAX_AGENTS}")
    if n_lead < 2:
        raise GenError(f"--leaders {n_lead}: need at least 2 (they fix the formation's scale)")
    if n_lead >= n:
        raise GenError(f"--leaders {n_lead}: must be below --agents {n} (need a follower)")
    if args.graph is not GraphKind.KNN and args.k is not None:
        raise GenError(f"--k: only read with --graph knn (not {args.graph})")
    if args.k is not None and not 1 <= args.k < n:
        raise GenError(f"--k {args.k}: must be in 1..{n - 1} (below --agents)")
    base = vertices(args.shape, n, args.spacing)
    lead = pick_leaders(base, n_lead)
    v = base[lead + [i for i in range(n) if i not in lead]]  # leaders first: ids 1..L
    starts = scrambled_starts(v, n_lead, args.scramble, args.mix, args.shrink, args.spacing)
    ks = [args.k] if args.k is not None or args.graph is not GraphKind.KNN else \
        list(range(min(DEFAULT_K, n - 1), min(n, DEFAULT_K + K_TRIES)))
    name = f"{args.shape}{n}" if args.name is None else args.name  # "" refused by _name
    doc = _template(name, args.scramble, args.duration, args.deadline)
    doc["agent"] = [{"id": i + 1, "role": str(Role.LEADER if i < n_lead else Role.FOLLOWER),
                     "position": starts[i].tolist(), "velocity": [0.0, 0.0, 0.0],
                     "vertex": v[i].tolist()} for i in range(n)]
    # a scrambled start sends followers across the whole formation, at speeds the scenario
    # does not bound: a pair that first came into range in flight could not brake in time
    # (docs/safety.md, load check (b)), so every pair is sensed from the first step on
    span = widest(v, starts) * RANGE_MARGIN if args.mix > 0.0 else 0.0
    problem = ""
    for k in ks:
        doc["formation"] = _formation(v, n_lead, args.graph, k or DEFAULT_K, args.range, span)
        where = f"{args.shape} --agents {n}"
        try:
            _transient_speed(doc, where)
            sc = parse_scenario(doc, where)
        except ScenarioError as exc:
            problem = str(exc)
            if "formation." not in problem:  # not the graph's fault: no larger k helps
                break
            continue
        # the project's own scenarios pass the DESO gain check too (issue 42: a generated
        # 250-agent sphere was UNSTABLE on its graph); a denser graph may pass it
        unstable = scenario_gain_problem(sc)
        if unstable is not None:
            problem = f"{where}: {unstable}"
            continue
        return doc, k or 0, sc
    else:  # every k tried: a graph or gain problem each time
        if len(ks) > 1:
            problem += f" (knn_k {ks[0]}..{ks[-1]} tried; give --k to try another)"
    raise GenError(_without_run_flags(problem))


def _without_run_flags(problem: str) -> str:
    """The loader's one line with its run-time hint ("pass --allow-unsafe to run it
    anyway", a flag of the runs, not of ``gcs scenario``) replaced by what holds here: the
    generator writes only files that load without it."""
    for flag in (ALLOW_UNSAFE_FLAG, ALLOW_INFEASIBLE_FLAG):
        hint = run_anyway_hint(flag)
        if hint in problem:
            return problem.replace(hint, f"; not written (gcs scenario writes only files "
                                         f"that load without {flag})")
    return problem


def _header(args: argparse.Namespace, k: int) -> str:
    flags = (f"gcs scenario {args.shape} --agents {args.agents} --leaders {args.leaders} "
             f"--scramble {args.scramble} --spacing {args.spacing:g} --mix {args.mix:g} "
             f"--shrink {args.shrink:g} "
             f"--graph {args.graph}" + (f" --k {k}" if args.graph is GraphKind.KNN else ""))
    return (f"# Generated by: {flags}\n"
            "# Vertices in metres (closest pair --spacing apart); leaders are ids 1..L on their\n"
            "# vertices; followers start on their (or, with --mix, permuted) vertices, shrunk\n"
            "# toward the centroid, with a seeded jitter (docs/scenarios.md).\n"
            "# Frames: every vector here is ENU-style world frame, z up (the paper's frame).\n\n")


def _number(lo: float, hi: float, integer: bool) -> Any:
    def parse(text: str) -> float | int:
        try:
            v: float | int = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not (math.isfinite(v) and lo <= v <= hi):
            raise argparse.ArgumentTypeError(f"{text!r}: must be in [{lo:g}, {hi:g}]")
        return v

    return parse


def _name(text: str) -> str:
    """argparse ``type=`` of ``--name``: a valid swarm name (it is every Zenoh key's swarm
    part), refused as the flags are parsed; an empty ``--name`` is refused too, never taken
    as "no name" (the default), which would write a scenario the user did not ask for."""
    if (why := swarm_name_problem(text)) is not None:
        shown = repr(text) if len(text) <= 40 else repr(text[:37]) + "..."
        raise argparse.ArgumentTypeError(one_line(f"{shown}: scenario.name {why}"))
    return text


def cmd_scenario(args: argparse.Namespace) -> int:
    """Write the generated scenario on stdout; exit 2 with one line on a bad flag."""
    try:
        doc, k, sc = build(args)
    except GenError as exc:
        print(f"gcs scenario: {exc}", file=sys.stderr)
        return EXIT_USAGE
    from gcs.mission.preflight import observer_problem  # scipy, numba: not for the parser

    if (slow := observer_problem(sc)) is not None:  # written all the same: a user's choice
        print(f"gcs scenario: warning: {slow}", file=sys.stderr)
    sys.stdout.write(_header(args, k) + dump_toml(doc))
    return 0


def add_scenario_parser(sub: argparse._SubParsersAction) -> None:
    """``gcs scenario SHAPE --agents N --leaders L --scramble SEED [...]``."""
    p = sub.add_parser("scenario", help="write a generated formation scenario on stdout")
    p.add_argument("shape", type=Shape, choices=list(Shape))
    p.add_argument("--agents", type=_number(-1e9, 1e9, True), required=True, metavar="N")
    p.add_argument("--leaders", type=_number(-1e9, 1e9, True), required=True, metavar="L")
    p.add_argument("--scramble", type=_number(0, 2**32 - 1, True), required=True,
                   metavar="SEED", help="seed of the start permutation and jitter (>= 0)")
    p.add_argument("--spacing", type=_number(2.0, 50.0, False), default=3.0, metavar="M",
                   help="metres between the closest two vertices (default 3)")
    p.add_argument("--mix", type=_number(0.0, 1.0, False), default=0.0, metavar="F",
                   help="fraction of the followers whose starts are permuted (default 0)")
    p.add_argument("--shrink", type=_number(0.0, 0.3, False), default=0.15, metavar="F",
                   help="follower starts shrunk toward the centroid by F (default 0.15)")
    p.add_argument("--graph", type=GraphKind, choices=list(GRAPHS), default=GraphKind.KNN)
    p.add_argument("--k", type=int, default=None, metavar="K",
                   help="knn_k (default: the smallest >= 6 that passes the rigidity check)")
    p.add_argument("--range", type=_number(0.1, 1000.0, False), default=None, metavar="M",
                   help="formation.sensing_range_m (default: longest edge x 1.2; with --mix > 0 at "
                   "least the swarm's span x 1.2)")
    p.add_argument("--duration", type=_number(1.0, 3600.0, False), default=60.0, metavar="S")
    p.add_argument("--deadline", type=_number(0.0, 3600.0, False), default=30.0, metavar="S",
                   help="formation_deadline_s: tracking metrics from this time (default 30)")
    p.add_argument("--name", type=_name, default=None,
                   help="scenario.name (default SHAPE + N)")
    p.set_defaults(func=cmd_scenario)
