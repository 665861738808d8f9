"""One run of a sweep: the job, its inputs checked, and the run itself.

:class:`Job` (scenario path and text, method, seed, duration, allow flags; ``key`` names
it), the command-line parsers (:func:`parse_seeds`, :func:`parse_methods`,
:func:`parse_jobs`, :func:`parse_duration`, :func:`parse_address`; bad input is a
:class:`SweepInputError`, one line), :func:`make_jobs`, and
:func:`run_job`: one :func:`gcs.mission.inproc.run_inproc` of the scenario built from its text
(:func:`swarm_common.scenario.model.scenario_from_text`: a file's validation, no shared files
on a worker) to its CSV row (an exception is a ``crashed`` row, never lost).
"""

from __future__ import annotations

import logging
import os
import re
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gcs.report.sweep import flat_row
from swarm_common.enums import Method
from swarm_common.inputs import SEED_MAX, finite_float
from swarm_common.scenario.files import read_scenario_text
from swarm_common.scenario.model import (
    Scenario,
    ScenarioError,
    load_scenario,
    scenario_from_text,
)

log = logging.getLogger(__name__)


class SweepInputError(ValueError):
    """Bad command-line input of the sweep (exit 2); ``str()`` is the one-line reason."""


MAX_SWEEP_SEEDS = 100_000  # as gcs mission compare --seeds
MAX_SWEEP_JOBS = 256  # as gcs mission compare --jobs
MAX_SWEEP_DURATION_S = 3600.0  # as scenario.duration_s
CLUSTER_ADDRESS = re.compile(r"^(tcp|tls)://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+):(\d{1,5})$")


@dataclass(frozen=True)
class Job:
    """One run of the sweep."""

    path: str  # scenario file
    scenario: str  # scenario name
    method: str
    seed: int
    duration_s: float
    allow_infeasible: bool = False  # --allow-infeasible: load the scenario with a warning
    allow_unsafe: bool = False  # --allow-unsafe: load it with a warning per broken assumption
    text: str | None = None  # the scenario file's text (None: the worker reads ``path``)

    @property
    def key(self) -> tuple[str, str, int]:
        """(scenario, method, seed): the run's identity in runs.csv."""
        return (self.scenario, self.method, self.seed)


def parse_seeds(text: str) -> list[int]:
    """``"1-100"`` (inclusive range) or ``"1,4,9"`` (list) → seeds ≥ 0, in order, no repeats."""
    text = text.strip()
    try:
        if "," not in text and "-" in text:
            lo_s, hi_s = text.split("-", 1)
            lo, hi = int(lo_s), int(hi_s)
            if lo > hi:
                raise SweepInputError(f"--seeds {text!r}: empty range ({lo} > {hi})")
            if hi - lo >= MAX_SWEEP_SEEDS:  # checked before the list is built
                raise SweepInputError(f"--seeds {text!r}: more than {MAX_SWEEP_SEEDS} seeds")
            seeds = list(range(lo, hi + 1))
        else:
            seeds = [int(s) for s in text.split(",")]
    except ValueError as exc:
        if isinstance(exc, SweepInputError):
            raise
        raise SweepInputError(
            f"--seeds {text!r}: expected a range like 1-100 or a list like 1,4,9"
        ) from None
    if any(not 0 <= s <= SEED_MAX for s in seeds):
        raise SweepInputError(f"--seeds {text!r}: seeds must be in 0..{SEED_MAX}")
    if len(seeds) > MAX_SWEEP_SEEDS:
        raise SweepInputError(f"--seeds {text!r}: more than {MAX_SWEEP_SEEDS} seeds")
    return list(dict.fromkeys(seeds))


def parse_methods(text: str) -> list[str]:
    """``"rcbf,apf,none"`` → the methods, each a :class:`~swarm_common.enums.Method`."""
    names = [m.strip() for m in text.split(",") if m.strip()]
    known = [str(m) for m in Method]
    bad = [m for m in names if m not in known]
    if bad or not names:
        raise SweepInputError(
            f"--methods {text!r}: unknown method {', '.join(bad) or '(none given)'}; "
            f"choose from {','.join(known)}"
        )
    return list(dict.fromkeys(names))


def parse_jobs(text: str | None) -> int:
    """``--jobs``: a positive integer; None → ``os.cpu_count()``."""
    if text is None:
        return os.cpu_count() or 1
    try:
        jobs = int(text)
    except ValueError:
        raise SweepInputError(f"--jobs {text!r}: not an integer") from None
    if not 1 <= jobs <= MAX_SWEEP_JOBS:
        raise SweepInputError(f"--jobs {text!r}: must be in 1..{MAX_SWEEP_JOBS}")
    return jobs


def parse_duration(text: str | None) -> float | None:
    """``--duration``: seconds > 0 and finite; None → each scenario's ``run.duration_s``."""
    if text is None:
        return None
    v = finite_float(text)
    if v is None or not 0 < v <= MAX_SWEEP_DURATION_S:
        raise SweepInputError(f"--duration {text!r}: must be a finite number of seconds in "
                              f"(0, {MAX_SWEEP_DURATION_S:g}]")
    return v


def parse_address(text: str) -> str:
    """``tcp://HOST:PORT`` (or ``tls://``), port 1..65535; else :class:`SweepInputError`."""
    m = CLUSTER_ADDRESS.match(text.strip())
    if m is None or not 1 <= int(m.group(3)) <= 65535:
        raise SweepInputError(f"--cluster {text!r}: expected a scheduler address such as "
                              "tcp://HOST:8786")
    return text.strip()


def load_all(
    paths: list[str], allow_infeasible: bool = False, allow_unsafe: bool = False
) -> list[tuple[str, str, Scenario]]:
    """Read and load every scenario file up front (a bad one is bad input, before any run):
    (path, text, scenario) each; the workers get the text. Two files of one
    ``scenario.name`` (or one file given twice) are bad input too: runs.csv keys a run by
    (scenario name, method, seed), so the second file's runs would be run and dropped."""
    out = []
    named: dict[str, str] = {}
    for p in paths:
        try:
            text = read_scenario_text(Path(p))
            sc = scenario_from_text(text, p, allow_infeasible, allow_unsafe)
        except ScenarioError as exc:
            raise SweepInputError(str(exc).replace("\n", " ")) from None
        if sc.name in named:
            raise SweepInputError(
                f"{p}: scenario.name = {sc.name!r}, as {named[sc.name]}: a sweep keys its "
                "runs by scenario name; give each file its own name (or list it once)")
        named[sc.name] = p
        out.append((p, text, sc))
    return out


def make_jobs(
    scenarios: list[tuple[str, str, Scenario]], methods: list[str], seeds: list[int],
    duration: float | None,
) -> list[Job]:
    return [
        Job(p, sc.name, m, s, float(sc.run.duration_s if duration is None else duration),
            sc.allow_infeasible, sc.allow_unsafe, text)
        for p, text, sc in scenarios for m in methods for s in seeds
    ]


def run_job(job: Job) -> dict[str, Any]:
    """Worker: one in-process run → its CSV row; an exception becomes a ``crashed`` row
    (logged with its traceback in the worker)."""
    from gcs.mission.inproc import run_inproc

    base = {"scenario": job.scenario, "method": job.method, "seed": job.seed,
            "duration_s": job.duration_s}
    t0 = time.perf_counter()
    try:
        if job.text is None:
            sc = load_scenario(job.path, job.allow_infeasible, job.allow_unsafe)
        else:
            sc = scenario_from_text(job.text, job.path, job.allow_infeasible, job.allow_unsafe)
        res = run_inproc(sc, job.method, seed=job.seed, duration=job.duration_s)
    except Exception as exc:  # any failure of a run is logged and recorded, never lost
        log.error("run %s/%s/seed %d crashed:\n%s", job.scenario, job.method, job.seed,
                  traceback.format_exc())
        return {**base, "status": "crashed", "error": _one_line(exc),
                "wall_s": time.perf_counter() - t0}
    return {**base, "status": "ok", "error": "", **flat_row(res.metrics)}


def _one_line(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}".replace("\n", " ")[:500]


def crashed_row(job: Job, exc: BaseException) -> dict[str, Any]:
    """The row of a run whose worker died (killed, out of memory)."""
    return {"scenario": job.scenario, "method": job.method, "seed": job.seed,
            "duration_s": job.duration_s, "status": "crashed", "error": _one_line(exc)}


RowCallback = Callable[[dict[str, Any]], object]


