"""A follower's fence swapped in flight: the one its vehicle stores, when a ground station
uploaded another (offboard.daemon.fence_sync; docs/world.md, "A fence uploaded over
MAVLink").

The obstacles stay; the fence's planes are replaced in the follower's
:class:`~offboard.safety.dcbf.world_rows.WorldPlanes`, which the dcbf filter and the detour
read at every step, so the swap takes effect at the next step. A fence with more faces
than the filter has room for grows its row buffers (the compiled front then takes them
again); nothing else of the filter changes, so its state carries over.
"""

from __future__ import annotations

from offboard.safety.dcbf.filter import DcbfFilter
from offboard.safety.dcbf.front import DcbfFront
from offboard.safety.dcbf.world_rows import WorldPlanes
from swarm_common.world.config import Geofence, make_world


def swap_fence(world: WorldPlanes | None, filt: DcbfFilter, front: DcbfFront,
               fence: Geofence, range_m: float) -> WorldPlanes:
    """``world`` (None: the scenario has none) with ``fence`` as its fence, its rows within
    ``range_m`` (m); call between two steps."""
    if world is None:
        world = WorldPlanes(make_world((), None), range_m)
    before = world.capacity
    world.set_fence(fence)
    if filt.reserve_world(world.capacity - before):
        front.rebind()
    return world
