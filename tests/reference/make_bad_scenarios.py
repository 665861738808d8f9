"""Write the bad-scenario corpus of the bad input campaign into ``bad_scenarios/``.

Every file is a shipped scenario (``scenarios/cube8.toml``; ``course8.toml`` for
``[mission]``, ``cube8_obstacles.toml`` for ``[[obstacle]]`` and ``[geofence]``) with one
thing wrong, named ``<kind>-<what>.toml``. Its first two lines say what is wrong and what
the one-line error must contain::

    # BAD type: a string for a number (vehicle.mass_kg = "1.8")
    # expect: vehicle.mass_kg

``tests/integration/mission/test_bad_input_campaign.py`` runs each file through the three
command lines and checks the refusal: exit 2, one stderr line holding the ``expect`` text.
The files are kept (not generated at test time) so that a change of a shipped scenario
cannot silently turn a bad case into a good one: a rerun of this script shows it as a diff.

Rerun after a change here: ``.venv/bin/python tests/reference/make_bad_scenarios.py``. It
is deterministic; it removes the directory's ``*.toml`` first, so a dropped case leaves no
file behind. Add a case: one :class:`Case` line in :func:`cases` (its edits are exact text
replacements, each asserted to apply).
"""

from __future__ import annotations

import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE / "bad_scenarios"
SCENARIOS = HERE.parents[1] / "scenarios"
CUBE8, COURSE8, OBSTACLES = "cube8.toml", "course8.toml", "cube8_obstacles.toml"
EXPECT_PREFIX = "# expect: "
DIGITS_400 = "1" + "2345678901" * 40  # a 401-digit integer
DIGITS_5000 = "9" * 5000  # beyond Python's int-from-string limit (4300 digits)
SPHERE_1 = "centre_m = [1.0, 0.2, 4.0]\nradius_m = 0.3"  # cube8_obstacles' obstacle[1]
HUGE = 20_000  # characters of the huge strings (300 times the longest name allowed)

Edit = tuple[str, str]  # (old text, new text): the first occurrence replaced


@dataclass(frozen=True)
class Case:
    """One bad file: ``kind`` and ``slug`` name it (``<kind>-<slug>.toml``), ``why`` is its
    first line, ``expect`` a text its one-line error must contain. The body is ``base``
    with ``edits`` applied in order, or ``build(base text)`` (text or bytes) if given."""

    kind: str
    slug: str
    why: str
    expect: str
    edits: tuple[Edit, ...] = ()
    base: str = CUBE8
    build: Callable[[str], str | bytes] | None = None


def _replace(text: str, old: str, new: str) -> str:
    if old not in text:
        raise AssertionError(f"edit does not apply: {old!r} not in the base")
    return text.replace(old, new, 1)


def drop_table(header: str) -> Callable[[str], str]:
    """The base without the table ``header`` (``[vehicle]``) and its keys."""

    def build(text: str) -> str:
        start = text.index(f"\n{header}\n")
        end = text.find("\n[", start + len(header) + 2)
        return text[:start] + (text[end:] if end >= 0 else "\n")

    return build


def drop_agents_after(keep: int) -> Callable[[str], str]:
    """The base with only its first ``keep`` ``[[agent]]`` tables."""

    def build(text: str) -> str:
        parts = text.split("\n[[agent]]\n")
        return "\n[[agent]]\n".join(parts[: keep + 1]) + "\n"

    return build


def many_waypoints(extra: int) -> Callable[[str], str]:
    """course8 with ``extra`` more ``[[mission.waypoint]]`` tables."""

    def build(text: str) -> str:
        rows = "".join(f"[[mission.waypoint]]\ncentroid = [{2 + k % 10}.0, 2.0, 4.0]\n"
                       for k in range(extra))
        return _replace(text, "\n[sensing]\n", f"\n{rows}\n[sensing]\n")

    return build


def many_obstacles(count: int) -> Callable[[str], str]:
    """cube8_obstacles with ``count`` more small spheres far from everything."""

    def build(text: str) -> str:
        rows = "".join(f'[[obstacle]]\nkind = "sphere"\ncentre_m = [{100 + k}.0, 100.0, 4.0]\n'
                       f"radius_m = 0.1\n\n" for k in range(count))
        return _replace(text, "\n[[agent]]\n", f"\n{rows}[[agent]]\n")

    return build


def without_geofence_limits(text: str) -> str:
    return _replace(text, "max_m = [8.0, 7.0, 9.5]\n", "")


def mission_waypoints_empty(text: str) -> str:
    """course8 with ``waypoint = []`` in place of its waypoint tables."""
    start = text.index("[[mission.waypoint]]")
    end = text.index("\n[sensing]\n")
    return text[:start] + "waypoint = []\n" + text[end:]


def mission_waypoints_dropped(text: str) -> str:
    start = text.index("[[mission.waypoint]]")
    end = text.index("\n[sensing]\n")
    return text[:start] + text[end:]


def at_top(line: str) -> Callable[[str], str]:
    """The base with ``line`` before its first table (a top-level key)."""

    def build(text: str) -> str:
        return _replace(text, "\n[scenario]\n", f"\n{line}\n\n[scenario]\n")

    return build


def raw_bytes(old: str, new: bytes) -> Callable[[str], bytes]:
    """The base's UTF-8 bytes with ``old`` replaced by the bytes ``new``."""

    def build(text: str) -> bytes:
        data = text.encode()
        if old.encode() not in data:
            raise AssertionError(f"edit does not apply: {old!r} not in the base")
        return data.replace(old.encode(), new, 1)

    return build


def encoded(codec: str) -> Callable[[str], bytes]:
    def build(text: str) -> bytes:
        return text.encode(codec)

    return build


def cr_only(text: str) -> str:
    """Old Mac line ends: a bare CR is not a TOML newline."""
    return text.replace("\n", "\r")


def deep_dotted_header(text: str) -> str:
    """A table header 2000 keys deep (dots, no brackets: the nesting guard does not count
    them; tomllib builds it without recursion)."""
    return text + "\n[" + ".".join(["a"] * 2000) + "]\nx = 1\n"


def cases() -> list[Case]:
    """Every bad file, by kind (module docstring)."""
    C = Case
    leader_gone = ('id = 2\nrole = "leader"', 'id = 2\nrole = "follower"')
    return [
        # --- TOML syntax ------------------------------------------------------------------
        C("syntax", "unclosed-array", "an array without its ]", "not valid TOML",
          (("leaders = [1, 2]", "leaders = [1, 2"),)),
        C("syntax", "unclosed-string", "a string without its closing quote", "not valid TOML",
          (('name = "cube8"', 'name = "cube8'),)),
        C("syntax", "missing-value", "a key with no value", "not valid TOML",
          (("seed = 1", "seed = "),)),
        C("syntax", "duplicate-key", "scenario.seed given twice", "not valid TOML",
          (("seed = 1", "seed = 1\nseed = 2"),)),
        C("syntax", "duplicate-table", "the [vehicle] table declared twice", "not valid TOML",
          (("[sensing]\n", "[vehicle]\n[sensing]\n"),)),
        C("syntax", "bare-word", "an unquoted string value", "not valid TOML",
          (('method = "dcbf"', "method = dcbf"),)),
        C("syntax", "trailing-unit", "a unit after a number (1.8 kg)", "not valid TOML",
          (("mass_kg = 1.8", "mass_kg = 1.8 kg"),)),
        C("syntax", "unclosed-header", "a table header without its ]", "not valid TOML",
          (("[vehicle]\n", "[vehicle\n"),)),
        C("syntax", "bad-escape", "an unknown escape in a string", "not valid TOML",
          (('name = "cube8"', 'name = "cube\\q8"'),)),
        C("syntax", "leading-zero", "an integer with a leading zero", "not valid TOML",
          (("seed = 1", "seed = 01"),)),
        C("syntax", "no-equals", "a key and value without =", "not valid TOML",
          (("mass_kg = 1.8", "mass_kg 1.8"),)),
        C("syntax", "nul-in-string", "a NUL character inside a string", "not valid TOML",
          (('name = "cube8"', 'name = "cu\x00be8"'),)),
        C("syntax", "utf8-bom", "a UTF-8 byte order mark before the first line",
          "not valid TOML", build=lambda t: "\ufeff" + t),
        C("syntax", "cr-line-ends", "bare CR line ends (old Mac)", "not valid TOML",
          build=cr_only),
        C("syntax", "table-array-clash", "[agent] as a table after [[agent]] tables",
          "not valid TOML", build=lambda t: t + "\n[agent]\nid = 9\n"),
        # --- wrong types ------------------------------------------------------------------
        C("type", "string-for-float", 'a string for a number (mass_kg = "1.8")',
          "vehicle.mass_kg", (("mass_kg = 1.8", 'mass_kg = "1.8"'),)),
        C("type", "string-for-int", 'a string for an integer (control_hz = "fifty")',
          "scenario.control_hz", (("control_hz = 50", 'control_hz = "fifty"'),)),
        C("type", "array-for-scalar", "an array for a number (kp = [0.5])", "controller.kp",
          (("kp = 0.5", "kp = [0.5]"),)),
        C("type", "table-for-array", "an inline table for a vector (beta)", "observer.beta",
          (("beta = [24.0, 108.0, 108.0]", "beta = {a = 24.0}"),)),
        C("type", "bool-for-float", "a bool for a number (gamma = true)", "controller.gamma",
          (("gamma = 0.6", "gamma = true"),)),
        C("type", "bool-for-int", "a bool for an integer (substeps = true)",
          "observer.substeps", (("substeps = 4", "substeps = true"),)),
        C("type", "float-for-int", "a float for an integer (physics_hz = 200.0)",
          "scenario.physics_hz", (("physics_hz = 200 ", "physics_hz = 200.0 "),)),
        C("type", "int-for-string", "a number for a choice (method = 3)", "controller.method",
          (('method = "dcbf"', "method = 3"),)),
        C("type", "int-for-name", "a number for the name (name = 8)", "scenario.name",
          (('name = "cube8"', "name = 8"),)),
        C("type", "date-for-float", "a date for a number (duration_s)", "scenario.duration_s",
          (("duration_s = 60.0", "duration_s = 1979-05-27"),)),
        C("type", "scalar-for-table", "disturbance = 1 for the [disturbance] table",
          "[disturbance] must be a table", build=lambda t: at_top("disturbance = 1")(
              drop_table("[disturbance]")(t))),
        C("type", "string-in-vector", "a string inside a vector (amplitude_m)",
          "leader_trajectory.amplitude_m",
          (("amplitude_m = [0.8, 0.4, 0.2]", 'amplitude_m = [0.8, "0.4", 0.2]'),)),
        C("type", "string-for-id", 'an agent id as a string (id = "1")', "agent[0].id",
          (("id = 1\n", 'id = "1"\n'),)),
        C("type", "int-for-role", "an agent role as a number", "agent[0].role",
          (('role = "leader"', "role = 1"),)),
        C("type", "string-for-bool", 'cooperative = "no" (a string for a bool)',
          "agent[2].cooperative",
          (("vertex = [0, 0, 1]", 'vertex = [0, 0, 1]\ncooperative = "no"'),)),
        C("type", "flat-windows", "outages_s as one flat pair, not a list of pairs",
          "communication.outages_s",
          (("outages_s = [[5.0, 5.5], [15.0, 15.5], [40.0, 40.5]]", "outages_s = [5.0, 5.5]"),)),
        C("type", "string-for-ids", 'leaders = "1,2" (a string for a list of ids)',
          "formation.leaders", (("leaders = [1, 2]", 'leaders = "1,2"'),)),
        C("type", "mission-string-speed", 'mission.speed_mps = "fast"', "mission.speed_mps",
          (("speed_mps = 1.5", 'speed_mps = "fast"'),), base=COURSE8),
        C("type", "obstacle-string-radius", 'an obstacle radius_m = "big"',
          "obstacle[0].radius_m", (("radius_m = 0.2", 'radius_m = "big"'),), base=OBSTACLES),
        C("type", "agent-not-table", "an agent that is a number, not a table (agent = [1, 2])",
          "agent[0] must be a table",
          build=lambda t: at_top("agent = [1, 2]")(t.split("\n[[agent]]\n")[0])),
        # --- NaN, inf, numbers too large for a float ----------------------------------------
        C("nonfinite", "nan", "mass_kg = nan", "vehicle.mass_kg",
          (("mass_kg = 1.8", "mass_kg = nan"),)),
        C("nonfinite", "minus-nan", "tau_safe_s = -nan", "controller.tau_safe_s",
          (("tau_safe_s = 0.8", "tau_safe_s = -nan"),)),
        C("nonfinite", "inf", "kp = inf", "controller.kp", (("kp = 0.5", "kp = inf"),)),
        C("nonfinite", "plus-inf", "d_safe_m = +inf", "controller.d_safe_m",
          (("d_safe_m = 0.5", "d_safe_m = +inf"),)),
        C("nonfinite", "minus-inf", "gamma = -inf", "controller.gamma",
          (("gamma = 0.6", "gamma = -inf"),)),
        C("nonfinite", "1e400", "amplitude_n = 1e400 (inf as a float)",
          "disturbance.amplitude_n", (("amplitude_n = 0.2", "amplitude_n = 1e400"),)),
        C("nonfinite", "400-digit-float-key", "duration_s = a 401-digit integer",
          "scenario.duration_s", (("duration_s = 60.0", f"duration_s = {DIGITS_400}"),)),
        C("nonfinite", "400-digit-int-key", "seed = a 401-digit integer", "scenario.seed",
          (("seed = 1", f"seed = {DIGITS_400}"),)),
        C("nonfinite", "minus-400-digits", "omega_rad_s = minus a 401-digit integer",
          "disturbance.omega_rad_s", (("omega_rad_s = 1.0", f"omega_rad_s = -{DIGITS_400}"),)),
        C("nonfinite", "5000-digits", "seed = a 5000-digit integer (beyond int's limit)",
          "not a valid scenario", (("seed = 1", f"seed = {DIGITS_5000}"),)),
        C("nonfinite", "nan-position", "an agent position with nan", "agent[0].position",
          (("position = [4.0, 0.0, 6.0]", "position = [nan, 0.0, 6.0]"),)),
        C("nonfinite", "inf-velocity", "an agent velocity with inf", "agent[2].velocity",
          (("velocity = [0.0, 0.0, 0.6]", "velocity = [0.0, 0.0, inf]"),)),
        C("nonfinite", "minus-inf-vertex", "an agent vertex with -inf", "agent[3].vertex",
          (("vertex = [0, 0, 0]", "vertex = [0, 0, -inf]"),)),
        C("nonfinite", "nan-in-zeta", "nan inside unmodeled.zeta_nominal",
          "unmodeled.zeta_nominal", (("[0.05, 0.10,", "[0.05, nan,"),)),
        C("nonfinite", "nan-window", "an outage window starting at nan",
          "communication.outages_s", (("[[5.0, 5.5]", "[[nan, 5.5]"),)),
        C("nonfinite", "1e400-in-vector", "1e400 inside observer.beta", "observer.beta",
          (("beta = [24.0,", "beta = [1e400,"),)),
        C("nonfinite", "400-digits-in-vector", "a 401-digit integer inside an agent position",
          "agent[1].position", (("position = [4.0, 4.0, 6.0]",
                                 f"position = [4.0, {DIGITS_400}, 6.0]"),)),
        C("nonfinite", "nan-centroid", "a mission waypoint centroid with nan",
          "mission.waypoint[1].centroid",
          (("centroid = [14.0, 2.0, 4.0]", "centroid = [nan, 2.0, 4.0]"),), base=COURSE8),
        C("nonfinite", "inf-obstacle-radius", "an obstacle radius_m = inf", "obstacle[1].radius_m",
          ((SPHERE_1, SPHERE_1.replace("0.3", "inf")),), base=OBSTACLES),
        # --- negative or zero where positive is needed ---------------------------------------
        C("nonpositive", "negative-mass", "mass_kg = -1.8", "vehicle.mass_kg",
          (("mass_kg = 1.8", "mass_kg = -1.8"),)),
        C("nonpositive", "zero-thrust", "thrust_max_n = 0.0", "vehicle.thrust_max_n",
          (("thrust_max_n = 52.92", "thrust_max_n = 0.0"),)),
        C("nonpositive", "zero-lag", "tau_rollpitch_s = 0.0", "vehicle.tau_rollpitch_s",
          (("tau_rollpitch_s = 0.15", "tau_rollpitch_s = 0.0"),)),
        C("nonpositive", "zero-duration", "duration_s = 0.0", "scenario.duration_s",
          (("duration_s = 60.0", "duration_s = 0.0"),)),
        C("nonpositive", "negative-duration", "duration_s = -60.0", "scenario.duration_s",
          (("duration_s = 60.0", "duration_s = -60.0"),)),
        C("nonpositive", "zero-range", "sensing_range_m = 0.0", "formation.sensing_range_m",
          (("sensing_range_m = 10.0", "sensing_range_m = 0.0"),)),
        C("nonpositive", "negative-d-safe", "d_safe_m = -0.5", "controller.d_safe_m",
          (("d_safe_m = 0.5", "d_safe_m = -0.5"),)),
        C("nonpositive", "zero-max-age", "max_age_s = 0.0", "communication.max_age_s",
          (("max_age_s = 1.0", "max_age_s = 0.0"),)),
        C("nonpositive", "negative-seed", "seed = -1", "scenario.seed",
          (("seed = 1", "seed = -1"),)),
        C("nonpositive", "zero-substeps", "substeps = 0", "observer.substeps",
          (("substeps = 4", "substeps = 0"),)),
        C("nonpositive", "zero-collision-radius", "collision_radius_m = 0.0",
          "vehicle.collision_radius_m",
          (("collision_radius_m = 0.3", "collision_radius_m = 0.0"),)),
        C("nonpositive", "negative-u-max", "u_max_mps2 = -8.0", "controller.u_max_mps2",
          (("u_max_mps2 = 8.0", "u_max_mps2 = -8.0"),)),
        C("nonpositive", "negative-spread", "zeta_spread = -0.2", "unmodeled.zeta_spread",
          (("zeta_spread = 0.2", "zeta_spread = -0.2"),)),
        C("nonpositive", "negative-noise", "bearing_noise_rad = -0.001",
          "sensing.bearing_noise_rad",
          (("bearing_noise_rad = 0.001", "bearing_noise_rad = -0.001"),)),
        C("nonpositive", "zero-control-hz", "control_hz = 0", "scenario.control_hz",
          (("control_hz = 50", "control_hz = 0"),)),
        C("nonpositive", "negative-physics-hz", "physics_hz = -200", "scenario.physics_hz",
          (("physics_hz = 200 ", "physics_hz = -200 "),)),
        # --- out of range -------------------------------------------------------------------
        C("range", "tilt-95", "tilt_max_deg = 95.0", "vehicle.tilt_max_deg",
          (("tilt_max_deg = 30.0", "tilt_max_deg = 95.0"),)),
        C("range", "probability-1.5", "dropout_prob = 1.5 (a probability above 1)",
          "sensing.dropout_prob", (("dropout_prob = 0.0", "dropout_prob = 1.5"),)),
        C("range", "probability-1", "dropout_prob = 1.0 (every sample dropped)",
          "sensing.dropout_prob", (("dropout_prob = 0.0", "dropout_prob = 1.0"),)),
        C("range", "spread-2", "zeta_spread = 2.0 (a fraction above 1)", "unmodeled.zeta_spread",
          (("zeta_spread = 0.2", "zeta_spread = 2.0"),)),
        C("range", "control-hz-1", "control_hz = 1 (half a period outlasts the loop's lag)",
          "scenario.control_hz", (("control_hz = 50", "control_hz = 1"),)),
        C("range", "control-hz-1e9", "control_hz = 1000000000", "scenario.control_hz",
          (("control_hz = 50", "control_hz = 1000000000"),)),
        C("range", "physics-below-control", "physics_hz = 50 below control_hz = 100",
          "must be a multiple of scenario.control_hz",
          (("physics_hz = 200 ", "physics_hz = 50 "), ("control_hz = 50", "control_hz = 100"))),
        C("range", "physics-not-multiple", "physics_hz = 175, not a multiple of control_hz",
          "scenario.physics_hz = 175", (("physics_hz = 200 ", "physics_hz = 175 "),)),
        C("range", "physics-hz-20", "physics_hz = 20 (below the lowest rate)",
          "scenario.physics_hz", (("physics_hz = 200 ", "physics_hz = 20 "),)),
        C("range", "seed-2-32", "seed = 2**32", "scenario.seed",
          (("seed = 1", "seed = 4294967296"),)),
        C("range", "seed-2-64", "seed = 2**64", "scenario.seed",
          (("seed = 1", "seed = 18446744073709551616"),)),
        C("range", "frequency-11", "frequency_hz = 11.0", "leader_trajectory.frequency_hz",
          (("frequency_hz = 0.2", "frequency_hz = 11.0"),)),
        C("range", "amplitude-200", "an amplitude_m of 200 m", "leader_trajectory.amplitude_m",
          (("amplitude_m = [0.8, 0.4, 0.2]", "amplitude_m = [0.8, 0.4, 200.0]"),)),
        C("range", "position-1e5", "an agent 100 km up", "agent[0].position",
          (("position = [4.0, 0.0, 6.0]", "position = [4.0, 0.0, 1e5]"),)),
        C("range", "delay-above-max-age", "delay_s = 2.0 above max_age_s = 1.0",
          "communication.delay_s", (("max_age_s = 1.0", "max_age_s = 1.0\ndelay_s = 2.0"),)),
        C("range", "thrust-below-weight", "thrust_max_n = 10.0, below the weight",
          "vehicle.thrust_max_n", (("thrust_max_n = 52.92", "thrust_max_n = 10.0"),)),
        C("range", "cone-sides-2", "dcbf_cone_sides = 2", "controller.dcbf_cone_sides",
          (("dcbf_cone_sides = 8", "dcbf_cone_sides = 2"),)),
        C("range", "gravity-31", "gravity_mps2 = 31.0", "vehicle.gravity_mps2",
          (("gravity_mps2 = 9.81", "gravity_mps2 = 31.0"),)),
        C("range", "window-backwards", "an outage window that ends before it starts",
          "communication.outages_s", (("[[5.0, 5.5]", "[[5.5, 5.0]"),)),
        C("range", "window-negative", "an outage window starting at -1 s",
          "communication.outages_s", (("[[5.0, 5.5]", "[[-1.0, 5.5]"),)),
        C("range", "knn-k-300", "formation.knn_k = 300", "formation.knn_k",
          (("sensing_range_m = 10.0", "sensing_range_m = 10.0\nknn_k = 300"),)),
        C("range", "lifecycle-climb-0", "lifecycle.climb_rate_mps = 0",
          "lifecycle.climb_rate_mps", build=lambda t: t + "\n[lifecycle]\nclimb_rate_mps = 0\n"),
        C("range", "fault-drop-2", "faults.mavlink.drop = 2.0 (a probability above 1)",
          "faults.mavlink.drop", build=lambda t: t + "\n[faults.mavlink]\ndrop = 2.0\n"),
        # --- wrong vector lengths -------------------------------------------------------------
        C("veclen", "position-2", "an agent position of 2 numbers", "agent[0].position",
          (("position = [4.0, 0.0, 6.0]", "position = [4.0, 0.0]"),)),
        C("veclen", "velocity-4", "an agent velocity of 4 numbers", "agent[2].velocity",
          (("velocity = [0.0, 0.0, 0.6]", "velocity = [0.0, 0.0, 0.6, 0.0]"),)),
        C("veclen", "zeta-5", "zeta_nominal of 5 numbers", "unmodeled.zeta_nominal",
          (("[0.05, 0.10, 0.03, 0.01, 0.50, 0.05]", "[0.05, 0.10, 0.03, 0.01, 0.50]"),)),
        C("veclen", "beta-2", "observer.beta of 2 numbers", "observer.beta",
          (("beta = [24.0, 108.0, 108.0]", "beta = [24.0, 108.0]"),)),
        C("veclen", "velocity-gain-3", "observer.velocity_gain of 3 numbers",
          "observer.velocity_gain",
          (("velocity_gain = [1.0, 4.0]", "velocity_gain = [1.0, 4.0, 1.0]"),)),
        C("veclen", "amplitude-1", "amplitude_m of 1 number", "leader_trajectory.amplitude_m",
          (("amplitude_m = [0.8, 0.4, 0.2]", "amplitude_m = [0.8]"),)),
        C("veclen", "window-3", "an outage window of 3 numbers", "communication.outages_s",
          (("[[5.0, 5.5]", "[[5.0, 5.5, 6.0]"),)),
        C("veclen", "nested-position", "an agent position with a list inside",
          "agent[0].position", (("position = [4.0, 0.0, 6.0]", "position = [[4.0], 0.0, 6.0]"),)),
        C("veclen", "centroid-2", "a mission waypoint centroid of 2 numbers",
          "mission.waypoint[0].centroid",
          (("centroid = [2.0, 2.0, 4.0]", "centroid = [2.0, 2.0]"),), base=COURSE8),
        C("veclen", "sphere-centre-2", "a sphere obstacle centre_m of 2 numbers",
          "obstacle[1].centre_m", (("centre_m = [1.0, 0.2, 4.0]", "centre_m = [1.0, 0.2]"),),
          base=OBSTACLES),
        C("veclen", "geofence-min-2", "geofence.min_m of 2 numbers", "geofence.min_m",
          (("min_m = [-2.0, -2.0, 0.0]", "min_m = [-2.0, -2.0]"),), base=OBSTACLES),
        C("veclen", "edge-triple", 'a formation.edges entry of 3 ids (graph = "edges")',
          "formation.edges", (('graph = "cube_face_diagonals"',
                               'graph = "edges"\nedges = [[1, 2, 3]]'),)),
        # --- missing tables and keys ------------------------------------------------------------
        C("missing", "empty-file", "no tables at all", "missing section [scenario]",
          build=lambda t: ""),
        C("missing", "no-vehicle", "no [vehicle] table", "missing section [vehicle]",
          build=drop_table("[vehicle]")),
        C("missing", "no-controller", "no [controller] table", "missing section [controller]",
          build=drop_table("[controller]")),
        C("missing", "no-leader-trajectory", "no [leader_trajectory] and no [mission]",
          "missing section [leader_trajectory]", build=drop_table("[leader_trajectory]")),
        C("missing", "no-mass", "vehicle.mass_kg left out", "missing key vehicle.mass_kg",
          (("mass_kg = 1.8\n", ""),)),
        C("missing", "no-name", "scenario.name left out", "missing key scenario.name",
          (('name = "cube8"\n', ""),)),
        C("missing", "no-graph", "formation.graph left out", "missing key formation.graph",
          (('graph = "cube_face_diagonals"', ""),)),
        C("missing", "no-position", "an agent without position", "missing key agent[0].position",
          (("position = [4.0, 0.0, 6.0]\n", ""),)),
        C("missing", "no-agents", "no [[agent]] tables", "at least 2 agents",
          build=drop_agents_after(0)),
        C("missing", "one-agent", "a single [[agent]]", "at least 2 agents",
          build=drop_agents_after(1)),
        C("missing", "mission-no-speed", "mission.speed_mps left out",
          "missing key mission.speed_mps", (("speed_mps = 1.5 ", "# "),), base=COURSE8),
        C("missing", "mission-no-waypoints", "a [mission] without waypoints",
          "missing key mission.waypoint", base=COURSE8, build=mission_waypoints_dropped),
        C("missing", "waypoint-no-centroid", "a waypoint without its centroid",
          "missing key mission.waypoint[0].centroid",
          (("centroid = [2.0, 2.0, 4.0]\n", ""),), base=COURSE8),
        C("missing", "obstacle-no-radius", "a sphere obstacle without radius_m",
          "missing key obstacle[1].radius_m", ((SPHERE_1, SPHERE_1.split("\n")[0]),),
          base=OBSTACLES),
        C("missing", "obstacle-no-kind", "an obstacle without kind", "missing key obstacle[0].kind",
          (('kind = "cylinder"        # a pole up the middle of the cube\n', ""),),
          base=OBSTACLES),
        C("missing", "geofence-no-max", "a geofence box without max_m",
          "missing key geofence.max_m", base=OBSTACLES, build=without_geofence_limits),
        # --- unknown keys and tables ------------------------------------------------------
        C("unknown", "key", "vehicle.mass_lb beside mass_kg", "unknown key vehicle.mass_lb",
          (("mass_kg = 1.8", "mass_kg = 1.8\nmass_lb = 4.0"),)),
        C("unknown", "section", "an unknown table [sensingg]", "unknown section [sensingg]",
          (("[sensing]\n", "[sensingg]\nx = 1\n[sensing]\n"),)),
        C("unknown", "misspelt-section", "[controler] for [controller]",
          "unknown section [controler]", (("[controller]\n", "[controler]\n"),)),
        C("unknown", "top-level-key", "a top-level key version = 2", "unknown section [version]",
          build=at_top("version = 2")),
        C("unknown", "subtable", "a subtable [vehicle.extra]", "unknown key vehicle.extra",
          build=lambda t: t + "\n[vehicle.extra]\nx = 1\n"),
        C("unknown", "case", "Mass_kg (the key's case changed)", "unknown key vehicle.Mass_kg",
          (("mass_kg = 1.8", "Mass_kg = 1.8"),)),
        C("unknown", "agent-key", "an agent key colour", "unknown key agent[0].colour",
          (('role = "leader"', 'role = "leader"\ncolour = "red"'),)),
        C("unknown", "mission-key", "mission.speed_kmh", "unknown key mission.speed_kmh",
          (("speed_mps = 1.5 ", "speed_kmh = 5.4 "),), base=COURSE8),
        C("unknown", "waypoint-key", "a waypoint key altitude", "unknown key mission.waypoint[0]",
          (("hold_s = 10.0", "hold_s = 10.0\naltitude = 4.0"),), base=COURSE8),
        C("unknown", "obstacle-key", "size_m on a sphere obstacle",
          "unknown key obstacle[1].size_m", ((SPHERE_1, SPHERE_1 + "\nsize_m = [1.0, 1.0, 1.0]"),),
          base=OBSTACLES),
        C("unknown", "geofence-key", "geofence.height_m", "unknown key geofence.height_m",
          (("max_m = [8.0, 7.0, 9.5]", "max_m = [8.0, 7.0, 9.5]\nheight_m = 3.0"),),
          base=OBSTACLES),
        C("unknown", "faults-link", "a [faults.radio] link", "unknown key faults.radio",
          build=lambda t: t + "\n[faults.radio]\ndrop = 0.1\n"),
        C("unknown", "key-newline", 'a quoted key with a newline ("a\\nb")',
          "unknown key vehicle.'a\\nb'", (("mass_kg = 1.8", 'mass_kg = 1.8\n"a\\nb" = 1'),)),
        C("unknown", "section-newline", 'a quoted table name with a newline (["x\\ny"])',
          "unknown section ['x\\ny']", build=lambda t: t + '\n["x\\ny"]\nz = 1\n'),
        C("unknown", "agent-key-u2028", "an agent key with a line separator (U+2028)",
          "unknown key agent[0].'a\\u2028b'",
          (('role = "leader"', 'role = "leader"\n"a\u2028b" = 1'),)),
        C("unknown", "faults-key-newline", 'a [faults] key with a newline ("a\\nb")',
          "unknown key faults.a\\nb", build=lambda t: t + '\n[faults]\n"a\\nb" = 1\n'),
        C("unknown", "mission-key-newline", 'a [mission] key with a newline ("a\\nb")',
          "unknown key mission.'a\\nb'", (("speed_mps = 1.5 ", '"a\\nb" = 1\nspeed_mps = 1.5 '),),
          base=COURSE8),
        C("unknown", "lifecycle-key", "lifecycle.start_mode", "unknown key lifecycle.start_mode",
          build=lambda t: t + '\n[lifecycle]\nstart_mode = "ground"\n'),
        # --- agent ids and leaders ----------------------------------------------------------
        C("agents", "duplicate-id", "two agents with id 3", "duplicate agent id",
          (("id = 4\n", "id = 3\n"),)),
        C("agents", "duplicate-leaders", "leaders = [1, 1]", "duplicate agent id",
          (("leaders = [1, 2]", "leaders = [1, 1]"),)),
        C("agents", "leader-not-agent", "leaders = [1, 9] (no agent 9)",
          "id 9 is not an [[agent]] id", (("leaders = [1, 2]", "leaders = [1, 9]"),)),
        C("agents", "leader-256", "leaders = [1, 256]", "formation.leaders",
          (("leaders = [1, 2]", "leaders = [1, 256]"),)),
        C("agents", "leader-0", "leaders = [0, 1]", "formation.leaders",
          (("leaders = [1, 2]", "leaders = [0, 1]"),)),
        C("agents", "id-0", "an agent id 0", "agent[0].id", (("id = 1\n", "id = 0\n"),)),
        C("agents", "id-65536", "an agent id past 65535", "agent[7].id",
          (("id = 8\n", "id = 65536\n"),)),
        C("agents", "role-disagrees", "agent 3 is a leader but not in formation.leaders",
          "disagrees with formation.leaders", (('id = 3\nrole = "follower"',
                                                'id = 3\nrole = "leader"'),)),
        C("agents", "all-leaders", "every agent listed as a leader", "every agent is a leader",
          (("leaders = [1, 2]", "leaders = [1, 2, 3, 4, 5, 6, 7, 8]"),)),
        C("agents", "one-leader", "one leader (no bearing scale)", "need at least 2 leaders",
          (("leaders = [1, 2]", "leaders = [1]"), leader_gone)),
        C("agents", "unknown-role", 'role = "boss"', "agent[0].role",
          (('role = "leader"', 'role = "boss"'),)),
        C("agents", "leader-not-cooperative", "cooperative = false on a leader",
          "only a follower can be non-cooperative",
          (('role = "leader"', 'role = "leader"\ncooperative = false'),)),
        C("agents", "shared-vertex", "agents 3 and 4 on the same vertex", "share vertex",
          (("vertex = [0, 0, 0]", "vertex = [0, 0, 1]"),)),
        C("agents", "faults-unknown-agent", "[faults.agent.9] in an 8-agent scenario",
          "faults.agent.9", build=lambda t: t + "\n[faults.agent.9.mavlink]\ndrop = 0.1\n"),
        # --- empty arrays and strings ---------------------------------------------------
        C("empty", "leaders", "leaders = []", "formation.leaders",
          (("leaders = [1, 2]", "leaders = []"),)),
        C("empty", "position", "an agent position = []", "agent[0].position",
          (("position = [4.0, 0.0, 6.0]", "position = []"),)),
        C("empty", "zeta", "zeta_nominal = []", "unmodeled.zeta_nominal",
          (("[0.05, 0.10, 0.03, 0.01, 0.50, 0.05]", "[]"),)),
        C("empty", "beta", "observer.beta = []", "observer.beta",
          (("beta = [24.0, 108.0, 108.0]", "beta = []"),)),
        C("empty", "amplitude", "amplitude_m = []", "leader_trajectory.amplitude_m",
          (("amplitude_m = [0.8, 0.4, 0.2]", "amplitude_m = []"),)),
        C("empty", "edges", 'graph = "edges" with edges = []', "needs at least one pair",
          (('graph = "cube_face_diagonals"', 'graph = "edges"\nedges = []'),)),
        C("empty", "name", 'name = ""', "scenario.name", (('name = "cube8"', 'name = ""'),)),
        C("empty", "method", 'method = ""', "controller.method",
          (('method = "dcbf"', 'method = ""'),)),
        C("empty", "vehicle-table", "an empty [vehicle] table", "missing key vehicle.mass_kg",
          build=lambda t: drop_table("[vehicle]")(t) + "\n[vehicle]\n"),
        # --- graph names and graphs -------------------------------------------------------
        C("graph", "unknown", 'graph = "cube"', "formation.graph",
          (('graph = "cube_face_diagonals"', 'graph = "cube"'),)),
        C("graph", "empty", 'graph = ""', "formation.graph",
          (('graph = "cube_face_diagonals"', 'graph = ""'),)),
        C("graph", "upper-case", 'graph = "CUBE_FACE_DIAGONALS"', "formation.graph",
          (('graph = "cube_face_diagonals"', 'graph = "CUBE_FACE_DIAGONALS"'),)),
        C("graph", "path", 'graph = "../../etc/passwd"', "formation.graph",
          (('graph = "cube_face_diagonals"', 'graph = "../../etc/passwd"'),)),
        C("graph", "knn-k-n", 'graph = "knn" with knn_k = 8 for 8 agents', "formation.knn_k = 8",
          (('graph = "cube_face_diagonals"', 'graph = "knn"\nknn_k = 8'),)),
        C("graph", "edges-with-cube", "formation.edges with the cube graph",
          "formation.edges: only read with", (('graph = "cube_face_diagonals"',
                                              'graph = "cube_face_diagonals"\nedges = [[1, 3]]'),)),
        C("graph", "edge-unknown-id", "formation.edges naming agent 9", "formation.edges",
          (('graph = "cube_face_diagonals"', 'graph = "edges"\nedges = [[1, 9]]'),)),
        C("graph", "edge-self-loop", "formation.edges with a self-loop", "formation.edges",
          (('graph = "cube_face_diagonals"', 'graph = "edges"\nedges = [[3, 3]]'),)),
        C("graph", "range-too-short", "sensing_range_m = 1.0 (edges never sensed)",
          "formation.sensing_range_m", (("sensing_range_m = 10.0", "sensing_range_m = 1.0"),)),
        C("graph", "not-rigid", "one edge only: not bearing rigid",
          "the leaders do not fix followers",
          (('graph = "cube_face_diagonals"', 'graph = "edges"\nedges = [[1, 3]]'),)),
        # --- swarm names --------------------------------------------------------------------
        C("name", "wildcard", 'name = "**" (a Zenoh wildcard)', "scenario.name",
          (('name = "cube8"', 'name = "**"'),)),
        C("name", "slash", 'name = "a/b"', "scenario.name", (('name = "cube8"', 'name = "a/b"'),)),
        C("name", "dot-dot", 'name = ".."', "scenario.name", (('name = "cube8"', 'name = ".."'),)),
        C("name", "too-long", "a 65-character name", "scenario.name",
          (('name = "cube8"', f'name = "{"n" * 65}"'),)),
        C("name", "space", 'name = "cube 8"', "scenario.name",
          (('name = "cube8"', 'name = "cube 8"'),)),
        C("name", "non-ascii", 'name = "cübe8"', "scenario.name",
          (('name = "cube8"', 'name = "c\u00fcbe8"'),)),
        C("name", "newline", 'name = "cube\\n8" (a newline in the name)', "scenario.name",
          (('name = "cube8"', 'name = "cube\\n8"'),)),
        # --- [mission] (course8) ------------------------------------------------------------
        C("mission", "no-waypoints", "waypoint = []", "mission.waypoint = []", base=COURSE8,
          build=mission_waypoints_empty),
        C("mission", "nan-centroid", "a waypoint centroid of nan", "mission.waypoint[0].centroid",
          (("centroid = [2.0, 2.0, 4.0]", "centroid = [nan, nan, nan]"),), base=COURSE8),
        C("mission", "below-floor", "a waypoint that puts the formation underground",
          "below the floor", (("centroid = [14.0, 2.0, 4.0]", "centroid = [14.0, 2.0, 0.5]"),),
          base=COURSE8),
        C("mission", "scale-below-d-safe", "scale = 0.05: agents closer than d_safe_m",
          "closer than the minimum separation",
          (("centroid = [14.0, 2.0, 4.0]", "centroid = [14.0, 2.0, 4.0]\nscale = 0.05"),),
          base=COURSE8),
        C("mission", "speed-above-max", "speed_mps = 4.0 above max_speed_mps = 3.0",
          "must not exceed mission.max_speed_mps", (("speed_mps = 1.5 ", "speed_mps = 4.0 "),),
          base=COURSE8),
        C("mission", "waypoint-speed-20", "a waypoint speed_mps = 20",
          "mission.waypoint[1].speed_mps",
          (("centroid = [14.0, 2.0, 4.0]", "centroid = [14.0, 2.0, 4.0]\nspeed_mps = 20.0"),),
          base=COURSE8),
        C("mission", "waypoint-speed-above-max", "a waypoint speed_mps above max_speed_mps",
          "must not exceed mission.max_speed_mps",
          (("centroid = [14.0, 2.0, 4.0]", "centroid = [14.0, 2.0, 4.0]\nspeed_mps = 3.5"),),
          base=COURSE8),
        C("mission", "max-speed-16", "max_speed_mps = 16", "mission.max_speed_mps",
          (("max_speed_mps = 3.0", "max_speed_mps = 16.0"),), base=COURSE8),
        C("mission", "accel-above-input-set", "max_accel_mps2 = 10: more than the vehicle has",
          "mission.max_accel_mps2", (("max_accel_mps2 = 1.0", "max_accel_mps2 = 10.0"),),
          base=COURSE8),
        C("mission", "1006-waypoints", "1006 waypoints (at most 1000)", "at most 1000",
          base=COURSE8, build=many_waypoints(1000)),
        C("mission", "and-sinusoid", "[mission] and a moving [leader_trajectory]",
          "both move the leaders", base=COURSE8,
          build=lambda t: t + "\n[leader_trajectory]\nfrequency_hz = 0.2\n"
          "amplitude_m = [0.8, 0.4, 0.2]\n"),
        C("mission", "yaw-1000", "a waypoint yaw_deg = 1000", "mission.waypoint[2].yaw_deg",
          (("yaw_deg = 90.0\nhold_s = 2.0", "yaw_deg = 1000.0\nhold_s = 2.0"),), base=COURSE8),
        C("mission", "hold-negative", "a waypoint hold_s = -1", "mission.waypoint[0].hold_s",
          (("hold_s = 10.0", "hold_s = -1.0"),), base=COURSE8),
        C("mission", "scale-zero", "a waypoint scale = 0", "mission.waypoint[1].scale",
          (("centroid = [14.0, 2.0, 4.0]", "centroid = [14.0, 2.0, 4.0]\nscale = 0.0"),),
          base=COURSE8),
        C("mission", "scalar", "mission = 3 (not a table)", "[mission] = 3: must be a table",
          build=lambda t: at_top("mission = 3")(t)),
        C("mission", "waypoint-numbers", "waypoint = [1, 2] (numbers, not tables)",
          "mission.waypoint[0]", base=COURSE8,
          build=lambda t: mission_waypoints_empty(t).replace("waypoint = []",
                                                             "waypoint = [1, 2]")),
        # --- [[obstacle]] (cube8_obstacles) -------------------------------------------------
        C("obstacle", "negative-radius", "a sphere radius_m = -0.3", "obstacle[1].radius_m",
          ((SPHERE_1, SPHERE_1.replace("0.3", "-0.3")),), base=OBSTACLES),
        C("obstacle", "zero-radius", "a cylinder radius_m = 0", "obstacle[0].radius_m",
          (("radius_m = 0.2", "radius_m = 0.0"),), base=OBSTACLES),
        C("obstacle", "nan-centre", "a sphere centre_m with nan", "obstacle[1].centre_m",
          (("centre_m = [1.0, 0.2, 4.0]", "centre_m = [nan, 0.2, 4.0]"),), base=OBSTACLES),
        C("obstacle", "zero-size", "a box of size 0 along x", "obstacle[4].size_m",
          (("size_m = [0.4, 1.0, 0.4]", "size_m = [0.0, 1.0, 0.4]"),), base=OBSTACLES),
        C("obstacle", "unknown-kind", 'kind = "cone"', "obstacle[0].kind",
          (('kind = "cylinder"', 'kind = "cone"'),), base=OBSTACLES),
        C("obstacle", "z-range-inverted", "a cylinder whose top is below its bottom",
          "bottom must be below top", (("z_range_m = [0.0, 9.0]", "z_range_m = [9.0, 0.0]"),),
          base=OBSTACLES),
        C("obstacle", "negative-clearance", "clearance_m = -1", "obstacle[1].clearance_m",
          ((SPHERE_1, SPHERE_1 + "\nclearance_m = -1.0"),), base=OBSTACLES),
        C("obstacle", "nan-yaw", "a box yaw_deg = nan", "obstacle[4].yaw_deg",
          (("yaw_deg = 30.0", "yaw_deg = nan"),), base=OBSTACLES),
        C("obstacle", "on-an-agent", "a sphere where agent 1 starts", "inside its clearance_m",
          (("centre_m = [4.8, 2.0, 4.0]", "centre_m = [4.0, 0.0, 6.0]"),), base=OBSTACLES),
        C("obstacle", "1001-more", "1011 obstacles (at most 1000)", "at most 1000",
          base=OBSTACLES, build=many_obstacles(1001)),
        C("obstacle", "scalar", "obstacle = 5 (not a list of tables)", "obstacle = 5",
          build=at_top("obstacle = 5")),
        # --- [geofence] (cube8_obstacles) ---------------------------------------------------
        C("geofence", "min-above-max", "geofence min_m above max_m", "geofence: max_m.x",
          (("min_m = [-2.0, -2.0, 0.0]", "min_m = [9.0, -2.0, 0.0]"),), base=OBSTACLES),
        C("geofence", "nan", "geofence.max_m with nan", "geofence.max_m",
          (("max_m = [8.0, 7.0, 9.5]", "max_m = [8.0, nan, 9.5]"),), base=OBSTACLES),
        C("geofence", "agents-outside", "a fence that leaves agents 7 and 8 outside", "geofence:",
          (("max_m = [8.0, 7.0, 9.5]", "max_m = [5.0, 7.0, 9.5]"),), base=OBSTACLES),
        C("geofence", "not-convex", "a polygon fence that is not convex", "not convex",
          (("min_m = [-2.0, -2.0, 0.0]\nmax_m = [8.0, 7.0, 9.5]",
            "polygon_m = [[-2.0, -2.0], [8.0, -2.0], [3.0, 2.0], [8.0, 7.0], [-2.0, 7.0]]\n"
            "z_range_m = [0.0, 9.5]"),), base=OBSTACLES),
        C("geofence", "box-and-polygon", "min_m beside polygon_m", "geofence.min_m",
          (("max_m = [8.0, 7.0, 9.5]", "max_m = [8.0, 7.0, 9.5]\n"
            "polygon_m = [[-2.0, -2.0], [8.0, -2.0], [8.0, 7.0]]"),), base=OBSTACLES),
        C("geofence", "array-of-tables", "[[geofence]] (an array, not a table)",
          "[geofence] = [", (("[geofence]\n", "[[geofence]]\n"),), base=OBSTACLES),
        # --- bytes and encodings ----------------------------------------------------------
        C("encoding", "ff-fe", "0xff 0xfe bytes in the name", "not UTF-8",
          build=raw_bytes('name = "cube8"', b'name = "\xff\xfe"')),
        C("encoding", "latin1", "a Latin-1 encoded u-umlaut in the name", "not UTF-8",
          build=raw_bytes('name = "cube8"', b'name = "c\xfcbe8"')),
        C("encoding", "utf16", "the scenario in UTF-16 after this header", "not UTF-8",
          build=encoded("utf-16")),
        C("encoding", "truncated-utf8", "a UTF-8 sequence cut short", "not UTF-8",
          build=raw_bytes('name = "cube8"', b'name = "cube8\xe2\x82"')),
        C("encoding", "overlong-nul", "an overlong encoding of NUL (0xc0 0x80)", "not UTF-8",
          build=raw_bytes('name = "cube8"', b'name = "cu\xc0\x80be8"')),
        # --- deep nesting -------------------------------------------------------------------
        C("nesting", "arrays-5000", "arrays nested 5000 deep", "nested deeper",
          build=lambda t: t + "\nx = " + "[" * 5000 + "]" * 5000 + "\n"),
        C("nesting", "inline-tables-40", "inline tables nested 40 deep", "nested deeper",
          build=lambda t: t + "\ny = " + "{a = " * 40 + "1" + "}" * 40 + "\n"),
        C("nesting", "arrays-33", "arrays nested 33 deep (one over the limit)", "nested deeper",
          (("kp = 0.5", "kp = " + "[" * 33 + "0.5" + "]" * 33),)),
        C("nesting", "dotted-header-2000", "a table header 2000 keys deep",
          "unknown section [a]", build=deep_dotted_header),
        # --- huge values --------------------------------------------------------------------
        C("huge", "name", f"a name of {HUGE} characters", "scenario.name",
          (('name = "cube8"', f'name = "{"x" * HUGE}"'),)),
        C("huge", "method", f"a method of {HUGE} characters", "controller.method",
          (('method = "dcbf"', f'method = "{"d" * HUGE}"'),)),
        C("huge", "graph", f"a graph name of {HUGE} characters", "formation.graph",
          (('graph = "cube_face_diagonals"', f'graph = "{"g" * HUGE}"'),)),
        C("huge", "section-name", f"a table name of {HUGE} characters", "unknown section",
          build=lambda t: t + f"\n[{'s' * HUGE}]\nx = 1\n"),
        C("huge", "key", f"a key of {HUGE} characters", "unknown key vehicle.",
          (("mass_kg = 1.8", f"mass_kg = 1.8\n{'k' * HUGE} = 1"),)),
        # once a bug: a 20 000-character key in [mission], [[obstacle]] or [geofence] was
        # quoted whole, a 20 kB error line; fixed in swarm_common/table_check.py (key_text)
        C("huge", "mission-key", f"a [mission] key of {HUGE} characters",
          "unknown key mission.'kkk",
          (("speed_mps = 1.5 ", f"{'k' * HUGE} = 1\nspeed_mps = 1.5 "),), base=COURSE8),
        C("huge", "obstacle-key", f"an [[obstacle]] key of {HUGE} characters",
          "unknown key obstacle[1].'kkk", ((SPHERE_1, SPHERE_1 + f"\n{'k' * HUGE} = 1"),),
          base=OBSTACLES),
        C("huge", "geofence-key", f"a [geofence] key of {HUGE} characters",
          "unknown key geofence.'kkk",
          (("max_m = [8.0, 7.0, 9.5]", f"max_m = [8.0, 7.0, 9.5]\n{'k' * HUGE} = 1"),),
          base=OBSTACLES),
        C("huge", "fault-value", "a faults value of 401 digits", "faults.mavlink.drop",
          build=lambda t: t + f"\n[faults.mavlink]\ndrop = {DIGITS_400}\n"),
        # --- consistent keys, unsafe or infeasible together --------------------------------
        C("unsafe", "start-too-close", "agents 3 and 4 start 0.2 m apart",
          "closer than controller.d_safe_m",
          (("position = [2.0, 0.4, 2.9]", "position = [2.0, 0.4, 4.9]"),)),
        C("unsafe", "vertex-too-close", "a vertex 0.4 m from another at the leaders' scale",
          "agent[3].vertex", (("vertex = [0, 0, 1]", "vertex = [0, 0, 0.1]"),)),
        C("unsafe", "infeasible", "a 0.4 Hz leader sinusoid (too much acceleration)",
          "--allow-infeasible", (("frequency_hz = 0.2", "frequency_hz = 0.4"),)),
        C("unsafe", "gain-vs-lag", "kp = 5.0: the followers' loop loses its lag margin",
          "--allow-unsafe", (("kp = 0.5", "kp = 5.0"),)),
        C("unsafe", "head-on", "agents 3 and 4 rush at each other at 9 m/s", "--allow-unsafe",
          (("velocity = [0.0, 0.0, 0.6]", "velocity = [0.0, 0.0, 9.0]"),)),
        C("unsafe", "ground-pad-z", 'lifecycle.start = "ground" with agents in the air',
          "the position is a pad", build=lambda t: t + '\n[lifecycle]\nstart = "ground"\n'),
    ]


def body(case: Case) -> bytes:
    """The file's bytes: the two header lines, then the edited base."""
    text = (SCENARIOS / case.base).read_text()
    for old, new in case.edits:
        text = _replace(text, old, new)
    built: str | bytes = case.build(text) if case.build is not None else text
    data = built.encode() if isinstance(built, str) else built
    header = f"# BAD {case.kind}: {case.why}\n{EXPECT_PREFIX}{case.expect}\n"
    return header.encode("ascii", "backslashreplace") + data


def main() -> int:
    """Write every case; refuse duplicate names and names the test cannot parse back."""
    all_cases = cases()
    names = [f"{c.kind}-{c.slug}.toml" for c in all_cases]
    if len(set(names)) != len(names):
        raise SystemExit(f"duplicate case names: {sorted(n for n in names if names.count(n) > 1)}")
    for name in names:
        if not re.fullmatch(r"[a-z0-9]+-[a-z0-9.-]+\.toml", name):
            raise SystemExit(f"bad case name {name!r}")
    OUT.mkdir(exist_ok=True)
    for old in OUT.glob("*.toml"):
        old.unlink()
    for case, name in zip(all_cases, names, strict=True):
        (OUT / name).write_bytes(body(case))
    print(f"wrote {len(names)} files to {OUT}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
