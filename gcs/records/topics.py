"""The topic scheme of a run's MCAP record (docs/records.md): topic names, schema names and
the ROS 2 message definitions of the messages that have no Foxglove schema.

Frames: ``world`` (ENU, z up, metres) and ``vehicle_<id>`` (each vehicle's body, placed by
``/world/tf``; orientation identity: the series holds no attitude). Timestamps (log time,
publish time and every message's ``timestamp``) are the simulation time of the step, in
nanoseconds from the start of the run. Agents are named by their scenario id.
"""

from __future__ import annotations

MAGIC = b"\x89MCAP0\r\n"  # the first bytes of every MCAP file

WORLD_FRAME = "world"
TF = "/world/tf"  # foxglove.FrameTransforms: world -> vehicle_<id>, one per vehicle per step
SCENE = "/scene"  # foxglove.SceneUpdate: vehicles, bearings sensed, obstacles, geofence
DESIRED = "/formation/desired"  # foxglove.PosesInFrame: desired position of every agent
PAIRS = "/pairs"  # ros2msg Pairs: distance and barrier h of every pair, min of both
EVENTS = "/events"  # foxglove.Log: safety alarms, QP fallbacks, agent alarm bits, failures

# the Foxglove (protobuf) schema of each fixed topic
FOXGLOVE_SCHEMAS: dict[str, str] = {
    TF: "foxglove.FrameTransforms",
    SCENE: "foxglove.SceneUpdate",
    DESIRED: "foxglove.PosesInFrame",
    EVENTS: "foxglove.Log",
}
ESTIMATE_SCHEMA = "bearing_swarm/msg/AgentEstimate"
QP_SCHEMA = "bearing_swarm/msg/AgentQP"
PAIRS_SCHEMA = "bearing_swarm/msg/Pairs"
PROFILE = "bearing-swarm"  # the MCAP header's profile


def vehicle_frame(agent_id: int) -> str:
    """The frame of vehicle ``agent_id`` (child of ``world`` in ``/world/tf``)."""
    return f"vehicle_{agent_id}"


def estimate_topic(agent_id: int) -> str:
    """:data:`ESTIMATE_SCHEMA`: what the agent's observer believed beside the truth, one
    per step."""
    return f"/agent/{agent_id}/estimate"


def qp_topic(agent_id: int) -> str:
    """:data:`QP_SCHEMA`: the agent's safety filter at the step."""
    return f"/agent/{agent_id}/qp"


def all_topics(ids: list[int]) -> dict[str, str]:
    """Every topic of a record of agents ``ids`` -> its schema name."""
    out = dict(FOXGLOVE_SCHEMAS)
    out[PAIRS] = PAIRS_SCHEMA
    for i in ids:
        out[estimate_topic(i)] = ESTIMATE_SCHEMA
        out[qp_topic(i)] = QP_SCHEMA
    return out


# The messages without a Foxglove schema are ROS 2 messages (schema encoding ``ros2msg``,
# message encoding ``cdr``), which Foxglove and PlotJuggler decode: (name, type, comment)
# of each field in order, every float64 first (so no field needs padding).
ESTIMATE_FIELDS: tuple[tuple[str, str, str], ...] = (
    ("t_s", "float64", "simulation time (s)"),
    ("p_m", "float64[3]", "true position, world ENU (m)"),
    ("v_m_s", "float64[3]", "true velocity (m/s)"),
    ("p_des_m", "float64[3]", "desired position from the leaders' true positions (m)"),
    ("v_des_m_s", "float64[3]", "desired velocity from the leaders' true velocities (m/s)"),
    ("p_est_m", "float64[3]", "estimated position z1 (m)"),
    ("v_est_m_s", "float64[3]", "estimated velocity z2 (m/s)"),
    ("p_des_est_m", "float64[3]", "desired position estimated, xi_p (m)"),
    ("d_est_m_s2", "float64[3]", "estimated lumped disturbance z3 + Phi zeta_hat (m/s^2)"),
    ("d_true_m_s2", "float64[3]", "true lumped disturbance Phi zeta + d/m (m/s^2)"),
    ("p_err_m", "float64", "||p_est - p|| (m)"),
    ("v_err_m_s", "float64", "||v_est - v|| (m/s)"),
    ("d_err_m_s2", "float64", "||d_est - d_true|| (m/s^2)"),
    ("track_err_m", "float64", "||p - p_des|| (m)"),
)
# the first version of QP_FIELDS (records written before the filter's report; the reader
# still reads them)
QP_FIELDS_V1: tuple[tuple[str, str, str], ...] = (
    ("t_s", "float64", "simulation time (s)"),
    ("u_m_s2", "float64[3]", "virtual control commanded, world ENU (m/s^2)"),
    ("h_min_m2", "float64", "smallest barrier the agent computed from its estimates (m^2)"),
    ("solve_us", "float64", "QP solve time (microseconds)"),
    ("thrust_n", "float64", "actual thrust (N)"),
    ("tilt_deg", "float64", "actual tilt from vertical (deg)"),
    ("degraded", "bool", "the QP fell back (QPStatus.degraded)"),
    ("input_clipped", "bool", "the setpoint conversion changed u (tilt/thrust clip)"),
    ("alarms", "uint8", "AgentAlarm bits raised at the step"),
)
QP_FIELDS: tuple[tuple[str, str, str], ...] = (
    *QP_FIELDS_V1[:6],
    ("u_nom_m_s2", "float64[3]", "nominal (CLF) control before the safety filter (m/s^2)"),
    ("correction_m_s2", "float64", "the filter's correction ||u_f - u_nom|| (m/s^2)"),
    ("clf_slack_m_s2", "float64", "slack delta of the CLF row (m/s^2)"),
    ("relax_m_s2", "float64", "relaxation sigma of the barrier rows (m/s^2)"),
    *QP_FIELDS_V1[6:],
    ("qp_status", "uint8", "QP status: 0 inactive, 1 solved, 2 relaxed, 3 fallback, "
     "255 unknown"),
    ("active_rows", "uint8", "rows active (tight) at the QP's solution (255: 255 or more)"),
    ("active_kinds", "uint8", "their kinds, QPRow bits: 1 CLF, 2 pair, 4 ground, "
     "8 obstacle, 16 fence, 32 input bound"),
)


PAIRS_ALL_MAX = 2016  # /pairs holds every pair while there are at most this many (64 agents)
PAIRS_PER_AGENT = 4  # past that, this many closest pairs per agent and step (pair_table)


def recorded_pair_count(n: int) -> int:
    """The number of pairs each ``/pairs`` message of an ``n``-agent record holds: every
    pair up to :data:`PAIRS_ALL_MAX`, else :data:`PAIRS_PER_AGENT` × n
    (:mod:`gcs.records.pair_table`)."""
    every = n * (n - 1) // 2
    return every if every <= PAIRS_ALL_MAX else min(every, PAIRS_PER_AGENT * n)


def pairs_fields(n_pairs: int, max_id: int = 255) -> tuple[tuple[str, str, str], ...]:
    """The :data:`PAIRS_SCHEMA` fields of a record of ``n_pairs`` pairs i < j whose largest
    agent id is ``max_id``: the ids as uint8, or as uint16 past 255 (a swarm of more than
    255 agents, in process only; uint8 would wrap them)."""
    ids = "uint8" if max_id <= 255 else "uint16"
    return (
        ("t_s", "float64", "simulation time (s)"),
        ("min_distance_m", "float64", "smallest pair distance over the period after t (m; "
         "metrics.json min_distance_m is its minimum)"),
        ("min_h_m2", "float64", "smallest true barrier h over the pairs at t (m^2)"),
        ("distance_m", f"float64[{n_pairs}]", "||p_i - p_j|| of each pair at t (m)"),
        ("h_m2", f"float64[{n_pairs}]", "true barrier ||dp||^2 + 2 tau dv.dp - D^2 (m^2)"),
        ("i", f"{ids}[{n_pairs}]", "id of each pair's first agent"),
        ("j", f"{ids}[{n_pairs}]", "id of each pair's second agent (i < j by column)"),
    )


def ros2msg(fields: tuple[tuple[str, str, str], ...]) -> str:
    """The ``ros2msg`` schema text of ``fields`` (units in the comments)."""
    return "".join(f"{typ} {name}  # {doc}\n" for name, typ, doc in fields)
