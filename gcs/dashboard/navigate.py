"""The dashboard's navigation menu (``n``): step, climb, scale and turn the formation, hold it
and resume its mission, through the leaders' ``mission`` and ``hold`` Zenoh commands
(docs/missions.md, "Changing a mission in flight"); and its typed go-to (``g``). Each is
checked by :class:`gcs.formation.steer.FormationSteer` before it is sent."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from gcs.formation.steer import FormationSteer
from swarm_common import wire
from swarm_common.mission.config import MissionError

from .view.mission_progress import MissionProgress, parse_goto, progress_at

STEP_M = 2.0  # m, a horizontal step of the centroid
CLIMB_M = 1.0  # m, a vertical step
SCALE_STEP = 1.2  # × (grow) or ÷ (shrink)
TURN_DEG = 30.0  # deg, a turn (counter-clockwise seen from above: left)
MENU_TITLE = "Fly the formation:"
GOTO_PROMPT = "Go to x y z [yaw°] (ENU, m):"
GOTO_HINT = "20 0 5  or  20, 0, 5, 90"
ERROR = mavlink.MAV_SEVERITY_ERROR  # the event log's severity of a refusal
NEEDS = "needs a launched scenario with a [mission] and a live Zenoh feed"

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
# what makes a menu's answer (a choice, a typed go-to) into the command at a mission time (s)
MakeCommand = Callable[[FormationSteer, str, float], wire.Command]


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


def goto_command(steer: FormationSteer, text: str, t: float) -> wire.Command:
    """The typed go-to's command (``text``: ``"x y z [yaw]"``, m ENU and deg, see
    :func:`.mission_progress.parse_goto`) at mission time ``t`` (s); a bad entry or a
    centroid the leaders could not fly raises MissionError."""
    centroid, yaw_deg = parse_goto(text)
    return steer.goto(centroid, t, yaw_deg)


def steer_time(steer: FormationSteer | None, commander: Any) -> float | None:
    """The swarm's mission time (s) when the formation can be steered (a mission scenario's
    ``steer``, the ``commander``'s Zenoh up and its mission time known), else None."""
    up = getattr(commander, "zenoh_up", None)
    t_now = getattr(commander, "mission_time", lambda: None)()
    if steer is None or not (callable(up) and up()) or t_now is None:
        return None
    return float(t_now)


def progress(steer: FormationSteer | None, commander: Any) -> MissionProgress | None:
    """The mission's progress at the ``commander``'s mission time (s), or None without a
    ``steer`` or that time (the mission panel, :mod:`.mission_progress`)."""
    t_now = getattr(commander, "mission_time", lambda: None)()
    return None if steer is None or t_now is None else progress_at(steer.timeline, t_now)


def sender(
    app: Any, what: str, steer: FormationSteer, t: float, make: MakeCommand
) -> Callable[[str | None], None]:
    """A modal's callback: ``app.send_zenoh(make(steer, answer, t))`` for an answer (none:
    cancelled); a refused one (MissionError) is one ERROR line in the app's event log."""

    def done(answer: str | None) -> None:
        if not answer:
            return
        try:
            cmd = make(steer, answer, t)
        except MissionError as exc:
            app.log_event(0, "cmd", f"{what} {answer} refused: {exc}", ERROR)
            return
        app.send_zenoh(cmd)

    return done
