"""The formation seen from above (x-y) or from the side (x-z), drawn with characters.

The desired cube (edges ``·``, vertices ``+``) is drawn under the vehicles (their id,
yellow for leaders, cyan for followers, red on white when their link is silent); under it,
when given (:meth:`FormationView.show_path`), the mission's planned centroid path (dim ``·``)
and its next waypoint (``◎``). Under everything, when the app has the scenario's world
(:meth:`FormationView.show_world`), each obstacle's footprint (grey ``░``) and the
geofence's outline (dim red ``┄``/``┆``, ``·`` at its corners); see gcs.dashboard.view.world_cells.
One character cell is taken as twice as tall as wide, so the picture keeps its aspect.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from rich.text import Text
from textual.widget import Widget

from swarm_common.world.config import World

from ..view.state import SwarmView
from ..view.world_cells import AXES, ROW_ASPECT, Fit, WorldCells, world_cells, world_extent

OBSTACLE = ("░", "grey50")
FENCE_STYLE = "dim red"


def glyph(agent_id: int) -> str:
    if agent_id < 10:
        return str(agent_id)
    if agent_id < 36:
        return chr(ord("a") + agent_id - 10)
    return "*"


class FormationView(Widget):
    DEFAULT_CSS = """
    FormationView { border: round $primary 60%; height: 1fr; min-height: 5; }
    """

    def __init__(self, plane: str = "xy", world: World | None = None, **kw) -> None:
        super().__init__(**kw)
        self.plane = plane
        self.view: SwarmView | None = None
        self.world: World | None = None
        self.world_pts: np.ndarray | None = None  # (N, 3) m ENU, bounds of the world
        self._cells: tuple[Fit, WorldCells] | None = None  # the last fit's world cells
        self.path: np.ndarray | None = None  # (K, 3) m ENU, the planned centroid path
        self.next_wp: np.ndarray | None = None  # (3,) m ENU, the next waypoint's centroid
        ia, ib, la, lb = AXES[plane]
        self.border_title = ("Top " if plane == "xy" else "Side ") + f"{la}-{lb}"
        self.show_world(world)

    def show(self, view: SwarmView) -> None:
        self.view = view
        self.on_resize()
        self.refresh()

    def show_world(self, world: World | None) -> None:
        """Draw ``world``'s obstacles and geofence under everything (None or an empty
        world: nothing); the fit takes them in."""
        self.world = None if world is None or world.empty else world
        self.world_pts = None if self.world is None else world_extent(self.world)
        self._cells = None
        self.on_resize()
        self.refresh()

    def show_path(self, path: np.ndarray | None, next_wp: np.ndarray | None) -> None:
        """Draw the planned centroid path (K, 3) m and the next waypoint (3,) m (ENU) under
        the formation, or neither (None); the fit takes them in."""
        self.path = None if path is None else np.asarray(path, dtype=float).reshape(-1, 3)
        self.next_wp = None if next_wp is None else np.asarray(next_wp, dtype=float).reshape(3)
        self.on_resize()
        self.refresh()

    def on_resize(self) -> None:
        fit = self._fit()
        self.border_subtitle = f"{fit.m_per_col:.2g} m/col" if fit else ""

    def _fit(self) -> Fit | None:
        """The metres-to-cells map fitting every point, or None."""
        w, h = self.content_size.width, self.content_size.height
        if w < 3 or h < 2 or self.view is None:
            return None
        ia, ib, _, _ = AXES[self.plane]
        v = self.view
        pts = [p for p in v.desired.values()] + [r.pos for r in v.rows if r.pos is not None]
        extra = [a for a in (self.path, self.next_wp, self.world_pts) if a is not None]
        arr = np.vstack([np.array(pts, dtype=float).reshape(-1, 3), *extra])
        if not len(arr):
            return None
        amin, amax = float(arr[:, ia].min()), float(arr[:, ia].max())
        bmin, bmax = float(arr[:, ib].min()), float(arr[:, ib].max())
        ra = max(amax - amin, 1.0) * 1.15
        rb = max(bmax - bmin, 1.0) * 1.15
        cx = max(ra / max(w - 1, 1), rb / (ROW_ASPECT * max(h - 1, 1)))
        if not math.isfinite(cx):
            return None
        return Fit(cx, (amin + amax) / 2, (bmin + bmax) / 2, w, h)

    def _world_cells(self, fit: Fit) -> WorldCells | None:
        """The world's cells in this view (kept while the fit stays the same)."""
        if self.world is None:
            return None
        if self._cells is None or self._cells[0] != fit:
            self._cells = fit, world_cells(self.world, self.plane, fit)
        return self._cells[1]

    def render(self) -> Text:
        w, h = self.content_size.width, self.content_size.height
        if w < 3 or h < 2 or self.view is None:
            return Text("")
        fit = self._fit()
        if fit is None:
            return Text("no positions", "dim")
        ia, ib, _, _ = AXES[self.plane]
        v = self.view

        def cell(p: Sequence[float] | np.ndarray) -> tuple[int, int]:
            return fit.cell(p[ia], p[ib])

        grid = [[" "] * w for _ in range(h)]
        style = [[""] * w for _ in range(h)]

        def put(c: int, r: int, ch: str, st: str) -> None:
            if 0 <= c < w and 0 <= r < h:
                grid[r][c] = ch
                style[r][c] = st

        if (wc := self._world_cells(fit)) is not None:
            for cells in wc.obstacles:
                for cr in cells:
                    put(*cr, *OBSTACLE)
            for cr in wc.fence_h | wc.fence_v:
                along_a, along_b = cr in wc.fence_h, cr in wc.fence_v
                put(*cr, "·" if along_a and along_b else "┄" if along_a else "┆", FENCE_STYLE)
        for p in self.path if self.path is not None else ():
            put(*cell(p), "·", "dim")
        for i, j in v.cube_edges:
            if i in v.desired and j in v.desired:
                (c0, r0), (c1, r1) = cell(v.desired[i]), cell(v.desired[j])
                n = max(abs(c1 - c0), abs(r1 - r0), 1)
                for k in range(n + 1):
                    put(round(c0 + (c1 - c0) * k / n), round(r0 + (r1 - r0) * k / n), "·", "green")
        for p in v.desired.values():
            put(*cell(p), "+", "bold green")
        if self.next_wp is not None:
            put(*cell(self.next_wp), "◎", "bold magenta")
        # vehicles, far ones first (so the nearer one is on top)
        depth = 3 - ia - ib
        placed = [(r, r.pos) for r in v.rows if r.pos is not None]
        for r, pos in sorted(placed, key=lambda rp: rp[1][depth]):
            if r.link_lost:
                st = "bold white on red"
            elif r.is_leader:
                st = "bold yellow"
            else:
                st = "bold cyan"
            put(*cell(pos), glyph(r.id), st)
        text = Text(no_wrap=True)
        for rr in range(h):
            for c in range(w):
                text.append(grid[rr][c], style[rr][c] or None)
            if rr < h - 1:
                text.append("\n")
        return text
