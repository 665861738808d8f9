"""Every choice the product makes, as a ``StrEnum``: one vocabulary for all packages.

A ``StrEnum`` member *is* its string (``Method.RCBF == "rcbf"``), so scenario files,
wire records and command lines carry the plain word, while code compares against the
member and a type checker sees the closed set.
"""

from __future__ import annotations

from enum import IntFlag, StrEnum


class Method(StrEnum):
    """Collision-avoidance method of a follower (paper Section 5 comparison)."""

    RCBF = "rcbf"  # CLF + reciprocal CBF QP (paper Section 4), as the paper poses it
    DCBF = "dcbf"  # CLF + sampled-data CBF QP over the realisable input set (docs/safety.md)
    APF = "apf"  # nominal controller + improved artificial potential field
    NONE = "none"  # nominal controller only, no avoidance


class Role(StrEnum):
    """An agent's role in the bearing formation."""

    LEADER = "leader"
    FOLLOWER = "follower"


class GraphKind(StrEnum):
    """Neighbour (sensing) graph of the formation (docs/graphs.md)."""

    CUBE_FACE_DIAGONALS = "cube_face_diagonals"
    COMPLETE = "complete"
    KNN = "knn"  # each vertex to its formation.knn_k nearest, symmetrised
    RANGE = "range"  # pairs within formation.sensing_range_m in the desired formation
    EDGES = "edges"  # the id pairs listed in formation.edges


class NoiseDraws(StrEnum):
    """Which pairs a follower's sensor draws noise for each step (docs/scenarios.md
    ``[sensing] noise_draws``)."""

    EVERY_AGENT = "every_agent"  # N×9 draws a step, whatever is in range (the default)
    IN_RANGE = "in_range"  # 9 draws per pair in range: the cost follows the neighbours


class QPStatus(StrEnum):
    """Outcome of one safety-filter step (``offboard.safety.rcbf.clf_rcbf.QPResult.status``)."""

    INACTIVE = "inactive"  # no QP was needed (no constraint near, or not rcbf)
    SOLVED = "solved"  # the QP was solved as posed (OSQP, or exactly: one active row, dcbf)
    RELAXED = "relaxed"  # hard rows were relaxed to regain feasibility
    FALLBACK = "fallback"  # solver failed: documented safe fallback applied

    @property
    def degraded(self) -> bool:
        """True when the step did not solve the QP as posed (counted as a fallback)."""
        return self in (QPStatus.RELAXED, QPStatus.FALLBACK)


class QPRow(IntFlag):
    """The kinds of a safety QP's rows, as bits: which kinds had a row active (tight) at
    the solution of a step (``offboard.records.ActiveRows``, docs/records.md)."""

    CLF = 1  # the soft CLF row (active: its slack δ > 0)
    PAIR = 2  # a barrier row of a pair (another agent, sensed or predicted)
    GROUND = 4  # a ground-barrier row (dcbf)
    OBSTACLE = 8  # a row of an obstacle's tangent plane (dcbf, docs/world.md)
    FENCE = 16  # a row of a geofence face (dcbf)
    INPUT = 32  # a bound of the input set (dcbf: the polytope; rcbf: the box)
    SPEED = 64  # a row of the dcbf transient speed limit (docs/safety.md §5i)


class QPSolver(StrEnum):
    """Solver of the followers' safety QPs (``[controller] qp_solver``; docs/safety.md §4b)."""

    DAQP = "daqp"  # dual active-set method: the exact optimum of these small dense QPs
    OSQP = "osqp"  # operator splitting (ADMM) with polishing: the solver of earlier rounds


class FailsafeAction(StrEnum):
    """What a vehicle does when its offboard setpoints stop (PX4 ``COM_OBL_RC_ACT``)."""

    HOLD = "hold"
    LAND = "land"


class VehicleMode(StrEnum):
    """The flight modes ``vehicle-sim`` implements, by the short names it reports
    (docs/px4/modes.md). HOLD is PX4's AUTO.LOITER; the AUTO sub-modes otherwise carry
    pymavlink's names."""

    POSCTL = "POSCTL"
    OFFBOARD = "OFFBOARD"
    HOLD = "HOLD"
    LAND = "LAND"
    ALTCTL = "ALTCTL"
    TAKEOFF = "TAKEOFF"
    RTL = "RTL"
    MISSION = "MISSION"


class StartMode(StrEnum):
    """Where a mission starts (``[lifecycle] start``; docs/lifecycle.md)."""

    AIRBORNE = "airborne"  # agents start at their ``position`` in the air (the paper's setup)
    GROUND = "ground"  # ``position`` is a pad on the ground; coordinated take-off first


class FaultLink(StrEnum):
    """A transport that fault injection applies to (``[faults.<link>]``, docs/faults.md)."""

    MAVLINK = "mavlink"
    ZENOH = "zenoh"


class FaultLinkChoice(StrEnum):
    """``gcs mission run --fault-link``: one transport or both."""

    MAVLINK = "mavlink"
    ZENOH = "zenoh"
    BOTH = "both"


class SensingSource(StrEnum):
    """``offboard --sensing``: where a daemon's sensor takes positions and velocities from
    (docs/px4/offboard-component.md)."""

    TRUTH = "truth"  # the simulator's truth topic
    ODOMETRY = "odometry"  # every vehicle's own ODOMETRY, shared by its daemon over Zenoh


class NavKind(StrEnum):
    """What the simulated vehicle's own position controller does with a
    :class:`vehicle_sim.autopilot.nav.NavTarget` (AUTO modes, missions, RTL)."""

    TAKEOFF = "takeoff"  # climb vertically to position_enu[2] above the current x, y
    GOTO = "goto"  # fly to position_enu and hold there
    LOITER = "loiter"  # hold position_enu (a waypoint's hold time is the executor's job)
    LAND = "land"  # descend at the land speed onto (x, y) of position_enu, then disarm
    RTL = "rtl"  # climb to the return altitude, fly over home, land


class Shape(StrEnum):
    """Formation shapes of the scenario generator (``gcs scenario SHAPE``; docs/scenarios.md)."""

    GRID = "grid"  # near-cubic box, filled layer by layer from the bottom
    RING = "ring"  # one horizontal circle
    SPHERE = "sphere"  # Fibonacci lattice on a sphere
    HELIX = "helix"  # HELIX_PER_TURN vertices per turn, one spacing between turns


class DefaultStreams(StrEnum):
    """Where ``vehicle-sim`` sends a link's default telemetry (``--default-streams``)."""

    ALWAYS = "always"  # to the link's default remote whether or not anyone listens (PX4)
    ON_CONTACT = "on-contact"  # HEARTBEAT only, until a client there speaks


class CommandKind(StrEnum):
    """A ground-station ``wire.Command``'s ``kind``: the word on the wire and the last part
    of its Zenoh key (docs/lifecycle.md)."""

    METHOD = "method"  # switch the followers' collision-avoidance method
    OUTAGE = "outage"  # inject a communication outage of duration_s
    LAND = "land"  # coordinated land-all at at_s
    TAKEOFF = "takeoff"  # coordinated take-off of a ground start at at_s
    MISSION = "mission"  # the leaders fly these formation waypoints from at_s (docs/missions.md)
    HOLD = "hold"  # the formation stops at its next rest from at_s and stays there
    LIVE = "live"  # the formation's centroid flies at a velocity from at_s, briefly


class AgentAlarm(IntFlag):
    """Safety alarms an agent raises in flight: a bitmask in its status record, one bit per
    assumption of docs/safety.md found broken at that step. Scored per run into
    ``metrics.json`` ``safety_alarms`` (docs/metrics.md)."""

    RESIDUAL = 1  # the observer's residual over its bound: its estimates may be diverging
    NEAR_ENTRY = 2  # a neighbour first heard closer than the distance it must be heard at
    FALLBACK = 4  # the agent left formation control for its safe fallback (hold, then land)
    DEADLOCK = 8  # its formation error stalls while its filter holds it (a liveness event)
    # the vehicle stores a fence the filter cannot take: the filter keeps its own fence, so
    # the filter and the simulator's breach check disagree (docs/world.md)
    FENCE_MISMATCH = 16


# No alarm: one shared value (an IntFlag built from an int costs an enum lookup, and the
# guard and monitor of every follower start each step from none)
NO_ALARM = AgentAlarm(0)


class SafetyAlarmKind(StrEnum):
    """The ``assumption`` of one ``metrics.json`` ``safety_alarms`` entry (docs/metrics.md):
    what the run found broken, from the truth (barrier, collision, ground strike, obstacle,
    geofence) or from an agent's own
    alarm bits (:class:`AgentAlarm`)."""

    BARRIER = "barrier"  # a pair's true barrier h < 0
    OWN_BARRIER = "own_barrier"  # an agent's barrier from its own estimates < 0: margin used up
    COLLISION = "collision"  # two vehicles closer than the collision radius
    GROUND_STRIKE = "ground_strike"  # a vehicle hit the ground faster than a landing
    OBSTACLE = "obstacle"  # a vehicle's true obstacle barrier < 0 (docs/world.md)
    GEOFENCE = "geofence"  # a vehicle's true geofence barrier < 0
    RESIDUAL = "residual"  # AgentAlarm.RESIDUAL
    NEAR_ENTRY = "near_entry"  # AgentAlarm.NEAR_ENTRY
    FALLBACK = "fallback"  # AgentAlarm.FALLBACK
    DEADLOCK = "deadlock"  # AgentAlarm.DEADLOCK: liveness, not safety (the verdict ignores it)
    FENCE_MISMATCH = "fence_mismatch"  # AgentAlarm.FENCE_MISMATCH
