"""Small composable Textual widgets of the dashboard."""

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
