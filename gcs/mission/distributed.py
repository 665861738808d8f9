"""Distributed mission runs: ``gcs mission run SCENARIO`` without ``--inproc``.

Starts, as real processes: one ``vehicle-sim`` (lockstep by default) and one
``offboard`` daemon per agent; hosts the Zenoh router itself (clients connect to it);
records every step's truth, estimates and statuses from Zenoh; shows a progress bar
(:mod:`gcs.mission.progress`); stops everything at the end, on Ctrl-C, or when a child dies
(naming it, exit 1). Ports and command lines come from :class:`gcs.mission.launch_spec.LaunchSpec`.

Run directory: ``metrics.json``, ``series.npz`` (:mod:`gcs.mission.run_output`),
``vehicle_<id>.tlog`` (each daemon's MAVLink link, readable by pymavlink's tools) and
one ``<process>.log`` per child.
"""

from __future__ import annotations

import json
import logging
import resource
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import zenoh

from gcs.launch import forkserver
from gcs.launch.watchdog import release_dir
from gcs.mission.audit import audit_document
from gcs.mission.launch_spec import (
    LaunchError,
    LaunchSpec,
    SigningChoice,
    secure_dir,
    split_packs,
)
from gcs.mission.live_feed import recorder_hook
from gcs.mission.preflight import check_physics, warn_liveness
from gcs.mission.procs import ProcessGroup
from gcs.mission.progress import Progress
from gcs.mission.recorder import Recorder
from gcs.mission.router import open_router
from gcs.mission.run_logs import lockstep_gaps
from gcs.mission.run_output import warn_verdict, write_run
from gcs.mission.score import (
    default_out_dir,
    recorded_metrics,
    recorder_series,
    score_run,
)
from gcs.mission.step_hooks import each, formation_hook, land_sender
from gcs.mission.supervise import RUNNER_NAME, MissionError, supervise
from gcs.mission.warmup import compile_kernels
from swarm_common.enums import DefaultStreams
from swarm_common.scenario.model import Scenario
from swarm_common.zenoh_session import write_swarm_security

if TYPE_CHECKING:
    from gcs.records.live import LiveView

log = logging.getLogger(__name__)
# scoring lives in gcs.mission.score, the watch of a started run (MissionError) in
# gcs.mission.supervise; these names stay importable from here
__all__ = ["MissionError", "default_out_dir", "recorded_metrics", "recorder_series",
           "run_and_score", "run_distributed"]


AbortHook = Callable[[Recorder, dict[str, Any], str], None]


def run_distributed(
    sc: Scenario,
    out_dir: Path,
    method: str,
    seed: int | None,
    duration: float,
    realtime: bool = False,
    port_offset: int = 0,
    kill_agent: int | None = None,
    kill_at: float | None = None,
    show_progress: bool = True,
    stall_timeout: float = 20.0,
    land_at: float | None = None,
    on_abort: AbortHook | None = None,
    secure: bool = True,
    signing: SigningChoice | None = None,
    processes: int | None = None,
    default_streams: DefaultStreams = DefaultStreams.ALWAYS,
    on_step: Callable[[int], None] | None = None,
    formation_port: int | None = None,
    live: LiveView | None = None,
) -> tuple[Recorder, dict[str, Any]]:
    """Run the mission as real processes; return the recorder and run facts.

    ``land_at``: publish a Zenoh land-all command (``wire.Command`` kind "land", at_s =
    land_at) until the run passes that mission time (docs/lifecycle.md). ``secure``: the
    router authenticates every process (fresh per-run credentials) and enforces the ACL
    (docs/security.md). ``signing``: MAVLink 2 signing of every vehicle link (default: on,
    with a fresh per-run key). ``on_abort(rec, facts, reason)``: called after every child has
    stopped when the run ends early (Ctrl-C, SIGTERM, the simulator's death, a stall),
    and every :data:`~gcs.mission.supervise.CHECKPOINT_EVERY_S` during the run (reason
    "checkpoint").
    ``processes``: pack the daemons into this many processes (None: one per agent;
    :class:`~gcs.mission.launch_spec.LaunchSpec`); a packed process authenticates as one Zenoh
    user that may publish its own agents' keys only. ``default_streams``: the simulator's
    ``--default-streams`` (:class:`~gcs.mission.launch_spec.LaunchSpec`). ``on_step(k)``: called
    by the supervising loop with the newest recorded step, about every 50 ms of wall time
    while the run goes (a script's events at a mission time). ``live``: a live view fed
    the recorded rows (:func:`gcs.mission.live_feed.recorder_hook`).

    Raises :class:`~gcs.mission.launch_spec.LaunchError` before starting anything when a port is
    busy, :class:`MissionError` when the simulator dies or the run stalls. A daemon's
    death is recorded in ``facts["failed_agents"]`` and the run goes on. Every child is
    stopped on the way out, whatever ends the run (Ctrl-C and SIGTERM included).
    """
    if (why := sc.process_problem()) is not None:
        raise LaunchError(why)
    preflight = warn_liveness(sc, method)
    signing = SigningChoice() if signing is None else signing
    sec_dir = secure_dir() if secure or signing.enabled else None
    try:
        sec = None
        if secure and sec_dir is not None:
            packs = split_packs(list(sc.ids), processes) if processes else None
            sec = write_swarm_security(sec_dir, _swarm(sc), sc.ids, packs=packs)
        key_path = signing.key_file(sec_dir)
        spec = LaunchSpec(
            sc, port_offset, method=method, seed=seed, lockstep=not realtime, run_dir=out_dir,
            sim_duration=duration + 1.0, zenoh_security=sec, signing_key=key_path,
            unsigned_gcs_link=signing.unsigned_gcs_link, daemon_processes=processes,
            default_streams=default_streams,
        )
        spec.check_ports()
        check_physics(sc, duration)  # after the flags' checks: their error stays one line
        out_dir.mkdir(parents=True, exist_ok=True)
        router = open_router([spec.router_endpoint],
                             config_file=None if sec is None else sec.router)
    except (RuntimeError, ValueError, OSError) as exc:  # SigningKeyError is a ValueError
        _remove(sec_dir)
        raise LaunchError(str(exc)) from None
    rec = Recorder(sc, int(round(duration * sc.run.control_hz)), seed=seed)
    subs = rec.subscribe(router, spec.swarm_name)
    formation = None
    if formation_port is not None:  # gcs.formation: the formation as one MAVLink vehicle
        try:
            formation = formation_hook(sc, rec, router, spec.swarm_name, formation_port,
                                       key_path)
        except (OSError, ValueError) as exc:  # a busy port, a scenario without a mission
            router.close()
            _remove(sec_dir)
            raise LaunchError(f"formation vehicle on UDP {formation_port}: {exc}") from None
    group = ProcessGroup(out_dir)
    facts: dict[str, Any] = {"failed_agents": [], "killed_agents": [], "aborted": False,
                             "mavlink_signing": signing.describe(),
                             "daemon_processes": len(spec.packs()), "preflight": preflight}
    t_wall0 = time.monotonic()
    cpu0 = time.process_time()
    reason = ""
    try:
        # compile (or load) the kernels once before the children start, so they do not all
        # compile them at once: in the fork server that the children are forked from
        # (gcs.launch.preload), else here, and the children load them from the cache
        # (gcs.mission.warmup)
        if not forkserver.enabled():
            log.debug("kernels ready in %.1f s", compile_kernels())
        for name, argv in spec.processes():
            group.start(name, argv, env=spec.child_env(name), gated=spec.is_daemon(name))
        bar = Progress(duration, label=str(method)) if show_progress else None
        land = None if land_at is None else land_sender(router, spec.swarm_name, land_at,
                                                          sc.control_dt)
        shown = None if live is None else recorder_hook(sc, rec, live)
        hooks = [h for h in (land, on_step, formation and formation[0], shown)
                 if h is not None]
        checkpoint = None if on_abort is None else (lambda: on_abort(rec, facts, "checkpoint"))
        victim = None if kill_agent is None else next(
            spec.daemon_name(p) for p in spec.packs() if kill_agent in p)
        facts.update(
            supervise(rec, group, sc.control_dt, victim, kill_agent, kill_at, bar,
                      stall_timeout, out_dir, each(hooks), facts, checkpoint,
                      spec.child_ports)
        )
        at_first = facts.get("processes_at_first_step", {}).get(RUNNER_NAME)
        if at_first is not None:
            at_first["cpu_s"] -= cpu0
        facts["processes"] = group.usage()
        facts["processes"][RUNNER_NAME] = {
            "cpu_s": time.process_time() - cpu0,
            "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        }
    except KeyboardInterrupt:
        reason = "interrupted (SIGINT)"
        raise
    except SystemExit as exc:
        reason = f"terminated (exit {exc.code})"
        raise
    except MissionError as exc:
        reason = str(exc).splitlines()[0]
        raise
    finally:
        group.stop()
        rec.finalize()  # what the subscribers' channels still hold, before undeclaring
        for s in subs:
            try:
                s.undeclare()
            except zenoh.ZError as exc:
                log.debug("undeclare subscriber: %s", exc)
        if formation is not None:
            formation[1].close()
            facts["formation_commands"] = [c.kind for c in formation[1].sent_commands]
        router.close()
        _remove(sec_dir)
        facts["wall_s"] = time.monotonic() - t_wall0
        if reason and on_abort is not None:
            facts["aborted"], facts["abort_reason"] = True, reason
            on_abort(rec, facts, reason)
    stats_path = spec.sim_stats_path
    if stats_path is not None and stats_path.exists():
        try:
            facts["simulator"] = json.loads(stats_path.read_text())
        except ValueError as exc:
            log.warning("%s: not JSON (%s); run facts without simulator stats", stats_path, exc)
    sim = facts.get("simulator")
    sim_audit = sim.pop("audit", None) if isinstance(sim, dict) else None
    facts["audit"] = audit_document(sim_audit, rec.commands, rec.commands_dropped)
    facts["recorder_dropped"] = rec.dropped
    if not realtime:  # what the daemons stepped without (gcs.mission.score.lockstep_misses)
        count, first = lockstep_gaps(out_dir)
        facts["lockstep_gaps"] = {"count": count, "first": first}
    return rec, facts


def _swarm(sc: Scenario) -> str:
    return sc.name


def _remove(path: Path | None) -> None:
    """Delete the run's secure directory (the passwords and the per-run key die with the
    run)."""
    release_dir(path)


def run_and_score(
    sc: Scenario,
    out_dir: Path,
    method: str,
    seed: int | None,
    duration: float,
    realtime: bool = False,
    port_offset: int = 0,
    kill_agent: int | None = None,
    kill_at: float | None = None,
    show_progress: bool = True,
    land_at: float | None = None,
    signing: SigningChoice | None = None,
    processes: int | None = None,
    default_streams: DefaultStreams = DefaultStreams.ALWAYS,
    formation_port: int | None = None,
    live: LiveView | None = None,
) -> dict[str, Any]:
    """One distributed run -> metrics.json + series.npz in ``out_dir``; returns the document.

    The files are also written every :data:`~gcs.mission.supervise.CHECKPOINT_EVERY_S`
    during the run and when it
    ends early, with ``"aborted": true`` (what ran so far), so a run killed even with
    SIGKILL leaves its last checkpoint behind."""

    def write_partial(rec: Recorder, facts: dict[str, Any], reason: str) -> None:
        part = {**facts, "aborted": True, "abort_reason": reason}
        try:
            doc, ser = score_run(rec, sc, part, method, seed, realtime, land_at, duration)
            with_audit(doc, rec)
            write_run(out_dir, doc, ser)
        except (OSError, ValueError) as exc:
            log.warning("could not write the %s metrics to %s: %s", reason, out_dir, exc)

    rec, facts = run_distributed(
        sc, out_dir, method, seed, duration, realtime=realtime, port_offset=port_offset,
        kill_agent=kill_agent, kill_at=kill_at, show_progress=show_progress, land_at=land_at,
        on_abort=write_partial, signing=signing, processes=processes,
        default_streams=default_streams, formation_port=formation_port, live=live,
    )
    doc, ser = score_run(rec, sc, facts, method, seed, realtime, land_at, duration)
    with_audit(doc, rec)
    write_run(out_dir, doc, ser, sc)
    warn_verdict(sc.name, method, doc["metrics"])
    return doc


def with_audit(doc: dict[str, Any], rec: Recorder) -> None:
    """Move the run's audit trail (``run.audit``, :func:`run_distributed`) to the
    document's top level, ``audit`` (docs/security.md, "Audit trail"); a run that ended
    early has no simulator statistics yet: the Zenoh commands the recorder saw so far."""
    run = doc.get("run")
    found = run.pop("audit", None) if isinstance(run, dict) else None
    doc["audit"] = found or audit_document(None, list(rec.commands), rec.commands_dropped)
