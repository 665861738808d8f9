"""Read a bearing-swarm MCAP record back (the ``mcap`` package's reader): check that a
file is a whole MCAP record of this project, and decode its ROS 2 topics (the estimates,
the safety filter, the pairs: :mod:`gcs.records.topics`) into arrays with the same packed
layout the writer used (:func:`gcs.records.payloads.layout`); and the run's document from
its metadata (:func:`read_document`).

Every failure is a :class:`RecordError` whose ``str()`` is one line naming the file.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader

from gcs.records import topics as tp
from gcs.records.payloads import layout
from gcs.records.topics import MAGIC

_AGENT = re.compile(r"^/agent/(\d+)/(estimate|qp)$")


class RecordError(ValueError):
    """A file that is not a whole record of this project (one line)."""


@dataclass(frozen=True)
class RecordArrays:
    """The decoded ROS 2 topics of a record: ``ids`` (agents in id order), per agent the
    structured arrays of ``estimate`` and ``qp`` (one row per step, fields of
    :data:`~gcs.records.topics.ESTIMATE_FIELDS` / :data:`~gcs.records.topics.QP_FIELDS`, or
    :data:`~gcs.records.topics.QP_FIELDS_V1` in an older record) and ``pairs``
    (:func:`~gcs.records.topics.pairs_fields`)."""

    ids: list[int]
    estimate: dict[int, np.ndarray]
    qp: dict[int, np.ndarray]
    pairs: np.ndarray


def check_file(path: Path) -> None:
    """``RecordError`` unless ``path`` is a regular file starting with the MCAP magic."""
    if not path.exists():
        raise RecordError(f"{path}: no such file")
    if not path.is_file():
        raise RecordError(f"{path}: not a file")
    with path.open("rb") as f:
        head = f.read(len(MAGIC))
    if head != MAGIC:
        raise RecordError(f"{path}: not an MCAP file")


def read_arrays(path: Path) -> RecordArrays:
    """Decode ``path``'s ROS 2 topics; ``RecordError`` when the file is truncated, is not
    MCAP, or is another program's record (no ``/pairs`` of this project's schema)."""
    check_file(path)
    rows: dict[str, list[bytes]] = {}
    schemas: dict[str, tuple[str, bytes]] = {}
    try:
        with path.open("rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is None:
                raise RecordError(f"{path}: no summary section (truncated?)")
            for ch in summary.channels.values():  # a run without steps has channels only
                sch = summary.schemas.get(ch.schema_id)
                if sch is not None and ch.message_encoding == "cdr":
                    schemas[ch.topic] = (sch.name, sch.data)
                    rows.setdefault(ch.topic, [])
            for schema, channel, msg in reader.iter_messages(log_time_order=True):
                if schema is not None and channel.message_encoding == "cdr":
                    schemas[channel.topic] = (schema.name, schema.data)
                    rows.setdefault(channel.topic, []).append(msg.data)
    except RecordError:
        raise
    except (McapError, EOFError, OSError, ValueError, KeyError, AssertionError) as exc:
        why = " ".join(str(exc).split())[:160] or type(exc).__name__
        raise RecordError(f"{path}: not a readable MCAP record ({why})") from None
    if tp.PAIRS not in schemas or schemas[tp.PAIRS][0] != tp.PAIRS_SCHEMA:
        raise RecordError(f"{path}: not a bearing-swarm record (no {tp.PAIRS} topic)")
    est: dict[int, np.ndarray] = {}
    qp: dict[int, np.ndarray] = {}
    for topic, data in rows.items():
        m = _AGENT.match(topic)
        if m is None:
            continue
        fields = tp.ESTIMATE_FIELDS if m.group(2) == "estimate" else tp.QP_FIELDS
        if fields is tp.QP_FIELDS and schemas[topic][1] == tp.ros2msg(tp.QP_FIELDS_V1).encode():
            fields = tp.QP_FIELDS_V1  # a record written before the filter's report
        (est if m.group(2) == "estimate" else qp)[int(m.group(1))] = _decode(
            path, topic, schemas[topic], fields, data)
    ids = sorted(est)
    if not ids or sorted(qp) != ids:
        raise RecordError(f"{path}: the agents' estimate and qp topics do not match")
    n = len(ids)
    fields = tp.pairs_fields(tp.recorded_pair_count(n), max(ids))
    every = tp.pairs_fields(n * (n - 1) // 2, max(ids))
    if schemas[tp.PAIRS][1].decode(errors="replace") == tp.ros2msg(every):
        fields = every  # a record of more than 64 agents written with every pair
    pairs = _decode(path, tp.PAIRS, schemas[tp.PAIRS], fields, rows[tp.PAIRS])
    return RecordArrays(ids, est, qp, pairs)


def read_document(path: Path) -> dict[str, Any]:
    """The run's ``metrics.json`` document as the record's metadata keeps it (``run``:
    scenario, method, seed; ``metrics``: the metrics, :func:`gcs.records.writer.write_mcap`);
    ``RecordError`` when the file is not a readable MCAP record or has no such metadata."""
    check_file(path)
    meta: dict[str, dict[str, str]] = {}
    try:
        with path.open("rb") as f:
            for m in make_reader(f).iter_metadata():
                meta[m.name] = dict(m.metadata)
    except (McapError, EOFError, OSError, ValueError, KeyError, AssertionError) as exc:
        why = " ".join(str(exc).split())[:160] or type(exc).__name__
        raise RecordError(f"{path}: not a readable MCAP record ({why})") from None
    run = meta.get("run")
    if run is None or "scenario" not in run:
        raise RecordError(f"{path}: not a bearing-swarm record (no run metadata)")
    try:
        metrics = json.loads(meta.get("metrics", {}).get("json", "{}"))
    except ValueError:
        raise RecordError(f"{path}: its metrics metadata is not JSON") from None
    seed = run.get("seed", "")
    return {"scenario": run["scenario"], "method": run.get("method"),
            "seed": int(seed) if seed.lstrip("-").isdigit() else seed,
            "metrics": metrics if isinstance(metrics, dict) else {}}


def _decode(path: Path, topic: str, schema: tuple[str, bytes],
            fields: tuple[tuple[str, str, str], ...], data: list[bytes]) -> np.ndarray:
    if schema[1].decode(errors="replace") != tp.ros2msg(fields):
        raise RecordError(f"{path}: {topic} has another schema than this version writes")
    dt = layout(fields)
    if any(len(d) != dt.itemsize for d in data):
        raise RecordError(f"{path}: {topic}: a message of the wrong size")
    return np.frombuffer(b"".join(data), dt)
