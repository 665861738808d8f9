"""What a mission run leaves behind: the recorded :class:`~gcs.report.metrics.Series` and the run
directory (``metrics.json`` + ``series.npz``), for in-process and distributed runs alike.

``series.npz`` holds one array per :class:`~gcs.report.metrics.Series` field (``t``, ``p``, ``v``,
``p_des``, ``v_des``, ``z1``, ``z2``, ``lumped_est``, ``lumped_true``, ``u``, ``thrust``,
``tilt_deg``, ``min_dist``, ``h_min``, ``solve_us``, ``fallback``, ``input_clipped``,
``alarms``: the :class:`~swarm_common.enums.AgentAlarm` bits, uint8; files written before
it have none, and no reader here needs it), and the safety filter's report of
:class:`~gcs.records.series.RunSeries` (``qp_status``, ``qp_active``, ``qp_kinds``,
``clf_slack``, ``qp_relax``, ``u_nom``, ``u_corr``; older files have none).
``metrics.json`` is :func:`run_document`: ``scenario``, ``method``, ``seed``, ``metrics`` (keys
:data:`~gcs.report.metrics.METRIC_KEYS`) and the runner's extras (in process: ``gains``,
``collision_pairs``; distributed: ``mode``, ``run``).
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Mapping, Sequence
from itertools import chain
from operator import attrgetter
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from gcs.records.series import (
    MAX_COUNT,
    QP_STATUS_CODES,
    STATUS_CODE,
    RunSeries,
    unknown_filter,
)
from gcs.report.metrics import SafetySpec, Series
from gcs.report.mission_metrics import (
    leader_yaw,
    mission_metrics,
    observer_metrics,
    yawed_desired,
)
from gcs.report.verdict import summary_line
from offboard.estimation.bearing import Formation
from offboard.records import AgentOutput
from swarm_common import inputs
from swarm_common.scenario.mission_check import yaws as mission_yaws
from swarm_common.scenario.model import Scenario

log = logging.getLogger(__name__)


def safety_spec(sc: Scenario, clipped_known: bool = True) -> SafetySpec:
    """The scenario's barrier τ (s), D (m) and tracking deadline (s) for
    :func:`~gcs.report.metrics.compute_metrics`; ``clipped_known``: the statuses carried
    ``input_clipped``."""
    return SafetySpec(sc.controller.tau_safe_s, sc.controller.d_safe_m,
                      sc.run.formation_deadline_s, clipped_known, tuple(sc.ids),
                      sc.vehicle.collision_radius_m, sc.world,
                      sc.controller.dcbf_vertical_scale)


def tilt_deg(att: np.ndarray) -> np.ndarray:
    """Tilt of each vehicle from vertical (deg): arccos(cos φ cos θ) of (..., 3) ENU
    roll/pitch/yaw in rad (the angle between body z and world z)."""
    return np.degrees(np.arccos(np.clip(np.cos(att[..., 0]) * np.cos(att[..., 1]), -1, 1)))


def empty_series(t: np.ndarray, n: int, fill: float = 0.0) -> RunSeries:
    """A :class:`~gcs.records.series.RunSeries` of ``len(t)`` steps for ``n`` agents, every
    value ``fill`` (NaN where rows may stay unknown, as in a recorded run); ``fallback``
    and ``input_clipped`` all False, ``alarms`` all 0, the QP's status unknown and no
    active rows (:func:`~gcs.records.series.unknown_filter`)."""
    kk = len(t)

    def z(*shape: int) -> np.ndarray:
        return np.full((kk, *shape), fill)

    return RunSeries(
        t=t, p=z(n, 3), v=z(n, 3), p_des=z(n, 3), v_des=z(n, 3), z1=z(n, 3), z2=z(n, 3),
        xi_p=z(n, 3),
        lumped_est=z(n, 3), lumped_true=z(n, 3), u=z(n, 3), thrust=z(n), tilt_deg=z(n),
        min_dist=z(), h_min=z(n), solve_us=z(n), fallback=np.zeros((kk, n), bool),
        input_clipped=np.zeros((kk, n), bool), alarms=np.zeros((kk, n), np.uint8),
        **unknown_filter(kk, n, fill),
    )


def set_truth_rows(
    ser: Series,
    form: Formation,
    p: np.ndarray,
    v: np.ndarray,
    lumped: np.ndarray,
    thrust: np.ndarray,
    att: np.ndarray,
    yaw: tuple[np.ndarray, np.ndarray] | None = None,
) -> None:
    """Every row of the simulator's truth, (K, N, ...) each: positions/velocities (m, m/s,
    ENU), the desired ones from the leaders' (paper eq. 5), true lumped disturbance
    (m/s²), thrust (N) and the tilt from the (K, N, 3) attitudes (rad); ``yaw``: (ψ, ψ')
    (K,) each of a turning formation (:func:`~gcs.report.mission_metrics.leader_yaw`). One
    product per quantity for the whole run (the in-process runner and a recorded run alike)."""
    lid = form.leader_idx
    ser.p[:], ser.v[:] = p, v
    if yaw is not None:  # a turning formation's bearings turn with it
        ser.p_des[:], ser.v_des[:] = yawed_desired(form, lid, p, v, *yaw)
    else:
        ser.p_des[:] = form.desired_positions_series(p[:, lid])
        ser.v_des[:] = form.desired_positions_series(v[:, lid])
    ser.lumped_true[:] = lumped
    ser.thrust[:] = thrust
    ser.tilt_deg[:] = tilt_deg(att)


# the real-valued and the integer status fields the agents' rows record, in their order
# (attrgetter: one C call per record; the QP's status is coded through STATUS_CODE)
_REAL_FIELDS = attrgetter("h_min", "solve_us", "slack", "violation", "correction")
_INT_FIELDS = attrgetter("input_clipped", "alarms", "active.count", "active.kinds")
_QP_STATUS = attrgetter("qp_status")
_CODE_OF = STATUS_CODE.__getitem__
# QPStatus.degraded by status code
_DEGRADED_BY_CODE = np.array([s.degraded for s in QP_STATUS_CODES], dtype=bool)
# outputs the runner stages before it writes their rows (AgentRows): 50 steps of cube8,
# 4 of 1,024 agents (what they hold alive is bounded, not the run's length)
STAGED_OUTPUTS = 4096
MAX_STAGED_STEPS = 50


def set_agent_rows(ser: RunSeries, r: int, outs: Sequence[AgentOutput]) -> None:
    """Row ``r`` of every agent's status, ``outs`` in scenario order: virtual control u
    (m/s²), estimated lumped disturbance, smallest barrier value, QP time (µs), whether the
    QP degraded, whether the setpoint conversion changed u (tilt/thrust clip), the
    agent's safety alarm bits (:class:`~swarm_common.enums.AgentAlarm`) and the safety
    filter's report (status, active rows, slacks, u_nom, correction)."""
    set_agent_blocks(ser, r, [outs])


class FlatRows(NamedTuple):
    """The agents' rows of ``b`` consecutive steps as arrays, (b, n, ...) each: the
    vectors (u, lumped estimate, u_nom: (b, n, 3, 3)), the real status fields (h_min,
    solve_us, slack, violation, correction: (b, n, 5)), the integer ones (input_clipped,
    alarms, active count, active kinds: (b, n, 4)) and the QP's status code (b, n). What
    :func:`flat_rows` reads from the outputs and :func:`write_flat_rows` writes; a shard
    of the agents sends it from its process (gcs.mission.agents.shards)."""

    vec: np.ndarray
    real: np.ndarray
    ints: np.ndarray
    code: np.ndarray


def flat_rows(steps: Sequence[Sequence[AgentOutput]]) -> FlatRows:
    """The :class:`FlatRows` of ``steps`` (one sequence of outputs per step, every one of
    the same agents): one conversion of each kind for the whole block, whose per-row numpy
    calls cost more than the values' own copying."""
    b = len(steps)
    n = len(steps[0]) if b else 0
    outs = [o for step in steps for o in step]
    if len(outs) != b * n:
        raise ValueError(f"{len(outs)} outputs for {b} rows of {n} agents")
    st = [o.status for o in outs]
    # the three vectors of every output in one concatenation (a list of arrays assigned to
    # rows would make numpy discover each element's shape)
    vec = (np.concatenate([v for o in outs for v in (o.u, o.lumped, o.status.u_nom)])
           if outs else np.zeros(0))
    # the scalar fields: one array of each kind, read from a flat iterator of C getters
    # (np.array of a list of tuples discovers each tuple's shape)
    m = len(outs)
    real = np.fromiter(chain.from_iterable(map(_REAL_FIELDS, st)), np.float64, 5 * m)
    ints = np.fromiter(chain.from_iterable(map(_INT_FIELDS, st)), np.int64, 4 * m)
    code = np.fromiter(map(_CODE_OF, map(_QP_STATUS, st)), np.int64, m)
    return FlatRows(vec.reshape(b, n, 3, 3), real.reshape(b, n, 5), ints.reshape(b, n, 4),
                    code.reshape(b, n))


def join_flat_rows(parts: Sequence[FlatRows]) -> FlatRows:
    """The :class:`FlatRows` of the same steps for the agents of ``parts`` one after the
    other (each part a run of consecutive agents, in scenario order)."""
    return FlatRows(*(np.concatenate(f, axis=1) for f in zip(*parts, strict=True)))


def write_flat_rows(ser: RunSeries, r: int, flat: FlatRows) -> None:
    """Rows ``r``, ``r + 1``, ... of every agent's status from ``flat`` (its steps in
    order; fields as :func:`set_agent_rows`)."""
    vec, real, ints, code = flat
    rows = slice(r, r + code.shape[0])
    ser.u[rows], ser.lumped_est[rows], ser.u_nom[rows] = (
        vec[:, :, 0], vec[:, :, 1], vec[:, :, 2])
    (ser.h_min[rows], ser.solve_us[rows], ser.clf_slack[rows], ser.qp_relax[rows],
     ser.u_corr[rows]) = (real[..., 0], real[..., 1], real[..., 2], real[..., 3],
                          real[..., 4])
    ser.input_clipped[rows], ser.alarms[rows] = ints[..., 0], ints[..., 1]
    ser.qp_active[rows] = np.minimum(ints[..., 2], MAX_COUNT)
    ser.qp_kinds[rows] = ints[..., 3]
    ser.qp_status[rows], ser.fallback[rows] = code, _DEGRADED_BY_CODE[code]


def set_agent_blocks(ser: RunSeries, r: int, steps: Sequence[Sequence[AgentOutput]]) -> None:
    """:func:`set_agent_rows` of consecutive rows ``r``, ``r + 1``, ... from ``steps`` (one
    sequence of outputs per row, every one of the same agents), through one
    :func:`flat_rows`."""
    if steps:
        write_flat_rows(ser, r, flat_rows(steps))


class AgentRows:
    """The agents' rows of a run's series, written in blocks: :meth:`add` keeps each step's
    outputs, and every ``block`` steps (or at :meth:`flush`) :func:`set_agent_blocks` writes
    them. ``block`` defaults to what :data:`STAGED_OUTPUTS` outputs of ``n`` agents fill, at
    most :data:`MAX_STAGED_STEPS`; 1 writes every row as it comes (a live view reads each).
    The outputs are only read, after their step: an agent never writes an output it
    returned."""

    def __init__(self, ser: RunSeries, n: int, block: int | None = None) -> None:
        self.ser = ser
        self.block = (max(1, min(MAX_STAGED_STEPS, STAGED_OUTPUTS // max(1, n)))
                      if block is None else max(1, int(block)))
        self._first = 0  # the row of the first staged step
        self._staged: list[Sequence[AgentOutput]] = []

    def add(self, r: int, outs: Sequence[AgentOutput] | FlatRows) -> None:
        """Row ``r``'s outputs (rows come in order, one after the other), or its
        :class:`FlatRows` (of one step), which is written at once."""
        if isinstance(outs, FlatRows):
            self.flush()
            write_flat_rows(self.ser, r, outs)
            return
        if not self._staged:
            self._first = r
        elif r != self._first + len(self._staged):
            raise ValueError(f"row {r} after {self._first + len(self._staged) - 1}")
        self._staged.append(outs)
        if len(self._staged) >= self.block:
            self.flush()

    def flush(self) -> None:
        """Write the staged rows."""
        if self._staged:
            set_agent_blocks(self.ser, self._first, self._staged)
            self._staged = []


def run_document(
    scenario: str, method: str, seed: int, metrics: Mapping[str, Any], **extra: Any
) -> dict[str, Any]:
    """The ``metrics.json`` document of one run (also what ``--json`` prints)."""
    return {"scenario": scenario, "method": str(method), "seed": seed, "metrics": metrics,
            **extra}


def json_default(x: Any) -> Any:
    """``json.dumps`` hook: numpy scalars as Python numbers."""
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(f"{type(x).__name__} is not JSON serializable")


def run_dir_inside(parent: Path, leaf: str) -> Path:
    """``parent/leaf``, refused (``ValueError``, one line) unless it stays inside ``parent``
    (no separator, ``..`` or absolute path in ``leaf``, no symlink out)."""
    if not leaf or leaf in (".", "..") or "/" in leaf or "\\" in leaf or "\0" in leaf:
        raise ValueError(f"run directory name {leaf!r}: must be one plain path component")
    base = parent.resolve()
    out = (base / leaf).resolve()
    if out.parent != base:
        raise ValueError(f"run directory {parent / leaf}: resolves outside {parent}")
    return parent / leaf


def out_dir_problem(out: Path) -> str | None:
    """Why ``out`` cannot be a run directory, or None: checked before a run starts
    (:func:`swarm_common.inputs.out_dir_problem`: created if missing, a probe file written
    and removed), so a run never ends with nowhere to write its results."""
    return inputs.out_dir_problem(out, "--out")


def _write_files(out_dir: Path, doc: Mapping[str, Any], series: Series) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, Any] = series.as_dict()
    tmp = out_dir / ".series.tmp.npz"
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, out_dir / "series.npz")
    tmp = out_dir / ".metrics.json.tmp"
    tmp.write_text(json.dumps(doc, indent=2, default=json_default) + "\n")
    os.replace(tmp, out_dir / "metrics.json")


def write_run(
    out_dir: Path, doc: Mapping[str, Any], series: Series, scenario: Scenario | None = None,
) -> Path:
    """Write ``metrics.json`` (``doc``) and ``series.npz`` (``series``) into ``out_dir``,
    each through a temporary file renamed over the old one, so a reader (or a run killed
    while writing) never sees half a file. When ``out_dir`` cannot be written (it was
    checked before the run, but a disk can fill or a folder vanish), the results go to a
    fresh private folder in the temporary directory instead, logged as an ERROR with its
    path: a finished run's results are never lost. With ``scenario``, also the run's
    MCAP record (``record.mcap``, :func:`gcs.records.writer.write_record`) beside them.
    Returns the folder written."""
    try:
        _write_files(out_dir, doc, series)
        written = out_dir
    except OSError as exc:
        written = inputs.fallback_dir("swarm-run-")
        _write_files(written, doc, series)
        log.error("cannot write the results to %s (%s): written to %s instead", out_dir,
                  exc.strerror or exc, written)
    if scenario is not None:
        from gcs.records.writer import write_record

        try:
            write_record(written, doc, series, scenario)
        except (OSError, ValueError) as exc:
            log.error("cannot write %s/record.mcap (%s); metrics.json and series.npz are "
                      "written", written, exc)
    return written


def print_result(doc: Mapping[str, Any], as_json: bool) -> None:
    """stdout of ``gcs mission run``: the document as one JSON line, or a metrics table."""
    if as_json:
        print(json.dumps(doc, default=json_default))
    else:
        for k, v in doc["metrics"].items():
            print(f"{k:24s} {v}")


def formation_yaw(
    sc: Scenario, p: np.ndarray, v: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """(ψ, ψ') of the rows when ``sc``'s mission turns the formation, else None."""
    return leader_yaw(sc, p, v) if mission_yaws(sc) else None


def run_mission_metrics(sc: Scenario, ser: Series, form: Formation) -> dict[str, Any]:
    """The keys of :data:`~gcs.report.metrics.EXTRA_KEYS` of a finished run's series: the
    desired-state observer's error and the mission's (:mod:`gcs.report.mission_metrics`).
    A mission that did not reach every waypoint is also a warning in the log."""
    f = form.follower_idx
    out = (observer_metrics(sc, form, ser.t, ser.xi_p)
           | mission_metrics(sc, ser.t, ser.p, ser.p_des, f))
    if out["mission_completed"] is False:
        log.warning("%s: the formation did not reach every mission waypoint within %.1f s "
                    "(mission_completed false)", sc.name, float(ser.t[-1]) if len(ser.t) else 0.0)
    return out


def warn_verdict(name: str, method: str, metrics: dict[str, Any]) -> bool:
    """Log a finished run's safety verdict when it is not "safe" (one WARNING line naming the
    first events: :func:`gcs.report.verdict.summary_line`); True when it was not."""
    line = summary_line(metrics)
    if line is None:
        return False
    log.warning("%s [%s]: %s", name, method, line)
    return True
