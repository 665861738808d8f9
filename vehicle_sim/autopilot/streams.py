"""Telemetry stream schedules of one vehicle (MAV_CMD_SET/GET_MESSAGE_INTERVAL).

Intervals are wall-clock seconds (0 = off). SET_MESSAGE_INTERVAL changes one stream
(-1 µs: off, 0: back to the link's default, else clamped to [10 ms, 2000 s]: no stream
faster than 100 Hz, whatever is asked). HEARTBEAT is the link's liveness: never off, at
least 1 Hz, at most 50 Hz.

Per link, as PX4 configures each MAVLink instance by its mode
(``Mavlink::configure_streams_to_default``): the API link starts from the *onboard* set
(:data:`vehicle_sim.autopilot.config.DEFAULT_RATES`, ODOMETRY at ``odometry_hz``: the
offboard daemon's input), the GCS link from PX4's *normal* set
(:data:`vehicle_sim.autopilot.config.GCS_RATES`: ATTITUDE 15 Hz, no ODOMETRY). Every
stream the vehicle can build is known on both links (off where the set leaves it out),
so a client may switch on any of them on its own link.

Rates are per peer (:class:`PeerStreams`): a rate request (SET_MESSAGE_INTERVAL,
REQUEST_DATA_STREAM) changes the schedule of the peer that sent it only, starting from
its link's set; every other destination keeps its link's defaults. A peer's schedule
lives as long as the link counts the peer as present (it spoke within
``endpoint.PEER_TIMEOUT_S``): once it falls silent its schedule is dropped, so the next
client, even one on the same address, starts from the defaults again. PX4 keeps
requested rates for the life of its MAVLink instance, which on a UDP link outlives the
client that asked; resetting on silence stops one client's rates from leaking into the
next one's (docs/px4/streams.md).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from pymavlink.dialects.v20 import common as M

from vehicle_sim.autopilot.config import GCS_RATES

# a destination with its own schedule: (link name, (host, port))
PeerKey = tuple[str, tuple[str, int]]
# what a due stream is for: one peer, or (link name, None) = the link's default schedule
StreamKey = tuple[str, tuple[str, int] | None]

LINK_API, LINK_GCS = "api", "gcs"
MIN_INTERVAL_S = 0.01  # 100 Hz at most per stream and destination
MAX_INTERVAL_S = 2000.0  # fits the int32 µs of MESSAGE_INTERVAL
HEARTBEAT_MIN_S, HEARTBEAT_MAX_S = 0.02, 1.0
DUE_SLACK_S = 1e-3  # a stream due within this much is sent now
ODOMETRY = M.MAVLINK_MSG_ID_ODOMETRY


def _interval(hz: float) -> float:
    return 1.0 / hz if hz > 0 else 0.0


class StreamSchedule:
    """Which message ids are due on the wall clock, from default rates (Hz, 0 = off;
    ``odometry_hz``, if given, sets ODOMETRY's)."""

    def __init__(self, rates: dict[int, float], odometry_hz: float | None = None) -> None:
        self.defaults = dict(rates)
        if odometry_hz is not None:
            self.defaults[ODOMETRY] = odometry_hz
        self.intervals: dict[int, float] = {m: _interval(hz) for m, hz in self.defaults.items()}
        self._next_due: dict[int, float] = {}
        # (skip, earliest next due time of the streams a due(…, skip) call considers):
        # calls before that time return at once (they run on every loop pass)
        self._quiet: tuple[tuple[int, ...], float] | None = None

    def __contains__(self, mid: int) -> bool:
        return mid in self.intervals

    def interval_us(self, mid: int) -> int:
        """MESSAGE_INTERVAL.interval_us of a known stream (-1 = off)."""
        iv = self.intervals[mid]
        return int(round(iv * 1e6)) if iv else -1

    def set_interval(self, mid: int, interval_us: float, wall: float) -> None:
        """SET_MESSAGE_INTERVAL for a known stream; the next one is due at ``wall``."""
        if interval_us < 0:
            self.intervals[mid] = 0.0
        elif interval_us == 0:
            self.intervals[mid] = _interval(self.defaults.get(mid, 0.0))
        else:
            self.intervals[mid] = min(max(interval_us * 1e-6, MIN_INTERVAL_S), MAX_INTERVAL_S)
        if mid == M.MAVLINK_MSG_ID_HEARTBEAT:
            iv = self.intervals[mid]
            iv = iv if iv > 0 else HEARTBEAT_MAX_S
            self.intervals[mid] = min(HEARTBEAT_MAX_S, max(HEARTBEAT_MIN_S, iv))
        self._next_due[mid] = wall
        self._quiet = None

    def due(self, wall: float, skip: tuple[int, ...] = ()) -> list[int]:
        """The streams whose interval has elapsed at ``wall`` (and book their next time).

        A stream keeps its phase (next = previous due + interval) so its mean rate is the
        requested one even when calls come late; one that fell more than an interval
        behind restarts from ``wall`` (no burst of catch-up frames)."""
        quiet = self._quiet
        if quiet is not None and quiet[0] == skip and wall + DUE_SLACK_S < quiet[1]:
            return []
        out: list[int] = []
        earliest = math.inf
        for mid, iv in self.intervals.items():
            if iv <= 0 or mid in skip:
                continue
            due = self._next_due.get(mid)
            if due is None:
                due = wall
            if wall + DUE_SLACK_S >= due:
                out.append(mid)
                due += iv
                if due < wall:
                    due = wall + iv
            self._next_due[mid] = due
            earliest = min(earliest, due)
        self._quiet = (skip, earliest)
        return out


class PeerStreams:
    """Per link a default schedule (every destination of the link without requests of
    its own) and one schedule per peer that asked for a rate.

    ``rates``: the API link's set (ODOMETRY at ``odometry_hz``); ``gcs_rates``: the GCS
    link's (default :data:`~vehicle_sim.autopilot.config.GCS_RATES`). A link of another
    name uses the API set."""

    def __init__(
        self, rates: dict[int, float], odometry_hz: float,
        gcs_rates: dict[int, float] | None = None,
    ) -> None:  # fmt: skip
        api = dict(rates)
        api[ODOMETRY] = odometry_hz
        gcs = dict(GCS_RATES if gcs_rates is None else gcs_rates)
        known = sorted(set(api) | set(gcs))
        self.link_rates: dict[str, dict[int, float]] = {
            LINK_API: {m: api.get(m, 0.0) for m in known},
            LINK_GCS: {m: gcs.get(m, 0.0) for m in known},
        }
        self.defaults = {name: StreamSchedule(r) for name, r in self.link_rates.items()}
        self.peers: dict[PeerKey, StreamSchedule] = {}

    @property
    def default(self) -> StreamSchedule:
        """The API link's default schedule."""
        return self.defaults[LINK_API]

    def rates_for(self, link: str) -> dict[int, float]:
        """The default rates (Hz) of ``link``."""
        return self.link_rates.get(link, self.link_rates[LINK_API])

    def __contains__(self, mid: int) -> bool:
        return mid in self.default

    def for_peer(self, key: PeerKey | None, create: bool = False) -> StreamSchedule:
        """The schedule of ``key`` (with ``create``, a fresh one from its link's set when
        it has none); else its link's default; the API link's default if None."""
        if key is None:
            return self.default
        if create and key not in self.peers:
            self.peers[key] = StreamSchedule(self.rates_for(key[0]))
        sched = self.peers.get(key)
        if sched is not None:
            return sched
        return self.defaults.get(key[0], self.default)

    def custom(self, link: str) -> set[tuple[str, int]]:
        """Addresses on ``link`` that have their own schedule (not on the default one)."""
        return {addr for name, addr in self.peers if name == link}

    def forget(self, live: Iterable[PeerKey]) -> None:
        """Drop the schedules of peers that are gone: their rates end with them."""
        keep = set(live)
        for key in [k for k in self.peers if k not in keep]:
            del self.peers[key]

    def due(self, wall: float, skip: tuple[int, ...] = ()) -> list[tuple[StreamKey, int]]:
        """(destination, message id) due at ``wall``: ``(link, None)`` for a link's
        default schedule, ``(link, addr)`` for one peer's."""
        out: list[tuple[StreamKey, int]] = []
        for name, sched in self.defaults.items():
            out.extend(((name, None), m) for m in sched.due(wall, skip))
        for key, sched in self.peers.items():
            out.extend((key, m) for m in sched.due(wall, skip))
        return out
