"""A row per vehicle: mode, arming, link health, state, errors, safety, QP, failsafe."""

from __future__ import annotations

from collections.abc import Callable

from rich.text import Text
from textual.widgets import DataTable

from swarm_common.enums import QPStatus

from ..px4modes import short_mode
from ..view.state import SwarmView, VehicleRow
from .fmt import age, num, vec

QP_SHORT: dict[str, str] = {
    QPStatus.INACTIVE: "inact",
    QPStatus.SOLVED: "solved",
    QPStatus.RELAXED: "relax",
    QPStatus.FALLBACK: "fallbk",
}
Cell = Callable[[VehicleRow, SwarmView], Text | str]


def _link(r: VehicleRow, compact: bool) -> Text:
    if r.hb_age is None and r.link_lost:
        return Text("silent" if compact else "never", "bold red")
    s = f"{age(r.hb_age)} {r.rate_hz:3.0f}Hz" if not compact else f"{age(r.hb_age)} {r.rate_hz:.0f}"
    return Text(s, "bold red" if r.link_lost else "green")


def _h(r: VehicleRow, v: SwarmView) -> Text:
    if r.h_min is None:
        return Text("miss" if r.status_missing else "-", "yellow" if r.status_missing else "dim")
    return Text(num(r.h_min, 5, 2), "bold red" if r.h_min < 0 else "")


def _nn(r: VehicleRow, v: SwarmView) -> Text:
    if r.nn_dist is None:
        return Text("-", "dim")
    return Text(num(r.nn_dist, 4, 2), "bold red" if r.nn_dist < v.d_safe else "")


def _qp(r: VehicleRow, compact: bool) -> Text:
    if r.qp_status is None:
        return Text("miss" if r.status_missing else "-", "yellow" if r.status_missing else "dim")
    st = QP_SHORT.get(r.qp_status, r.qp_status[:6])
    good = r.qp_status == QPStatus.SOLVED
    style = "" if good else "yellow"
    if compact:
        return Text(f"{r.qp_us or 0:4.0f}" if good else st[:4], style)
    return Text(st, style)


def _fs(r: VehicleRow, v: SwarmView) -> Text:
    return Text(r.failsafe, "green" if r.failsafe == "ok" else "bold red")


def _id(r: VehicleRow, v: SwarmView, compact: bool) -> Text:
    style = "bold yellow" if r.is_leader else "bold cyan"
    if compact:
        return Text(f"{r.id}{'L' if r.is_leader else 'F'}", style)
    return Text(str(r.id), style)


def _arm(r: VehicleRow, compact: bool) -> Text:
    if r.armed is None:
        return Text("?", "dim")
    if compact:
        return Text("A" if r.armed else "-", "bold" if r.armed else "dim")
    return Text("yes" if r.armed else "no", "bold" if r.armed else "dim")


def _err(x: float | None, width: int) -> Text:
    if x is None:
        return Text("-", "dim")
    return Text(num(x, width, 2), "yellow" if x > 0.5 else "")


FULL: list[tuple[str, str, Cell]] = [
    ("id", "ID", lambda r, v: _id(r, v, False)),
    ("role", "Role", lambda r, v: r.role),
    ("mode", "Mode", lambda r, v: Text(r.mode, "bold red" if r.link_lost else "")),
    ("arm", "Arm", lambda r, v: _arm(r, False)),
    ("link", "Link HB/rate", lambda r, v: _link(r, False)),
    ("pos", "Position E N U m", lambda r, v: vec(r.pos, 5, 1)),
    ("vel", "Velocity m/s", lambda r, v: vec(r.vel, 5, 1)),
    ("trk", "Trk", lambda r, v: _err(r.track_err, 5)),
    ("est", "Est", lambda r, v: _err(r.est_err, 5)),
    ("nn", "NN m", _nn),
    ("h", "h_min", _h),
    ("qp", "QP", lambda r, v: _qp(r, False)),
    ("us", "QP µs", lambda r, v: num(r.qp_us, 5, 0) if r.qp_us is not None else "-"),
    ("method", "Meth", lambda r, v: r.method or "-"),
    ("fs", "Failsafe", _fs),
]
COMPACT: list[tuple[str, str, Cell]] = [
    ("id", "ID", lambda r, v: _id(r, v, True)),
    ("mode", "Mode", lambda r, v: Text(short_mode(r.mode), "bold red" if r.link_lost else "")),
    ("arm", "A", lambda r, v: _arm(r, True)),
    ("link", "Link", lambda r, v: _link(r, True)),
    ("pos", "Pos E N U", lambda r, v: vec(r.pos, 4, 1)),
    ("trk", "Trk", lambda r, v: _err(r.track_err, 4)),
    ("est", "Est", lambda r, v: _err(r.est_err, 4)),
    ("nn", "NN", _nn),
    ("h", "h_min", _h),
    ("qp", "QP µs", lambda r, v: _qp(r, True)),
    ("fs", "FS", _fs),
]


class VehicleTable(DataTable):
    """``show(view, compact)`` refreshes the cells in place; the cursor row is kept."""

    DEFAULT_CSS = """
    VehicleTable { height: auto; max-height: 12; }
    """

    def __init__(self, **kw) -> None:
        super().__init__(cursor_type="row", zebra_stripes=False, cell_padding=1, **kw)
        self._compact: bool | None = None
        self._ids: list[int] = []

    @property
    def selected_id(self) -> int | None:
        if not self._ids or self.cursor_row < 0 or self.cursor_row >= len(self._ids):
            return None
        return self._ids[self.cursor_row]

    def show(self, view: SwarmView, compact: bool) -> None:
        cols = COMPACT if compact else FULL
        ids = [r.id for r in view.rows]
        if compact != self._compact or ids != self._ids:
            cursor = self.cursor_row
            self.clear(columns=True)
            self.cell_padding = 0 if compact else 1
            for key, label, _ in cols:
                self.add_column(_pad(label, compact), key=key)
            for r in view.rows:
                self.add_row(*[_pad(f(r, view), compact) for _, _, f in cols], key=str(r.id))
            self._compact, self._ids = compact, ids
            if ids:
                self.move_cursor(row=min(max(cursor, 0), len(ids) - 1))
            return
        for r in view.rows:
            for key, _, f in cols:
                self.update_cell(str(r.id), key, _pad(f(r, view), compact), update_width=True)


def _pad(cell: Text | str, compact: bool) -> Text | str:
    """Compact tables have no cell padding: one leading space separates the columns."""
    if not compact:
        return cell
    return Text(" ") + (cell if isinstance(cell, Text) else Text(cell))
