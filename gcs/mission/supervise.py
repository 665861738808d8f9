"""Watching a started distributed run (:func:`gcs.mission.distributed.run_distributed`)
until its last step: the recorder drained, the progress shown, a daemon's death recorded
(the others fly on), the simulator's death or a stall ended with :class:`MissionError`
(a busy port with :class:`~gcs.mission.launch_spec.LaunchError`), a daemon killed on
purpose (``--kill-agent``), checkpoints written, and the start-up timed apart from the
stepping.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from gcs.mission.launch_spec import LaunchError
from gcs.mission.ports import PortUse, bind_failure_line
from gcs.mission.procs import ProcessGroup, role_of, stall_cause
from gcs.mission.progress import Progress
from gcs.mission.recorder import Recorder
from offboard.daemon.packing import parse_agents

log = logging.getLogger(__name__)


class MissionError(RuntimeError):
    """A run failed once started: a child died or the run stalled (exit 1). ``str()``
    names the culprit."""


STARTUP_TIMEOUT_S = 90.0  # wall: the start-up (to step 1) may take at least this long
STARTUP_PER_PROCESS_S = 10.0  # wall, per child: its interpreter, imports and kernels


def startup_timeout_s(processes: int) -> float:
    """How long the start-up may take (wall s, from the start to step 1: every daemon
    ready and the simulator's barrier at t_0 passed): :data:`STARTUP_TIMEOUT_S`, or
    :data:`STARTUP_PER_PROCESS_S` per child process when that is longer (64 daemons,
    one per agent, start in about 2 minutes on 2 loaded cores)."""
    return max(STARTUP_TIMEOUT_S, STARTUP_PER_PROCESS_S * processes)


CHECKPOINT_EVERY_S = 10.0  # wall: metrics.json + series.npz so far, marked aborted
RUNNER_NAME = "gcs (router + recorder)"  # this process, in the run facts' process table
STATE_EVERY_S = 1.0  # wall seconds between looks for stopped children (/proc)


def supervise(
    rec: Recorder,
    group: ProcessGroup,
    dt: float,
    victim: str | None,
    kill_agent: int | None,
    kill_at: float | None,
    bar: Progress | None,
    stall_timeout: float,
    out_dir: Path,
    on_step: Callable[[int], None] | None,
    facts: dict[str, Any],
    checkpoint: Callable[[], None] | None = None,
    ports_of: Callable[[str], list[PortUse]] | None = None,
) -> dict[str, Any]:
    """Watch a started run until step ``rec.steps``: drain the recorder, show progress,
    kill the process ``victim`` (the one of ``kill_agent``) at ``kill_at`` (s), add a dead
    daemon's agents to ``facts["failed_agents"]`` (the others fly on), raise
    :class:`MissionError` when the simulator dies or the run stalls, call ``checkpoint`` every
    :data:`CHECKPOINT_EVERY_S` (or 20 times its own cost, if longer). Returns the timing
    facts (``run_wall_s``, ``stepping_wall_s``, ``stepping_realtime_factor``, and
    ``processes_at_first_step`` / ``steps_from_first``: each process's CPU when stepping
    began, so that the stepping cost can be told from the start-up)."""
    out: dict[str, Any] = {}
    startup_limit = startup_timeout_s(len(group.children))
    failed: list[int] = facts["failed_agents"]
    last_k = -1
    last_change = t_run0 = next_ckpt = next_state = time.monotonic()
    next_ckpt += CHECKPOINT_EVERY_S
    t_first: float | None = None
    k_first = 0
    try:
        while True:
            time.sleep(0.05)
            rec.drain()
            with rec.lock:
                k = rec.max_step
            if k >= 1 and t_first is None:
                t_first, k_first = time.monotonic(), k
                # CPU so far (start-up): what the stepping cost is measured from
                out["steps_from_first"] = rec.steps - k_first
                out["processes_at_first_step"] = {
                    **group.usage(),
                    RUNNER_NAME: {"cpu_s": time.process_time(), "peak_rss_mib": 0.0},
                }
            if k != last_k:
                last_change, last_k = time.monotonic(), k
                if bar is not None:
                    bar.update(max(k, 0) * dt)
            if k >= rec.steps:
                break
            if on_step is not None:
                on_step(k)
            if victim is not None and not facts["killed_agents"] and k * dt >= (kill_at or 0.0):
                group.kill(victim)
                facts["killed_agents"].append(kill_agent)
            _check_children(group, failed, max(k, 0) * dt, ports_of)
            if time.monotonic() >= next_state:  # stopped children: named, once each
                next_state = time.monotonic() + STATE_EVERY_S
                group.warn_stopped(facts, max(k, 0) * dt)
            if failed and k < 1:  # the start barrier waits for every vehicle: it never passes
                raise early_death(group, failed, ports_of)
            # the start-up, to step 1: the simulator offers t_0 (truth of step 0) until
            # every daemon is up and answers in OFFBOARD (its barrier)
            limit = stall_timeout if k >= 1 else max(stall_timeout, startup_limit)
            if time.monotonic() - last_change > limit:
                raise MissionError(
                    f"run stalled at step {k} for {limit:.0f} s: {stall_cause(group)}; "
                    f"see logs in {out_dir}"
                )
            if checkpoint is not None and time.monotonic() >= next_ckpt:
                t0 = time.monotonic()
                checkpoint()
                next_ckpt = time.monotonic() + max(CHECKPOINT_EVERY_S,
                                                   20.0 * (time.monotonic() - t0))
    finally:
        if bar is not None:
            bar.close()
    out["run_wall_s"] = time.monotonic() - t_run0
    if t_first is not None:
        stepping = time.monotonic() - t_first
        out["stepping_wall_s"] = stepping
        out["stepping_realtime_factor"] = (rec.steps - k_first) * dt / stepping
    return out


def _check_children(
    group: ProcessGroup, failed: list[int], t: float,
    ports_of: Callable[[str], list[PortUse]] | None = None,
) -> None:
    """A dead daemon: its agent joins ``failed`` (once, with a warning naming its log and
    the cause); a dead simulator ends the run: :class:`MissionError` with the cause (the
    last error line of its log), or :class:`LaunchError` when that cause is a busy port."""
    for child in group.dead():
        if not child.name.startswith("offboard-"):
            cause = group.cause(child)
            busy = _busy_port_error(child.name, cause, child.log_path, ports_of)
            if busy is not None:
                raise busy
            raise MissionError(
                f"{role_of(child.name)} died at t = {t:.2f} s: {group.fault(child)} "
                f"(log: {child.log_path})"
            )
        for aid in parse_agents(child.name.removeprefix("offboard-")):
            if aid not in failed:
                failed.append(aid)
                then = "the run goes on without it" if t > 0 else "before the start"
                log.warning("agent %d's daemon exited at t = %.2f s, %s: %s (see %s)",
                            aid, t, then, group.fault(child), child.log_path)


def early_death(
    group: ProcessGroup, failed: list[int], ports_of: Callable[[str], list[PortUse]] | None,
) -> Exception:
    """The one-line error of daemons dead before the start: the first one's cause (the last
    error line of its log) and log; a :class:`LaunchError` when the cause is a busy port."""
    dead = [c for c in group.dead() if c.name.startswith("offboard-")]
    first = dead[0] if dead else None
    cause = "" if first is None else group.cause(first)
    if first is not None:
        busy = _busy_port_error(first.name, cause, first.log_path, ports_of)
        if busy is not None:
            return busy
    where = "" if first is None else f": {cause} (log: {first.log_path})"
    return MissionError(
        f"the daemon of agent(s) {', '.join(map(str, failed))} exited before the start"
        f"{where}; the simulator starts when every vehicle is armed in OFFBOARD, so the run "
        "cannot start"
    )


def _busy_port_error(
    name: str, cause: str, log_path: Path, ports_of: Callable[[str], list[PortUse]] | None,
) -> LaunchError | None:
    """A :class:`LaunchError` (exit 2) when ``cause`` says a port of child ``name`` was in
    use (:func:`~gcs.mission.ports.bind_failure_line`); None for any other cause."""
    if ports_of is None:
        return None
    line = bind_failure_line(name, cause, log_path, ports_of(name))
    return None if line is None else LaunchError(line)
