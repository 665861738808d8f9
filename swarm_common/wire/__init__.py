"""Zenoh key expressions and payloads: defined once, here (docs/architecture.md §Zenoh).

Keys, under one root and a swarm name (``swarm/<name>/...``):

=====================================  ==========================================  ==========
key                                    payload                                     publisher
=====================================  ==========================================  ==========
``<root>/<swarm>/truth``               :class:`Truth` (all vehicles, one message;  vehicle-sim
                                       with a stored fence that changed, its
                                       outline)
``<root>/<swarm>/agent/<id>/estimate`` :class:`Estimate` (post-update, for t_k+1)  offboard
``<root>/<swarm>/agent/<id>/status``   :class:`Status`                             offboard
``<root>/<swarm>/agent/<id>/odometry`` :class:`Odometry` (own vehicle, ENU, at t_k) offboard
``<root>/<swarm>/cmd/method``          :class:`Command` kind="method"              gcs
``<root>/<swarm>/cmd/outage``          :class:`Command` kind="outage"              gcs
``<root>/<swarm>/cmd/land``            :class:`Command` kind="land"                gcs
``<root>/<swarm>/cmd/takeoff``         :class:`Command` kind="takeoff"             gcs
``<root>/<swarm>/cmd/mission``         :class:`Command` kind="mission"             gcs
``<root>/<swarm>/cmd/hold``            :class:`Command` kind="hold"                gcs
``<root>/<swarm>/cmd/live``            :class:`Command` kind="live"                gcs
=====================================  ==========================================  ==========

Payloads are msgpack maps with a version field ``"v": 1``; every float vector is
packed as little-endian float32 bytes, so both ends (and the in-process runner, which
pushes its values through the same :func:`encode` / :func:`decode`) see identical
float32-rounded numbers. A payload that fails to decode raises :class:`WireError`
(receivers count and drop it).

The package's modules: :mod:`.payloads` (the dataclasses and :func:`encode`),
:mod:`.validate` (:func:`decode`, every field checked, and :func:`roundtrip`) and
:mod:`.keys` (the key expressions). Import the names from here: ``from swarm_common import
wire`` then ``wire.Estimate``, ``wire.decode(data)``, ``wire.key_truth(swarm)``.
"""

from __future__ import annotations

from swarm_common.wire.keys import (
    DEFAULT_ROOT,
    agent_id_from_key,
    key_cmd,
    key_estimate,
    key_odometry,
    key_status,
    key_truth,
)
from swarm_common.wire.payloads import (
    COMMAND_KINDS,
    MAX_FENCE_COORDS,
    MAX_MISSION_TEXT,
    VERSION,
    Command,
    Estimate,
    Odometry,
    Payload,
    Status,
    Truth,
    WireError,
    encode,
    f32,
)
from swarm_common.wire.validate import decode, roundtrip

__all__ = [
    "COMMAND_KINDS", "DEFAULT_ROOT", "MAX_FENCE_COORDS", "MAX_MISSION_TEXT", "VERSION",
    "Command", "Estimate", "Odometry", "Payload", "Status", "Truth", "WireError",
    "agent_id_from_key", "decode", "encode", "f32", "key_cmd", "key_estimate",
    "key_odometry", "key_status", "key_truth", "roundtrip",
]
