"""The agents of an in-process run, stepped in this process or in several (``--workers``).

:class:`LocalAgents` steps every agent of a run here, one after the other.
:class:`AgentShards` splits the agents into runs of consecutive scenario indices
(:func:`shard_bounds`, balanced by followers): the first run is stepped here, each other
one in a worker process of its own (:func:`serve_shard`), all at the same time, so a
large swarm's step uses every core it is given.

Bit for bit: a worker builds its agents exactly as this process would
(:func:`offboard.agent.factory.make_agent` from the same scenario, method, seed and
formation), and every step hands them the same truth, the same batch of estimates and the
same link state. An agent's step reads nothing of another agent but that batch, so a run
with workers equals a run without one, bit for bit. Each shard returns its step as arrays
(:class:`StepResult`: the commands, the published estimates and the agents' rows as
:class:`~gcs.mission.run_output.FlatRows`), joined here in scenario order; pickling the
outputs themselves cost about 55 µs an agent, as much as a third of its step.

Each worker is a fresh interpreter (``python -c``, :func:`worker_main`) with a socket
to this process; the set-up and every step travel over it pickled (a
:class:`multiprocessing.connection.Connection`). Failure: a worker that raises sends its
traceback and stops; one that dies closes its socket. Either way the run raises
:class:`ShardError` (one line), and :meth:`AgentShards.close` ends every worker. A
worker dies with the process that started it (Linux ``PR_SET_PDEATHSIG``), so none
outlives a killed run.

Entry points: :func:`agent_steppers` (either kind for ``workers``), :func:`workers_for`
(``--workers``), :class:`LocalAgents`,
:class:`AgentShards`, :class:`StepResult`.
"""

from __future__ import annotations

import logging
import os
import signal
import socket
import subprocess
import sys
import traceback
from collections.abc import Sequence
from multiprocessing.connection import Connection
from typing import Any, NamedTuple, Protocol, cast

import numpy as np

from gcs.mission.agents import AUTO_WORKERS, MAX_WORKERS
from gcs.mission.agents.wire_form import published_batch
from gcs.mission.procs import child_log_level, child_pythonpath
from gcs.mission.run_output import FlatRows, flat_rows, join_flat_rows
from offboard.agent.factory import FollowerAgent, LeaderAgent, make_agent
from offboard.agent.landing import LandingPlan
from offboard.estimation.bearing import Formation
from offboard.estimation.peer_table import EstimateBatch
from offboard.records import AgentOutput
from swarm_common.blas import single_thread_blas
from swarm_common.enums import Role
from swarm_common.logsetup import configure_logging
from swarm_common.process_life import die_with_parent, frozen_while
from swarm_common.scenario.model import Scenario

log = logging.getLogger(__name__)

Agent = FollowerAgent | LeaderAgent
# --workers auto shares the agents from this many on (docs/performance.md: 64 agents ran
# 3.15x in one process and 4.64x in two, 27 agents 7.75x and 8.15x)
AUTO_MIN_AGENTS = 64
WORKER_CODE = "from gcs.mission.agents.shards import worker_main; worker_main()"


class ShardError(RuntimeError):
    """A worker of :class:`AgentShards` failed or died (message: one line)."""


class StepResult(NamedTuple):
    """One step of a run of agents, in scenario order."""

    q_ned: np.ndarray  # (n,4) float32 setpoint quaternions (NED, w x y z)
    thrust_norm: np.ndarray  # (n,) float32 normalised thrusts
    published: EstimateBatch  # the estimates as receivers see them (published_batch)
    rows: Sequence[AgentOutput] | FlatRows  # what AgentRows.add records


class AgentSteps(Protocol):
    """What the in-process runner steps: :class:`LocalAgents` or :class:`AgentShards`."""

    landing_started: bool

    def initial(self) -> EstimateBatch: ...
    def gains(self) -> list[str]: ...
    def step(self, k: int, t: float, tp: np.ndarray, tv: np.ndarray, heard: EstimateBatch,
             comm: bool) -> StepResult: ...
    def start_landing(self, plan: LandingPlan) -> None: ...
    def finish(self) -> tuple[np.ndarray, int]: ...
    def close(self) -> None: ...


def join_batches(parts: Sequence[EstimateBatch]) -> EstimateBatch:
    """The batch of the agents of ``parts`` one after the other."""
    return EstimateBatch(*(np.concatenate(f) for f in zip(
        *((b.t, b.rows, b.leader, b.cooperative) for b in parts), strict=True)))


class LocalAgents:
    """``agents`` (consecutive in scenario order) stepped in this process; ``flat``: the
    rows of each step as :class:`FlatRows` (a shard's), else the outputs themselves."""

    def __init__(self, agents: Sequence[Agent], flat: bool = False) -> None:
        self.agents = list(agents)
        self.flat = flat
        self.landing_started = False

    def initial(self) -> EstimateBatch:
        """The agents' estimates before the first step, as published."""
        return published_batch([ag.initial_estimate() for ag in self.agents])

    def gains(self) -> list[str]:
        """The first follower's gains, one line each (none without a follower)."""
        for ag in self.agents:
            if isinstance(ag, FollowerAgent):
                return ag.gains.lines()
        return []

    def step(self, k: int, t: float, tp: np.ndarray, tv: np.ndarray, heard: EstimateBatch,
             comm: bool) -> StepResult:
        """Every agent's step k at ``t`` (s) on the truth and the estimates heard."""
        outs = [ag.step(k, t, tp, tv, heard, comm) for ag in self.agents]
        m = len(outs)
        return StepResult(
            np.concatenate([o.q_ned for o in outs]).reshape(m, 4),
            np.array([o.thrust_norm for o in outs], dtype=np.float32),
            published_batch([o.estimate for o in outs]),
            flat_rows([outs]) if self.flat else outs,
        )

    def start_landing(self, plan: LandingPlan) -> None:
        for ag in self.agents:
            ag.start_landing(plan)
        self.landing_started = True

    def finish(self) -> tuple[np.ndarray, int]:
        """(ζ̂ (m,6) of each agent, zeros for a leader; the followers' fallbacks)."""
        zeta = np.zeros((len(self.agents), 6))
        fallbacks = 0
        for i, ag in enumerate(self.agents):
            if isinstance(ag, FollowerAgent):
                zeta[i] = ag.deso.zeta
                fallbacks += ag.fallbacks
        return zeta, fallbacks

    def close(self) -> None:
        """Nothing to end here."""


def local_agents(sc: Scenario, method: str, seed: int, form: Formation, lo: int, hi: int,
                 flat: bool = False) -> LocalAgents:
    """The agents [lo, hi) of ``sc`` built here, as any process builds them
    (:func:`~offboard.agent.factory.make_agent`: the same bits in each)."""
    return LocalAgents([make_agent(sc, a.id, method=method, seed=seed, form=form)
                        for a in sc.agents[lo:hi]], flat=flat)


def shard_bounds(sc: Scenario, workers: int) -> list[tuple[int, int]]:
    """``workers`` runs [lo, hi) of consecutive scenario indices covering every agent, with
    as even a count of followers as they allow (a leader's step costs a fraction of a
    follower's); fewer runs when there are fewer agents, or when the leaders at either end
    weigh too little to fill one."""
    n = sc.n
    w = max(1, min(int(workers), n))
    weight = np.array([0.1 if a.role is Role.LEADER else 1.0 for a in sc.agents])
    edges = np.searchsorted(np.cumsum(weight), weight.sum() * np.arange(1, w) / w) + 1
    cuts = [0, *sorted({int(e) for e in edges if 0 < e < n}), n]
    return list(zip(cuts[:-1], cuts[1:], strict=True))


def serve_shard(conn: Connection) -> None:
    """A worker's life: take its set-up (scenario, method, seed, formation, the run
    [lo, hi) of agents, the log level), build those agents, report their initial batch,
    then answer each request (a step, the land-all, the gain report, the end) until told
    to finish (module docstring)."""
    try:
        sc, method, seed, form, lo, hi, level = conn.recv()
        configure_logging(level)
        with single_thread_blas():
            shard = local_agents(sc, method, seed, form, lo, hi, flat=True)
            conn.send(("ready", shard.initial()))
            with frozen_while():
                while True:
                    msg = conn.recv()
                    if msg[0] == "step":
                        conn.send(("ok", shard.step(*msg[1:])))
                    elif msg[0] == "land":
                        shard.start_landing(msg[1])
                    elif msg[0] == "gains":
                        conn.send(("ok", shard.gains()))
                    else:
                        conn.send(("ok", shard.finish()))
                        return
    except EOFError:  # the run ended without us
        return
    except Exception as exc:  # reported to the run, which raises it
        conn.send(("error", f"{type(exc).__name__}: {exc}", traceback.format_exc()))


def worker_main() -> None:
    """A worker process's entry (``python -c``, the connection's descriptor in argv[1]):
    it dies with the run that started it, and leaves Ctrl-C to the run (which then closes
    the connection: the worker ends at its next read or write)."""
    die_with_parent(signal.SIGKILL, os.getppid())()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        serve_shard(Connection(int(sys.argv[1])))
    except OSError:  # the run closed the connection while this step was under way
        pass


class AgentShards:
    """The agents in ``len(bounds)`` runs: the first stepped here, each other in a worker
    process (module docstring). Same interface as :class:`LocalAgents`."""

    def __init__(self, sc: Scenario, method: str, seed: int, form: Formation,
                 bounds: Sequence[tuple[int, int]]) -> None:
        lo0, hi0 = bounds[0]
        self.landing_started = False
        self._conns: list[Connection] = []
        self._procs: list[subprocess.Popen[bytes]] = []
        self._names: list[str] = []
        level = child_log_level()
        env = {**os.environ, "PYTHONPATH": child_pythonpath(os.environ.get("PYTHONPATH"))}
        try:
            for lo, hi in bounds[1:]:
                mine, theirs = socket.socketpair()
                # a fresh interpreter, not multiprocessing's spawn: that re-runs the
                # caller's main script, which need not guard itself
                # (safe-path mode and the runner's code first on its path, as every
                # child of a run: gcs.mission.procs.python_entry)
                p = subprocess.Popen(
                    [sys.executable, "-P", "-c", WORKER_CODE, str(theirs.fileno())],
                    pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL, env=env)
                theirs.close()
                conn = Connection(mine.detach())
                self._conns.append(conn)
                self._procs.append(p)
                self._names.append(f"agents {lo}-{hi - 1}")
                self._send((sc, method, seed, form, lo, hi, level), only=len(self._conns) - 1)
            # this process builds its own shard while the workers build theirs
            self.local = local_agents(sc, method, seed, form, lo0, hi0, flat=True)
            ready = [self._answer(i) for i in range(len(self._conns))]
        except BaseException:
            self.close()
            raise
        self._initial = join_batches([self.local.initial(), *(r[0] for r in ready)])

    def _send(self, msg: tuple[Any, ...], only: int | None = None) -> None:
        """``msg`` to every worker, or to worker ``only`` (ShardError if one died)."""
        for i, c in enumerate(self._conns):
            if only is not None and i != only:
                continue
            try:
                c.send(msg)
            except OSError:
                raise self._died(i) from None

    def _died(self, i: int) -> ShardError:
        try:  # its socket closed as it exited: its exit status comes at once
            self._procs[i].wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            pass
        return ShardError(f"agent worker {self._names[i]} died (exit "
                          f"{self._procs[i].returncode})")

    def _answer(self, i: int) -> Any:
        """Worker i's answer to its last request (ShardError if it failed or died)."""
        try:
            msg = self._conns[i].recv()
        except (EOFError, OSError):
            raise self._died(i) from None
        if msg[0] == "error":
            log.error("agent worker %s failed:\n%s", self._names[i], msg[2])
            raise ShardError(f"agent worker {self._names[i]}: {msg[1]}")
        return msg[1] if msg[0] == "ok" else msg[1:]

    def initial(self) -> EstimateBatch:
        return self._initial

    def gains(self) -> list[str]:
        """The first follower's gain report: this process's own shard's, or else asked of
        the workers in order. Every follower of a formation has the same report, and this
        process has it already (the scenario's load checked it), while a worker would
        compute it anew: at 1,024 agents 5.4 s, so a worker is asked only when this
        process holds no follower."""
        for i in range(-1, len(self._conns)):
            if i < 0:
                got = self.local.gains()
            else:
                self._send(("gains",), only=i)
                got = self._answer(i)
            if got:
                return list(got)
        return []

    def step(self, k: int, t: float, tp: np.ndarray, tv: np.ndarray, heard: EstimateBatch,
             comm: bool) -> StepResult:
        """Step k of every shard at once, joined in scenario order."""
        self._send(("step", k, t, tp, tv, heard, comm))
        parts = [self.local.step(k, t, tp, tv, heard, comm)]
        parts += [self._answer(i) for i in range(len(self._conns))]
        return StepResult(
            np.concatenate([p.q_ned for p in parts]),
            np.concatenate([p.thrust_norm for p in parts]),
            join_batches([p.published for p in parts]),
            join_flat_rows([cast(FlatRows, p.rows) for p in parts]),  # every shard's flat
        )

    def start_landing(self, plan: LandingPlan) -> None:
        self._send(("land", plan))
        self.local.start_landing(plan)
        self.landing_started = True

    def finish(self) -> tuple[np.ndarray, int]:
        self._send(("finish",))
        parts = [self.local.finish(), *(self._answer(i) for i in range(len(self._conns)))]
        return np.concatenate([z for z, _ in parts]), sum(f for _, f in parts)

    def close(self) -> None:
        """End every worker (at once if it still runs) and close the pipes."""
        for c in self._conns:
            c.close()
        for p in self._procs:
            try:
                p.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        self._conns, self._procs = [], []


def auto_workers(n: int) -> int:
    """``--workers auto``: 1 below :data:`AUTO_MIN_AGENTS` agents (a step too short to
    share), else one process per CPU this process may run on, at most MAX_WORKERS."""
    if n < AUTO_MIN_AGENTS:
        return 1
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cpus = os.cpu_count() or 1
    return max(1, min(cpus, MAX_WORKERS, n))


def workers_for(spec: int | str, n: int) -> int:
    """The processes ``--workers spec`` gives a run of ``n`` agents: ``auto``
    (:func:`auto_workers`) or the count itself."""
    return auto_workers(n) if spec == AUTO_WORKERS else int(spec)


def agent_steppers(sc: Scenario, method: str, seed: int, form: Formation,
                   workers: int = 1) -> LocalAgents | AgentShards:
    """The run's agents in ``workers`` processes (this one included; 1: all here, as
    :class:`LocalAgents`). ValueError (one line) outside 1..MAX_WORKERS."""
    if not 1 <= int(workers) <= MAX_WORKERS:
        raise ValueError(f"workers: {workers} outside 1..{MAX_WORKERS}")
    bounds = shard_bounds(sc, workers)
    if len(bounds) == 1:
        return local_agents(sc, method, seed, form, 0, sc.n)
    return AgentShards(sc, method, seed, form, bounds)
