"""One line before take-off: the plan's envelope and whether the vehicles' parameters agree
(:mod:`..preflight`); it steps aside once a vehicle flies its agent's setpoints."""

from __future__ import annotations

from rich.text import Text
from textual.widgets import Static

from ..view.preflight import ParamAgreement, PlanEnvelope


class PreflightPanel(Static):
    DEFAULT_CSS = """
    PreflightPanel { height: 1; background: $boost; padding: 0 1; }
    """

    def __init__(self, envelope: PlanEnvelope | None = None, **kw) -> None:
        super().__init__("", **kw)
        self.envelope = envelope
        self.params: ParamAgreement | None = None
        self.text = ""
        self.display = envelope is not None

    def show(self, params: ParamAgreement | None, flying: bool) -> None:
        """Draw the envelope and ``params`` (None: not asked yet); hidden while ``flying``."""
        self.params = params
        if self.envelope is None or flying:
            self.display = False
            return
        self.display = True
        env = self.envelope
        t = Text(no_wrap=True, overflow="ellipsis")
        t.append("pre-flight ", "dim")
        t.append(env.line(), "" if env.pairs_apart else "bold red")
        t.append("  ")
        if params is None:
            t.append("params: asking the vehicles", "dim")
        else:
            t.append(params.line(), "green" if params.agree else "bold yellow")
        self.text = t.plain
        self.update(t)
