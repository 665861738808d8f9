"""Small composable Textual widgets of the dashboard, one per module.

:class:`VehicleTable` (per-vehicle rows), :class:`FormationView` (the swarm seen from
above), :class:`MinDistancePlot`, :class:`EventLog`, :class:`StatusBar`,
:class:`MissionPanel` (:mod:`.mission_panel`: the mission's next waypoint and progress),
:class:`PreflightPanel` (:mod:`.preflight_panel`: the plan's envelope and the vehicles'
parameters, before take-off), :class:`ReplayBar` (:mod:`.replay_bar`: a replay's min
distance now and over the run), and
the modal screens :class:`ConfirmScreen`, :class:`ChoiceScreen` and :class:`InputScreen`;
:mod:`.fmt` formats numbers.
"""

from .distance_plot import MinDistancePlot
from .event_log import EventLog
from .formation import FormationView
from .mission_panel import MissionPanel
from .modals import ChoiceScreen, ConfirmScreen, InputScreen
from .preflight_panel import PreflightPanel
from .replay_bar import ReplayBar
from .status_bar import StatusBar
from .vehicle_table import VehicleTable

__all__ = [
    "ChoiceScreen",
    "ConfirmScreen",
    "EventLog",
    "FormationView",
    "InputScreen",
    "MinDistancePlot",
    "MissionPanel",
    "PreflightPanel",
    "ReplayBar",
    "StatusBar",
    "VehicleTable",
]
