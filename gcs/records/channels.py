"""The record's channels on one foxglove :class:`~foxglove.Context` and the messages of a
control step: one implementation, shared by the MCAP file (:mod:`gcs.records.writer`, the
context's sink an MCAP writer) and the live view (:mod:`gcs.records.live`, a WebSocket
server). Topic and schema names: :mod:`gcs.records.topics`.

A step's messages come from rows of a :class:`~gcs.report.metrics.Series` (the whole run
for a file, the latest rows for the live view); the ROS 2 bodies of all its rows are built
at once (:func:`cdr_messages`, :mod:`gcs.records.payloads`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from foxglove import Channel, Context, Schema
from foxglove.channels import (
    FrameTransformsChannel,
    LogChannel,
    PosesInFrameChannel,
    SceneUpdateChannel,
)
from foxglove.messages import (
    FrameTransform,
    FrameTransforms,
    Log,
    LogLevel,
    Pose,
    PosesInFrame,
    Quaternion,
    SceneUpdate,
    Vector3,
)

from gcs.records import payloads as pl
from gcs.records import topics as tp
from gcs.records.events import Event
from gcs.records.pair_table import pair_table, row_norm
from gcs.records.scene import (
    IDENTITY,
    bearing_update,
    sensed_pairs,
    stamp,
    vehicle_entities,
    world_entities,
)
from gcs.records.series import filter_arrays
from gcs.report.metrics import Series

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
        self.vertical_scale = 1.0  # the barrier's κ (docs/safety.md §4c), from the scenario

    def pairs_fields(self) -> tuple[tuple[str, str, str], ...]:
        """The ``/pairs`` message's fields for these agents
        (:func:`~gcs.records.topics.recorded_pair_count` pairs, ids up to the largest)."""
        return tp.pairs_fields(tp.recorded_pair_count(len(self.ids)),
                                max(self.ids, default=0))

    @classmethod
    def from_scenario(cls, sc: Any) -> RecordContext:
        from offboard.estimation.bearing import formation_from_scenario

        form = formation_from_scenario(sc)
        ids = [int(i) for i in sc.ids]
        out = cls(ids, [ids[i] for i in form.leader_idx],
                  sensed_pairs(form.sensed, form.follower_idx),
                  float(sc.vehicle.collision_radius_m), float(sc.controller.tau_safe_s),
                  float(sc.controller.d_safe_m), sc.world)
        out.vertical_scale = float(sc.controller.dcbf_vertical_scale)
        return out

    @classmethod
    def bare(cls, n: int, tau_s: float = 0.0, d_safe_m: float = 0.0) -> RecordContext:
        empty = np.zeros(0, np.int64)
        return cls(list(range(1, n + 1)), [], (empty, empty), 0.3, tau_s, d_safe_m, None)


@dataclass(frozen=True)
class CdrMessages:
    """The CDR bodies of the ROS 2 topics for every row of a series: ``est[a][k]`` and
    ``qp[a][k]`` of agent column a, ``pairs[k]``."""

    est: list[list[bytes]]
    qp: list[list[bytes]]
    pairs: list[bytes]


def _by_agent(x: np.ndarray) -> np.ndarray:
    """(K, N, ...) rows -> (N K, ...): agent 0's K rows, then agent 1's, ..."""
    x = np.asarray(x)
    return np.swapaxes(x, 0, 1).reshape(-1, *x.shape[2:])


def cdr_messages(s: Series, c: RecordContext) -> CdrMessages:
    """The ``/agent/<id>/estimate``, ``/agent/<id>/qp`` and ``/pairs`` bodies of every row
    of ``s`` (numpy: each kind for every agent and row at once)."""
    k, n = len(s.t), len(c.ids)
    t = np.tile(np.asarray(s.t, float), n)
    est = pl.cdr_rows(tp.ESTIMATE_FIELDS, {
        "t_s": t, "p_m": _by_agent(s.p), "v_m_s": _by_agent(s.v),
        "p_des_m": _by_agent(s.p_des), "v_des_m_s": _by_agent(s.v_des),
        "p_est_m": _by_agent(s.z1), "v_est_m_s": _by_agent(s.z2),
        "p_des_est_m": _by_agent(s.xi_p), "d_est_m_s2": _by_agent(s.lumped_est),
        "d_true_m_s2": _by_agent(s.lumped_true), "p_err_m": _by_agent(row_norm(s.z1 - s.p)),
        "v_err_m_s": _by_agent(row_norm(s.z2 - s.v)),
        "d_err_m_s2": _by_agent(row_norm(s.lumped_est - s.lumped_true)),
        "track_err_m": _by_agent(row_norm(s.p - s.p_des))}, n * k)
    f = filter_arrays(s)
    qp = pl.cdr_rows(tp.QP_FIELDS, {
        "t_s": t, "u_m_s2": _by_agent(s.u), "h_min_m2": _by_agent(s.h_min),
        "solve_us": _by_agent(s.solve_us), "thrust_n": _by_agent(s.thrust),
        "tilt_deg": _by_agent(s.tilt_deg), "u_nom_m_s2": _by_agent(f["u_nom"]),
        "correction_m_s2": _by_agent(f["u_corr"]), "clf_slack_m_s2": _by_agent(f["clf_slack"]),
        "relax_m_s2": _by_agent(f["qp_relax"]), "degraded": _by_agent(s.fallback),
        "input_clipped": _by_agent(s.input_clipped), "alarms": _by_agent(s.alarms),
        "qp_status": _by_agent(f["qp_status"]), "active_rows": _by_agent(f["qp_active"]),
        "active_kinds": _by_agent(f["qp_kinds"])}, n * k)
    tab = pair_table(s.p, s.v, c.tau_s, c.d_safe_m, c.vertical_scale)
    ids = np.asarray(c.ids)
    pairs = pl.cdr_rows(c.pairs_fields(), {
        "t_s": s.t, "min_distance_m": s.min_dist, "min_h_m2": tab.min_h_m2,
        "distance_m": tab.distance_m, "h_m2": tab.h_m2, "i": ids[tab.i], "j": ids[tab.j]}, k)
    return CdrMessages([est[a * k:(a + 1) * k] for a in range(n)],
                       [qp[a * k:(a + 1) * k] for a in range(n)], pairs)


def _ros2_channel(topic: str, name: str, fields: tuple[tuple[str, str, str], ...],
                  ctx: Context) -> Any:
    schema = Schema(name=name, encoding="ros2msg", data=tp.ros2msg(fields).encode())
    return Channel(topic, schema=schema, message_encoding="cdr", context=ctx).base


class RecordChannels:
    """Every topic of the record (:func:`gcs.records.topics.all_topics`) as a channel on
    ``ctx``, and the messages of a step. ``skip_unwatched``: build a topic's message only
    while some sink subscribes to it (``has_sinks``; the live view, whose clients choose
    their topics); a file's sink takes every channel, so the writer asks nothing."""

    def __init__(self, ctx: Context, c: RecordContext, skip_unwatched: bool = False) -> None:
        self.c, self.skip = c, skip_unwatched
        self.frames = [tp.vehicle_frame(i) for i in c.ids]
        self.tf = FrameTransformsChannel(tp.TF, context=ctx)
        self.scene = SceneUpdateChannel(tp.SCENE, context=ctx)
        self.desired = PosesInFrameChannel(tp.DESIRED, context=ctx)
        self.events = LogChannel(tp.EVENTS, context=ctx)
        self.est = [_ros2_channel(tp.estimate_topic(i), tp.ESTIMATE_SCHEMA, tp.ESTIMATE_FIELDS,
                                  ctx) for i in c.ids]
        self.qp = [_ros2_channel(tp.qp_topic(i), tp.QP_SCHEMA, tp.QP_FIELDS, ctx)
                   for i in c.ids]
        self.pairs = _ros2_channel(tp.PAIRS, tp.PAIRS_SCHEMA, c.pairs_fields(), ctx)
        self.ros2: list[Any] = [*self.est, *self.qp, self.pairs]

    def _on(self, ch: Any) -> bool:
        return not self.skip or bool(ch.has_sinks())

    def wants_cdr(self) -> bool:
        """Whether a ROS 2 topic's messages would be logged (:func:`cdr_messages` needed)."""
        return not self.skip or any(ch.has_sinks() for ch in self.ros2)

    def log_setup(self, t_ns: int) -> None:
        """The ``/scene`` of the start: a frame-locked entity per vehicle, the world."""
        if not self._on(self.scene):
            return
        c = self.c
        ents = vehicle_entities(t_ns, c.ids, c.leaders, c.radius_m)
        if c.world is not None:
            ents += world_entities(t_ns, c.world)
        self.scene.log(SceneUpdate(entities=ents), log_time=t_ns)

    def log_step(self, s: Series, k: int, t_ns: int, cdr: CdrMessages | None, lines: bool,
                 rotations: Sequence[Quaternion] | None = None) -> None:
        """The messages of row ``k`` of ``s`` at sim time ``t_ns``: ``/world/tf`` (each
        vehicle's ``rotations``, default the identity), the ROS 2 topics (``cdr``: their
        bodies, None to log none), and with ``lines`` the bearings of ``/scene`` and
        ``/formation/desired``."""
        ts = stamp(t_ns)
        if self._on(self.tf):
            rots = [IDENTITY] * len(self.frames) if rotations is None else rotations
            self.tf.log(FrameTransforms(transforms=[
                FrameTransform(timestamp=ts, parent_frame_id=tp.WORLD_FRAME, child_frame_id=f,
                               translation=Vector3(x=x, y=y, z=z), rotation=q)
                for f, (x, y, z), q in zip(self.frames, s.p[k].tolist(), rots, strict=True)]),
                log_time=t_ns)
        if cdr is not None:
            for a in range(len(self.frames)):
                if self._on(self.est[a]):
                    self.est[a].log(cdr.est[a][k], t_ns)
                if self._on(self.qp[a]):
                    self.qp[a].log(cdr.qp[a][k], t_ns)
            if self._on(self.pairs):
                self.pairs.log(cdr.pairs[k], t_ns)
        if not lines:  # the 3-D view's lines and desired poses: BEARING_PERIOD_S
            return
        src, dst = self.c.sensed
        if len(src) and self._on(self.scene):
            self.scene.log(bearing_update(t_ns, s.p[k], src, dst), log_time=t_ns)
        if self._on(self.desired):
            self.desired.log(PosesInFrame(timestamp=ts, frame_id=tp.WORLD_FRAME, poses=[
                Pose(position=Vector3(x=x, y=y, z=z), orientation=IDENTITY)
                for x, y, z in s.p_des[k].tolist()]), log_time=t_ns)

    def log_event(self, ev: Event, t_ns: int) -> None:
        """One ``/events`` Log (stamped at the event's time, logged at ``t_ns``)."""
        if self._on(self.events):
            self.events.log(Log(timestamp=stamp(ev.ns), level=_LEVELS[ev.level],
                                message=ev.message, name=ev.name), log_time=t_ns)
