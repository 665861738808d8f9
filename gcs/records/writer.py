"""Write a run's MCAP record (``record.mcap``, docs/records.md) with foxglove-sdk's MCAP
writer: Foxglove's protobuf schemas for the transforms, desired poses, scene and events,
ROS 2 messages (``ros2msg`` schemas, CDR: :mod:`gcs.records.payloads`) for the estimates,
the safety filter and the pairs. The channels and the messages of a step are
:class:`~gcs.records.channels.RecordChannels`' (the live view logs the same ones).

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
from foxglove import Context, open_mcap
from foxglove.mcap import MCAPCompression, MCAPWriteOptions

from gcs.records import topics as tp
from gcs.records.channels import RecordChannels, RecordContext, cdr_messages
from gcs.records.events import all_events
from gcs.records.scene import BEARING_PERIOD_S
from gcs.records.series import rows_of
from gcs.report.metrics import Series

RECORD_NAME = "record.mcap"
CHUNK_STEPS = 64  # steps whose message bodies write_mcap builds at once
# zstd level 1 on the writing thread: a 60 s cube8 record in about 9 MB, and the fastest
# (level 3: 3 % smaller, 15 % slower; lz4: 12 % larger; bench/record_cost.py)
ZSTD_LEVEL = 1


def _options() -> MCAPWriteOptions:
    return MCAPWriteOptions(compression=MCAPCompression.Zstd, profile=tp.PROFILE,
                            compression_level=ZSTD_LEVEL, compression_threads=0)


def write_mcap(path: Path, doc: Mapping[str, Any], series: Series, c: RecordContext) -> Path:
    """Write the record of ``series`` (and ``doc``, the run's ``metrics.json`` document) to
    ``path`` through a temporary file renamed over it; returns ``path``."""
    s = series
    n = s.p.shape[1]
    if len(c.ids) != n:
        raise ValueError(f"the series has {n} agents, the scenario {len(c.ids)}")
    ns = np.round(np.asarray(s.t, float) * 1e9).astype(np.int64)
    events = all_events(doc, ns, c.ids, s.fallback, s.alarms, s.input_clipped)
    dt = float(np.median(np.diff(s.t))) if len(s.t) > 1 else 1.0
    every = max(1, int(round(BEARING_PERIOD_S / dt))) if dt > 0 else 1

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
        ch = RecordChannels(ctx, c)
        e = 0
        # the ROS 2 bodies of CHUNK_STEPS steps at a time: the same messages in the same
        # order, without every step's bodies in memory at once (a large swarm's record)
        for a in range(0, len(ns), CHUNK_STEPS):
            b = min(a + CHUNK_STEPS, len(ns))
            part = s if (a, b) == (0, len(ns)) else rows_of(s, slice(a, b))
            cdr = cdr_messages(part, c)
            for k in range(a, b):
                t_ns = int(ns[k])
                if k == 0:
                    ch.log_setup(t_ns)
                ch.log_step(part, k - a, t_ns, cdr, lines=k % every == 0)
                while e < len(events) and events[e].ns <= t_ns:
                    ch.log_event(events[e], t_ns)
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
