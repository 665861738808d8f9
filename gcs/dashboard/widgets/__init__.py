"""Small composable Textual widgets of the dashboard, one per module.

:class:`VehicleTable` (per-vehicle rows), :class:`FormationView` (the swarm seen from
above), :class:`MinDistancePlot`, :class:`EventLog`, :class:`StatusBar`, and the modal
screens :class:`ConfirmScreen` and :class:`ChoiceScreen`; :mod:`.fmt` formats numbers.
"""

from .distance_plot import MinDistancePlot
from .event_log import EventLog
from .formation import FormationView
from .modals import ChoiceScreen, ConfirmScreen
from .status_bar import StatusBar
from .vehicle_table import VehicleTable

__all__ = [
    "ChoiceScreen",
    "ConfirmScreen",
    "EventLog",
    "FormationView",
    "MinDistancePlot",
    "StatusBar",
    "VehicleTable",
]
