"""Telemetry stream schedule of one vehicle (MAV_CMD_SET/GET_MESSAGE_INTERVAL).

Intervals are wall-clock seconds (0 = off). Every stream starts at its default rate
(``config.DEFAULT_RATES``, ODOMETRY at ``odometry_hz``); SET_MESSAGE_INTERVAL changes
one (-1 µs: off, 0: back to the default, else clamped to [10 ms, 2000 s]: no stream
faster than 100 Hz, whatever is asked). HEARTBEAT is the link's liveness: never off, at
least 1 Hz, at most 50 Hz.

Rates are per peer (:class:`PeerStreams`): a rate request (SET_MESSAGE_INTERVAL,
REQUEST_DATA_STREAM) changes the schedule of the peer that sent it only; every other
destination keeps the defaults. A peer's schedule lives as long as the link counts the
peer as present (it spoke within ``mavlink_link.PEER_TIMEOUT_S``): once it falls silent
its schedule is dropped, so the next client, even one on the same address, starts from
the defaults again. PX4 keeps requested rates for the life of its MAVLink instance, which
on a UDP link outlives the client that asked; resetting on silence is the choice that
stops one client's rates from leaking into the next one's (docs/px4/streams.md).

The defaults are the same on both links of a vehicle (API and GCS): one default schedule,
packed once and sent to every destination that has no schedule of its own.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from pymavlink.dialects.v20 import common as M

# a destination with its own schedule: (link name, (host, port))
PeerKey = tuple[str, tuple[str, int]]

MIN_INTERVAL_S = 0.01  # 100 Hz at most per stream and destination
MAX_INTERVAL_S = 2000.0  # fits the int32 µs of MESSAGE_INTERVAL
HEARTBEAT_MIN_S, HEARTBEAT_MAX_S = 0.02, 1.0
DUE_SLACK_S = 1e-3  # a stream due within this much is sent now


def _interval(hz: float) -> float:
    return 1.0 / hz if hz > 0 else 0.0


class StreamSchedule:
    """Which message ids are due on the wall clock."""

    def __init__(self, rates: dict[int, float], odometry_hz: float) -> None:
        self.defaults = dict(rates)
        self.defaults[M.MAVLINK_MSG_ID_ODOMETRY] = odometry_hz
        self.intervals: dict[int, float] = {mid: _interval(hz) for mid, hz in rates.items()}
        self.intervals[M.MAVLINK_MSG_ID_ODOMETRY] = 1.0 / odometry_hz if odometry_hz else 0
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
        """The streams whose interval has elapsed at ``wall`` (and book their next time)."""
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
    """The default schedule (every destination without requests of its own) and one
    schedule per peer that asked for a rate."""

    def __init__(self, rates: dict[int, float], odometry_hz: float) -> None:
        self.rates = dict(rates)
        self.odometry_hz = odometry_hz
        self.default = StreamSchedule(self.rates, odometry_hz)
        self.peers: dict[PeerKey, StreamSchedule] = {}

    def __contains__(self, mid: int) -> bool:
        return mid in self.default

    def for_peer(self, key: PeerKey | None, create: bool = False) -> StreamSchedule:
        """The schedule of ``key`` (a fresh default one if ``create``); default if None."""
        if key is None:
            return self.default
        if create and key not in self.peers:
            self.peers[key] = StreamSchedule(self.rates, self.odometry_hz)
        return self.peers.get(key, self.default)

    def custom(self, link: str) -> set[tuple[str, int]]:
        """Addresses on ``link`` that have their own schedule (not on the default one)."""
        return {addr for name, addr in self.peers if name == link}

    def forget(self, live: Iterable[PeerKey]) -> None:
        """Drop the schedules of peers that are gone: their rates end with them."""
        keep = set(live)
        for key in [k for k in self.peers if k not in keep]:
            del self.peers[key]

    def due(self, wall: float, skip: tuple[int, ...] = ()) -> list[tuple[PeerKey | None, int]]:
        """(destination or None for the default schedule, message id) due at ``wall``."""
        out: list[tuple[PeerKey | None, int]] = [(None, m) for m in self.default.due(wall, skip)]
        for key, sched in self.peers.items():
            out.extend((key, m) for m in sched.due(wall, skip))
        return out
