"""The filter follows the fence its vehicle stores (docs/world.md, "A fence uploaded over
MAVLink").

The simulator enforces whatever fence its vehicle stores: the scenario's ``[geofence]``
at start, or one a ground station uploaded since. The daemon downloads it
(:mod:`offboard.daemon.mavlink.fence_download`) and here decides what the follower's
dcbf filter keeps, so that the filter and the simulator agree:

* the same outline as the filter's fence (to :data:`~swarm_common.world.mavlink_fence.
  MATCH_TOL_M`): nothing changes, bit for bit. That is every run where nobody uploads, so a
  lockstep run stays deterministic and equal to the same run in process;
* another convex inclusion polygon: the filter takes it at the next step boundary, with
  the altitude band and margin of its fence (MAVLink's zones carry no altitude);
* a fence the filter cannot represent (non-convex, exclusion zones, circles, several
  inclusion polygons, too many vertices) or no fence at all: the filter keeps its fence,
  and one WARNING line says that the filter and the simulator disagree;
* a download that failed or is not a valid fence: counted in :attr:`FenceSync.bad`,
  dropped, one WARNING line; the filter keeps its fence.

Latitudes and longitudes are read about the vehicle's GPS_GLOBAL_ORIGIN, the origin of the
local frame its odometry (and so the filter) is in. A download finished before the first
origin waits for it; a vehicle that sends none within :data:`ORIGIN_WAIT_S` has its fence
read about the default origin (:data:`~swarm_common.world.geodesy.DEFAULT_ORIGIN`), with
one WARNING line. An origin that moves later has the last download read again about it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from swarm_common.enums import AgentAlarm
from swarm_common.world import geodesy
from swarm_common.world.config import Geofence
from swarm_common.world.mavlink_fence import (
    FenceItem,
    filter_fence,
    horizontal_vertices,
    read_fence,
    same_outline,
)

log = logging.getLogger("offboard.daemon.core")  # the daemon's lines keep one logger name

ORIGIN_WAIT_S = 5.0  # s (monotonic) a finished download waits for the vehicle's origin


class FenceSync:
    """The filter's fence of agent ``agent_id`` against its vehicle's. ``fence``: the
    scenario's (what the filter starts with); ``apply(fence)``: swap the filter's fence,
    False when its agent has no world rows (not dcbf)."""

    def __init__(self, agent_id: int, fence: Geofence | None, d_safe: float,
                 apply: Callable[[Geofence], bool]) -> None:
        self.id = agent_id
        self.fence = fence  # the filter's fence now
        self.d_safe = d_safe
        self._apply = apply
        self.adopted = 0  # fences the filter took from its vehicle
        self.refused = 0  # fences it could not take (it kept its own)
        self.bad = 0  # downloads that failed or held no valid fence
        self.disagree = ""  # why the filter's fence is not the vehicle's; "" when it is
        self.origin: geodesy.Origin | None = None  # the vehicle's GPS_GLOBAL_ORIGIN
        # the last download, the origin it was read about (None: waiting for one) and the
        # monotonic time it finished
        self._last: tuple[int, list[FenceItem]] | None = None
        self._read_about: geodesy.Origin | None = None
        self._since = 0.0

    def on_download(self, got: tuple[int, list[FenceItem]] | str, now: float = 0.0) -> None:
        """One finished download (:meth:`FenceDownload.take
        <offboard.daemon.mavlink.fence_download.FenceDownload.take>`) at monotonic ``now``."""
        if isinstance(got, str):
            self._bad(f"the fence download failed: {got}")
            return
        self._last, self._read_about, self._since = got, None, now
        if self.origin is not None:
            self._read(self.origin)

    def on_origin(self, origin: geodesy.Origin | None, now: float) -> None:
        """The vehicle's GPS_GLOBAL_ORIGIN as last heard (None: none yet) at monotonic
        ``now``: a download waiting for it, or read about another, is read about it; one
        that waited ORIGIN_WAIT_S for none is read about the default origin."""
        if origin is None:
            if self._last is not None and self._read_about is None \
                    and now - self._since >= ORIGIN_WAIT_S:
                log.warning("agent %d: the vehicle sent no GPS_GLOBAL_ORIGIN in %g s; its "
                            "fence is read about the default origin", self.id, ORIGIN_WAIT_S)
                self._read(geodesy.DEFAULT_ORIGIN)
            return
        if origin is self.origin:  # the link's last message, seen before: nothing new
            return
        # a first origin other than the default, or one that moved: said once
        if geodesy.origin_offset_m(origin, self.origin or geodesy.DEFAULT_ORIGIN) > \
                geodesy.ORIGIN_SAME_M:
            log.info("agent %d: the vehicle's local origin is %.7f, %.7f (%.2f m from the "
                     "default)", self.id, origin[0], origin[1],
                     geodesy.origin_offset_m(origin, geodesy.DEFAULT_ORIGIN))
        self.origin = origin
        if self._last is not None and (self._read_about is None or geodesy.origin_offset_m(
                origin, self._read_about) > geodesy.ORIGIN_SAME_M):
            self._read(origin)

    @property
    def read_about(self) -> geodesy.Origin | None:
        """The origin the last download was read about; None before one was read."""
        return self._read_about

    def _read(self, origin: geodesy.Origin) -> None:
        """The last download, read about ``origin``."""
        if self._last is None:
            return
        self._read_about = origin
        fence_id, items = self._last
        read = read_fence(items, origin)
        which = f"fence_id {fence_id:#x}, {len(items)} items"
        if read.kind == "bad":
            self._bad(f"the vehicle's fence ({which}) is not valid: {read.reason}")
        elif read.kind == "none":
            self._keep(which, "it stores no inclusion zone", quiet=self.fence is None)
        elif read.kind == "unsupported":
            self._keep(which, f"the filter cannot represent {read.reason}")
        elif same_outline(read.xy, self.fence):
            if self.disagree:
                log.info("agent %d: the vehicle's fence (%s) is the filter's again", self.id,
                         which)
            self.disagree = ""
        else:
            self._take(which, read.xy)

    def _take(self, which: str, xy: tuple[tuple[float, float], ...]) -> None:
        fence = filter_fence(xy, self.fence, self.d_safe)
        if isinstance(fence, str):
            self._keep(which, fence)
            return
        if not self._apply(fence):
            self._keep(which, "this agent's filter has no world rows")
            return
        self.fence = fence
        self.adopted += 1
        self.disagree = ""
        bottom, top = fence.z_range_m
        log.warning("agent %d: the filter takes the vehicle's fence (%s): %d vertices %s, "
                    "z %g to %g m, margin %g m", self.id, which, len(xy),
                    _outline(horizontal_vertices(fence)), bottom, top, fence.margin_m)

    def _keep(self, which: str, why: str, quiet: bool = False) -> None:
        """The filter keeps its fence although the vehicle's differs (``quiet``: both have
        none, which is agreement)."""
        if quiet:
            self.disagree = ""
            return
        self.refused += 1
        self.disagree = why
        log.warning("agent %d: the vehicle's fence (%s): %s; the filter keeps its own: the "
                    "filter and the simulator disagree", self.id, which, why)

    def _bad(self, line: str) -> None:
        self.bad += 1
        log.warning("agent %d: %s; dropped, the filter keeps its fence", self.id, line)

    def alarm_bits(self) -> int:
        """:data:`~swarm_common.enums.AgentAlarm.FENCE_MISMATCH` while the filter keeps a
        fence other than the vehicle's (:attr:`disagree`), else 0: raised on every step's
        status, so the run's metrics, verdict and the dashboard say it, not the log alone."""
        return int(AgentAlarm.FENCE_MISMATCH) if self.disagree else 0

    def summary(self) -> str:
        """One line for the daemon's last words; "" when nothing happened."""
        if not (self.adopted or self.refused or self.bad):
            return ""
        state = f"disagree ({self.disagree})" if self.disagree else "agree"
        return (f"fence: {self.adopted} taken, {self.refused} kept against the vehicle's, "
                f"{self.bad} bad downloads; filter and simulator {state}")


def _outline(xy: tuple[tuple[float, float], ...]) -> str:
    return "[" + ", ".join(f"({x:.2f}, {y:.2f})" for x, y in xy) + "]"
