"""Write a run's MCAP record (``record.mcap``, docs/records.md) with foxglove-sdk's MCAP
writer: Foxglove's protobuf schemas for the transforms, desired poses, scene and events,
ROS 2 messages (``ros2msg`` schemas, CDR: :mod:`gcs.records.payloads`) for the estimates,
the safety filter and the pairs.

Messages are written step by step in time order (zstd chunks), one per vehicle per step
on each per-vehicle topic, and ``/world/tf`` holds one transform per vehicle per step;
``/formation/desired`` and the bearing lines of ``/scene`` are drawn every
:data:`~gcs.records.scene.BEARING_PERIOD_S` (the per-step desired positions are in each
``/agent/<id>/estimate``).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from foxglove import Channel, Context, Schema, open_mcap
from foxglove.channels import (
    FrameTransformsChannel,
    LogChannel,
    PosesInFrameChannel,
    SceneUpdateChannel,
)
from foxglove.mcap import MCAPCompression, MCAPWriteOptions
from foxglove.messages import (
    FrameTransform,
    FrameTransforms,
    Log,
    LogLevel,
    Pose,
    PosesInFrame,
    SceneUpdate,
    Vector3,
)

from gcs.records import payloads as pl
from gcs.records import topics as tp
from gcs.records.events import all_events
from gcs.records.scene import (
    BEARING_PERIOD_S,
    IDENTITY,
    bearing_update,
    sensed_pairs,
    stamp,
    vehicle_entities,
    world_entities,
)
from gcs.report.metrics import Series
from gcs.report.verdict import pair_barrier

RECORD_NAME = "record.mcap"
# zstd level 1 on the writing thread: a 60 s cube8 record in about 9 MB, and the fastest
# (level 3: 3 % smaller, 15 % slower; lz4: 12 % larger; bench/record_cost.py)
ZSTD_LEVEL = 1
_LEVELS = {1: LogLevel.Debug, 2: LogLevel.Info, 3: LogLevel.Warning, 4: LogLevel.Error}


class RecordContext:
    """What the record needs from the scenario: agent ids (column order), leader ids, the
    sensed bearings (column pairs a -> b), the collision radius (m), barrier τ (s) and
    D (m), and the world (obstacles, geofence); :meth:`from_scenario` or, without one,
    :meth:`bare` (ids 1..N, no bearings, no world)."""

    def __init__(self, ids: list[int], leaders: list[int], sensed: tuple[np.ndarray, np.ndarray],
                 radius_m: float, tau_s: float, d_safe_m: float, world: Any) -> None:
        self.ids, self.leaders, self.sensed = ids, leaders, sensed
        self.radius_m, self.tau_s, self.d_safe_m, self.world = radius_m, tau_s, d_safe_m, world

    @classmethod
    def from_scenario(cls, sc: Any) -> RecordContext:
        from offboard.estimation.bearing import formation_from_scenario

        form = formation_from_scenario(sc)
        ids = [int(i) for i in sc.ids]
        return cls(ids, [ids[i] for i in form.leader_idx],
                   sensed_pairs(form.sensed, form.follower_idx),
                   float(sc.vehicle.collision_radius_m), float(sc.controller.tau_safe_s),
                   float(sc.controller.d_safe_m), sc.world)

    @classmethod
    def bare(cls, n: int, tau_s: float = 0.0, d_safe_m: float = 0.0) -> RecordContext:
        empty = np.zeros(0, np.int64)
        return cls(list(range(1, n + 1)), [], (empty, empty), 0.3, tau_s, d_safe_m, None)


def _options() -> MCAPWriteOptions:
    return MCAPWriteOptions(compression=MCAPCompression.Zstd, profile=tp.PROFILE,
                            compression_level=ZSTD_LEVEL, compression_threads=0)


def _ros2_channel(topic: str, name: str, fields: tuple[tuple[str, str, str], ...],
                  ctx: Context) -> Any:
    schema = Schema(name=name, encoding="ros2msg", data=tp.ros2msg(fields).encode())
    return Channel(topic, schema=schema, message_encoding="cdr", context=ctx).base


def _norm(x: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        return np.asarray(np.linalg.norm(x, axis=-1))


def _agent_messages(s: Series, c: RecordContext) -> tuple[list[list[bytes]], list[list[bytes]]]:
    k = len(s.t)
    est, qp = [], []
    for a in range(len(c.ids)):
        est.append(pl.cdr_rows(tp.ESTIMATE_FIELDS, {
            "t_s": s.t, "p_m": s.p[:, a], "v_m_s": s.v[:, a], "p_des_m": s.p_des[:, a],
            "v_des_m_s": s.v_des[:, a], "p_est_m": s.z1[:, a], "v_est_m_s": s.z2[:, a],
            "p_des_est_m": s.xi_p[:, a],
            "d_est_m_s2": s.lumped_est[:, a], "d_true_m_s2": s.lumped_true[:, a],
            "p_err_m": _norm(s.z1[:, a] - s.p[:, a]), "v_err_m_s": _norm(s.z2[:, a] - s.v[:, a]),
            "d_err_m_s2": _norm(s.lumped_est[:, a] - s.lumped_true[:, a]),
            "track_err_m": _norm(s.p[:, a] - s.p_des[:, a])}, k))
        qp.append(pl.cdr_rows(tp.QP_FIELDS, {
            "t_s": s.t, "u_m_s2": s.u[:, a], "h_min_m2": s.h_min[:, a],
            "solve_us": s.solve_us[:, a], "thrust_n": s.thrust[:, a],
            "tilt_deg": s.tilt_deg[:, a], "degraded": s.fallback[:, a],
            "input_clipped": s.input_clipped[:, a], "alarms": s.alarms[:, a]}, k))
    return est, qp


def _pairs_messages(s: Series, c: RecordContext) -> list[bytes]:
    n = s.p.shape[1]
    i, j = np.triu_indices(n, k=1)
    h = pair_barrier(s.p, s.v, c.tau_s, c.d_safe_m)
    with np.errstate(invalid="ignore"):
        hmin = np.min(h, axis=1) if h.shape[1] else np.full(len(s.t), np.nan)
    ids = np.asarray(c.ids)
    return pl.cdr_rows(tp.pairs_fields(len(i)), {
        "t_s": s.t, "min_distance_m": s.min_dist, "min_h_m2": hmin,
        "distance_m": _norm(s.p[:, i] - s.p[:, j]), "h_m2": h, "i": ids[i], "j": ids[j]},
        len(s.t))


def write_mcap(path: Path, doc: Mapping[str, Any], series: Series, c: RecordContext) -> Path:
    """Write the record of ``series`` (and ``doc``, the run's ``metrics.json`` document) to
    ``path`` through a temporary file renamed over it; returns ``path``."""
    s = series
    n = s.p.shape[1]
    if len(c.ids) != n:
        raise ValueError(f"the series has {n} agents, the scenario {len(c.ids)}")
    ns = np.round(np.asarray(s.t, float) * 1e9).astype(np.int64)
    est, qp = _agent_messages(s, c)
    pairs = _pairs_messages(s, c)
    events = all_events(doc, ns, c.ids, s.fallback, s.alarms, s.input_clipped)
    dt = float(np.median(np.diff(s.t))) if len(s.t) > 1 else 1.0
    every = max(1, int(round(BEARING_PERIOD_S / dt))) if dt > 0 else 1
    a, b = c.sensed
    frames = [tp.vehicle_frame(i) for i in c.ids]
    p_l, pd_l, ns_l = s.p.tolist(), s.p_des.tolist(), ns.tolist()

    tmp = path.with_name(f".{path.name}.tmp")
    ctx = Context()
    writer = open_mcap(tmp, allow_overwrite=True, context=ctx, writer_options=_options())
    try:
        writer.write_metadata("run", {
            "scenario": str(doc.get("scenario")), "method": str(doc.get("method")),
            "seed": str(doc.get("seed")), "ids": json.dumps(c.ids),
            "leaders": json.dumps(c.leaders), "frame": "ENU world, z up, metres",
            "time": "simulation time, ns from the start of the run"})
        writer.write_metadata("metrics", {"json": json.dumps(
            doc.get("metrics") or {}, default=lambda x: getattr(x, "item", lambda: str(x))())})
        tf = FrameTransformsChannel(tp.TF, context=ctx)
        scene = SceneUpdateChannel(tp.SCENE, context=ctx)
        desired = PosesInFrameChannel(tp.DESIRED, context=ctx)
        ev_ch = LogChannel(tp.EVENTS, context=ctx)
        est_ch = [_ros2_channel(tp.estimate_topic(i), tp.ESTIMATE_SCHEMA, tp.ESTIMATE_FIELDS,
                                ctx) for i in c.ids]
        qp_ch = [_ros2_channel(tp.qp_topic(i), tp.QP_SCHEMA, tp.QP_FIELDS, ctx) for i in c.ids]
        pairs_ch = _ros2_channel(tp.PAIRS, tp.PAIRS_SCHEMA, tp.pairs_fields(n * (n - 1) // 2),
                                 ctx)
        e = 0
        for k, t_ns in enumerate(ns_l):
            ts = stamp(t_ns)
            if k == 0:
                ents = vehicle_entities(t_ns, c.ids, c.leaders, c.radius_m)
                if c.world is not None:
                    ents += world_entities(t_ns, c.world)
                scene.log(SceneUpdate(entities=ents), log_time=t_ns)
            row = p_l[k]
            tf.log(FrameTransforms(transforms=[
                FrameTransform(timestamp=ts, parent_frame_id=tp.WORLD_FRAME, child_frame_id=f,
                               translation=Vector3(x=x, y=y, z=z), rotation=IDENTITY)
                for f, (x, y, z) in zip(frames, row, strict=True)]), log_time=t_ns)
            for a_i in range(n):
                est_ch[a_i].log(est[a_i][k], t_ns)
                qp_ch[a_i].log(qp[a_i][k], t_ns)
            pairs_ch.log(pairs[k], t_ns)
            if k % every == 0:  # the 3-D view's lines and desired poses: BEARING_PERIOD_S
                if len(a):
                    scene.log(bearing_update(t_ns, s.p[k], a, b), log_time=t_ns)
                desired.log(PosesInFrame(timestamp=ts, frame_id=tp.WORLD_FRAME, poses=[
                    Pose(position=Vector3(x=x, y=y, z=z), orientation=IDENTITY)
                    for x, y, z in pd_l[k]]), log_time=t_ns)
            while e < len(events) and events[e].ns <= t_ns:
                ev = events[e]
                ev_ch.log(Log(timestamp=stamp(ev.ns), level=_LEVELS[ev.level],
                              message=ev.message, name=ev.name), log_time=t_ns)
                e += 1
        writer.close()
        os.replace(tmp, path)
    except BaseException:
        writer.close()
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_record(out_dir: Path, doc: Mapping[str, Any], series: Series, scenario: Any) -> Path:
    """Write ``out_dir/record.mcap`` of a finished run (``doc``: its ``metrics.json``
    document; ``scenario``: its :class:`~swarm_common.scenario.model.Scenario`, or None for
    a record without the bearings and the world). Returns the file's path."""
    if scenario is not None:
        c = RecordContext.from_scenario(scenario)
    else:
        c = RecordContext.bare(series.p.shape[1])
    return write_mcap(Path(out_dir) / RECORD_NAME, doc, series, c)
