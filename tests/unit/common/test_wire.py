"""Zenoh payload codecs and the port scheme (swarm_common)."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest

from swarm_common import wire
from swarm_common.ports import GCS_PORT, vehicle_ports


def _truth(n: int = 3) -> wire.Truth:
    rng = np.random.default_rng(0)
    return wire.Truth(
        step=7,
        t=0.14,
        ids=list(range(1, n + 1)),
        p=rng.normal(size=(n, 3)) * 5,
        v=rng.normal(size=(n, 3)),
        att=rng.normal(size=(n, 3)) * 0.1,
        thrust=np.full(n, 17.658),
        lumped=rng.normal(size=(n, 3)) * 0.1,
        armed=[True] * n,
        mode=["OFFBOARD"] * n,
        collisions=2,
    )


def test_truth_roundtrip_is_float32_rounding() -> None:
    t = _truth()
    r = wire.roundtrip(t)
    assert isinstance(r, wire.Truth)
    assert r.step == 7 and r.ids == [1, 2, 3] and r.collisions == 2
    # exactly what float32 rounding gives, no more, no less
    np.testing.assert_array_equal(r.p, t.p.astype(np.float32).astype(np.float64))
    assert np.max(np.abs(r.p - t.p)) < 1e-6 * np.max(np.abs(t.p)) + 1e-12
    # a second trip changes nothing (idempotent: in-process == distributed)
    np.testing.assert_array_equal(wire.roundtrip(r).p, r.p)


def test_estimate_status_command_roundtrip() -> None:
    e = wire.Estimate(4, 10, 0.22, "follower", np.ones(3), np.zeros(3), np.ones(3) * 0.5,
                      np.arange(12.0))
    r = wire.roundtrip(e)
    assert isinstance(r, wire.Estimate) and r.id == 4 and r.xi.shape == (12,)
    s = wire.Status(3, 1, 0.02, "OFFBOARD", "rcbf", "solved", 55.0, 1.2, 0.3, "ok", 0)
    rs = wire.roundtrip(s)
    assert isinstance(rs, wire.Status) and rs.qp_status == "solved" and rs.h_min == 1.2
    assert rs.input_clipped is False
    s.input_clipped = True
    rc = wire.roundtrip(s)
    assert isinstance(rc, wire.Status) and rc.input_clipped is True
    c = wire.roundtrip(wire.Command("outage", agent=0, duration_s=0.5))
    assert isinstance(c, wire.Command) and c.duration_s == 0.5


def test_estimate_cooperative_flag() -> None:
    e = wire.Estimate(4, 10, 0.22, "follower", np.ones(3), np.zeros(3), np.zeros(3),
                      np.arange(12.0))
    plain = wire.encode(e)
    assert b"coop" not in plain  # the default adds nothing: old receivers decode it as before
    back = wire.decode(plain)
    assert isinstance(back, wire.Estimate) and back.cooperative is True
    e.cooperative = False
    back = wire.roundtrip(e)
    assert isinstance(back, wire.Estimate) and back.cooperative is False
    d = msgpack.unpackb(wire.encode(e), raw=False)
    d["coop"] = 1  # not a bool
    with pytest.raises(wire.WireError, match="coop"):
        wire.decode(msgpack.packb(d, use_bin_type=True))


@pytest.mark.parametrize(
    "payload",
    [
        b"",
        b"\x00\x01garbage",
        msgpack.packb([1, 2, 3]),
        msgpack.packb({"v": 99, "k": "truth"}),
        msgpack.packb({"v": 1, "k": "nope"}),
        msgpack.packb({"v": 1, "k": "est", "id": 3}),
        msgpack.packb({"v": 1, "k": "est", "id": 3, "step": 1, "t": 0.0, "role": "f",
                       "x": b"\x00" * 5}),
    ],
)
def test_malformed_payloads_raise_wire_error(payload: bytes) -> None:
    with pytest.raises(wire.WireError):
        wire.decode(payload)


def test_keys() -> None:
    assert wire.key_truth("cube8") == "swarm/cube8/truth"
    assert wire.key_estimate("cube8", 3) == "swarm/cube8/agent/3/estimate"
    assert wire.agent_id_from_key("swarm/cube8/agent/12/status") == 12
    with pytest.raises(wire.WireError):
        wire.agent_id_from_key("swarm/cube8/truth")


def test_port_scheme_px4_compatible_and_collision_free_to_255() -> None:
    v1 = vehicle_ports(1)
    got = (v1.api_local, v1.api_remote, v1.gcs_local, v1.gcs_remote)
    assert got == (14580, 14540, 18570, 14550)
    assert vehicle_ports(10).api_remote == 14549
    used: set[int] = set()
    for i in range(1, 256):
        vp = vehicle_ports(i)
        mine = {vp.api_local, vp.api_remote, vp.gcs_local}
        assert len(mine) == 3 and not (mine & used) and GCS_PORT not in mine
        used |= mine
    assert vehicle_ports(5, offset=1000).api_local == 14584 + 1000
    with pytest.raises(ValueError):
        vehicle_ports(0)


def test_port_free_sees_a_bound_socket() -> None:
    import socket

    from swarm_common.ports import port_free, swarm_udp_ports

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    try:
        assert not port_free(port)
    finally:
        s.close()
    assert port_free(port)
    ports = swarm_udp_ports([1, 2], offset=1000)
    assert ports[0] == 14550 + 1000 and len(ports) == 1 + 2 * 3 and len(set(ports)) == 7


def test_a_truth_carries_the_fences_that_changed() -> None:
    t = _truth()
    assert "fence" not in msgpack.unpackb(wire.encode(t))  # none changed: not on the wire
    t.fences = {2: np.array([0.0, 0.0, 8.0, 0.0, 8.0, 6.0]), 3: np.zeros(0)}
    r = wire.roundtrip(t)
    assert isinstance(r, wire.Truth) and set(r.fences) == {2, 3}
    np.testing.assert_array_equal(r.fences[2], [0.0, 0.0, 8.0, 0.0, 8.0, 6.0])
    assert r.fences[3].size == 0


@pytest.mark.parametrize("fence", [
    {"9": b""},  # not a vehicle of the truth
    {"x2": b""},  # not an id
    {"2": np.float32([1.0, 2.0, 3.0]).tobytes()},  # odd: not (x, y) pairs
    {"2": np.float32([1.0, np.nan]).tobytes()},  # not finite
    {"2": np.zeros(130, np.float32).tobytes()},  # more than 64 vertices
    {"2": "abc"},  # not bytes
    [1, 2],  # not a map
])
def test_a_bad_fence_in_a_truth_is_a_wire_error(fence) -> None:
    d = msgpack.unpackb(wire.encode(_truth()))
    d["fence"] = fence
    with pytest.raises(wire.WireError):
        wire.decode(msgpack.packb(d, use_bin_type=True))
