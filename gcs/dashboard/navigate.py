"""The dashboard's navigation menu (``n``): step, climb, scale and turn the formation, hold it
and resume its mission, through the leaders' ``mission`` and ``hold`` Zenoh commands
(docs/missions.md, "Changing a mission in flight"). Each choice is checked by
:class:`gcs.formation.steer.FormationSteer` before it is sent."""

from __future__ import annotations

from gcs.formation.steer import FormationSteer
from swarm_common import wire
from swarm_common.mission.config import MissionError

STEP_M = 2.0  # m, a horizontal step of the centroid
CLIMB_M = 1.0  # m, a vertical step
SCALE_STEP = 1.2  # × (grow) or ÷ (shrink)
TURN_DEG = 30.0  # deg, a turn (counter-clockwise seen from above: left)

CHOICES: list[tuple[str, str]] = [
    ("north", f"north {STEP_M:g} m"), ("south", f"south {STEP_M:g} m"),
    ("east", f"east {STEP_M:g} m"), ("west", f"west {STEP_M:g} m"),
    ("up", f"up {CLIMB_M:g} m"), ("down", f"down {CLIMB_M:g} m"),
    ("grow", f"scale ×{SCALE_STEP:g}"), ("shrink", f"scale ÷{SCALE_STEP:g}"),
    ("left", f"turn left {TURN_DEG:g}°"), ("right", f"turn right {TURN_DEG:g}°"),
    ("hold", "pause: stop at the next waypoint"), ("resume", "resume the mission"),
]  # fmt: skip
_MOVES = {
    "north": (0.0, STEP_M, 0.0), "south": (0.0, -STEP_M, 0.0),
    "east": (STEP_M, 0.0, 0.0), "west": (-STEP_M, 0.0, 0.0),
    "up": (0.0, 0.0, CLIMB_M), "down": (0.0, 0.0, -CLIMB_M),
}  # fmt: skip


def command_for(steer: FormationSteer, choice: str, t: float) -> wire.Command:
    """The Zenoh command of a menu ``choice`` at the swarm's mission time ``t`` (s); a choice
    the leaders could not fly (too low, too dense, nothing to resume) raises MissionError."""
    if choice in _MOVES:
        return steer.nudge(t, d_centroid=_MOVES[choice])
    if choice in ("grow", "shrink"):
        return steer.nudge(t, scale_by=SCALE_STEP if choice == "grow" else 1.0 / SCALE_STEP)
    if choice in ("left", "right"):
        return steer.nudge(t, d_yaw_deg=TURN_DEG if choice == "left" else -TURN_DEG)
    if choice == "hold":
        return steer.hold(t)
    if choice == "resume":
        return steer.resume(t)
    raise MissionError(f"navigation: unknown choice {choice!r}")
