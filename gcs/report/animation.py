"""A short GIF of the swarm around a run's closest approach, written by
:func:`gcs.report.comparison.write_report` through matplotlib's Pillow animation writer.

The window is the closest approach's time ± :data:`HALF_WINDOW_S` (cut to the run), one
frame every 1/:data:`FPS` s of simulated time played at :data:`FPS` frames per second (real
time), small (:data:`DPI`). Above, the same top and side views as :mod:`gcs.report.paths`:
each vehicle at the frame's time, its path over the window in light grey, and the frame's
nearest pair ringed and joined (magenta; red and thick at the closest approach itself).
Below, the smallest pair distance over the window against time, the closest approach
starred and a cursor at the frame's time. Only where matplotlib has the writer
(:func:`writer_available`); otherwise nothing is written and the report says so in one
line (:data:`NO_WRITER`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.artist import Artist

from gcs.report.paths import Closest, View, closest_of, draw_world_2d, pyplot, view_limits
from swarm_common.world.config import World

WRITER = "pillow"  # matplotlib.animation's writer name: Pillow, GIF files
HALF_WINDOW_S = 3.0  # s either side of the closest approach
FPS = 10  # frames per second of the GIF and per simulated second
DPI = 80  # 6.4 x 4 inches: 512 x 320 pixels
COLOURS = 64  # the GIF's palette
NO_WRITER = (f"No animation of the closest approach: matplotlib has no {WRITER!r} "
             "animation writer here (Pillow is not installed).")


@dataclass(frozen=True)
class Clip:
    """What an animation written shows."""

    path: Path
    t0_s: float  # first frame's time (s)
    t1_s: float  # last frame's time (s)
    frames: int
    closest: Closest


def writer_available() -> bool:
    """Whether matplotlib can write the GIF here (its :data:`WRITER` is installed)."""
    from matplotlib import animation

    return bool(animation.writers.is_available(WRITER))


def frame_steps(t: np.ndarray, k: int, half_s: float = HALF_WINDOW_S, fps: int = FPS) -> np.ndarray:
    """The steps of the frames: the step nearest to each time t_k + j/``fps`` within
    ``half_s`` of t_k and inside the run (t_k itself among them), in time order."""
    j = np.arange(-int(round(half_s * fps)), int(round(half_s * fps)) + 1)
    want = t[k] + j / fps
    want = want[(want >= t[0] - 1e-9) & (want <= t[-1] + 1e-9)]
    idx = np.clip(np.searchsorted(t, want - 1e-9), 0, len(t) - 1)
    before = np.clip(idx - 1, 0, len(t) - 1)  # the nearer of the two neighbours
    idx = np.where(np.abs(t[before] - want) < np.abs(t[idx] - want), before, idx)
    return np.unique(np.append(idx, k))


def gif_writer(fps: int) -> Any:
    """matplotlib's Pillow writer, its frames mapped onto one palette (the first frame's
    :data:`COLOURS` colours, no dithering) when it writes the GIF: Pillow would otherwise
    quantize every frame on its own, the slower half of the work and twice the bytes."""
    from matplotlib.animation import PillowWriter  # the writer WRITER names
    from PIL import Image

    class OnePaletteWriter(PillowWriter):
        def finish(self) -> None:
            frames = getattr(self, "_frames", None)  # PillowWriter's grabbed RGB(A) images
            if frames and all(f.mode == "RGB" for f in frames):
                first = frames[0].quantize(COLOURS, method=Image.Quantize.FASTOCTREE,
                                           dither=Image.Dither.NONE)
                self._frames = [first, *(f.quantize(palette=first, dither=Image.Dither.NONE)
                                         for f in frames[1:])]
            super().finish()

    return OnePaletteWriter(fps=fps)


class Still(Artist):
    """A picture of the figure's own size (RGBA, rows top to bottom) drawn as it is: the
    still part of every frame, without the resampling of ``figimage`` (ten times dearer)."""

    def __init__(self, rgba: np.ndarray) -> None:
        super().__init__()
        self._rows = np.ascontiguousarray(rgba[::-1])  # the renderer's rows go bottom to top

    def draw(self, renderer: Any) -> None:
        gc = renderer.new_gc()
        renderer.draw_image(gc, 0, 0, self._rows)
        gc.restore()


def _nearest_pair(p: np.ndarray) -> tuple[int, int, float]:
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)
    d[np.diag_indices(len(p))] = np.inf
    a, b = np.unravel_index(int(np.argmin(d)), d.shape)
    return int(a), int(b), float(d[a, b])


def panels(
    win: np.ndarray, world: World | None, heading: str = "",
    t_win: np.ndarray | None = None, d_win: np.ndarray | None = None,
) -> tuple[Any, list[Any]]:
    """The animation's still part: the top and side views (axes labelled, ENU, m) framing
    the window's positions ``win`` (K, N, 3), each vehicle's path over it in light grey,
    ``world``'s obstacles and fence, the legend and the ``heading``; below, the window's
    smallest pair distance ``d_win`` (m) against its times ``t_win`` (s), its minimum
    starred. (figure, [top, side, distance] axes), at :data:`DPI`."""
    from matplotlib.lines import Line2D

    plt = pyplot()
    lo, hi = view_limits(win, world)
    fig = plt.figure(figsize=(6.4, 4.0), dpi=DPI, facecolor="w")
    grid = fig.add_gridspec(2, 2, height_ratios=(3.0, 1.0))
    axes = [fig.add_subplot(grid[0, 0]), fig.add_subplot(grid[0, 1]),
            fig.add_subplot(grid[1, :])]
    for ax, view in zip(axes, (View.TOP, View.SIDE), strict=False):
        a, b = view.axes
        draw_world_2d(ax, world, view)
        ax.plot(win[:, :, a], win[:, :, b], color="0.8", lw=0.6)
        ax.set(xlim=(lo[a], hi[a]), ylim=(lo[b], hi[b]))
        ax.set_xlabel(view.labels[0], fontsize=8)
        ax.set_ylabel(view.labels[1], fontsize=8)
        ax.set_aspect("equal", adjustable="box")
    strip = axes[2]
    if t_win is not None and d_win is not None and len(t_win):
        strip.plot(t_win, d_win, color="k", lw=0.8)
        k = int(np.argmin(d_win))
        strip.plot([t_win[k]], [d_win[k]], "m*", ms=8)
        strip.set_ylim(0.0, max(1.1 * float(np.max(d_win)), 1e-3))
        if t_win[-1] > t_win[0]:  # a window of one step keeps the default limits
            strip.set_xlim(t_win[0], t_win[-1])
    strip.set_xlabel("time t (s)", fontsize=8)
    strip.set_ylabel("min dist. (m)", fontsize=8)
    strip.grid(True, alpha=0.3)
    for ax in axes:
        ax.tick_params(labelsize=7)
    keys = [Line2D([], [], ls="", marker="o", color="C3", ms=4, label="leaders"),
            Line2D([], [], ls="", marker="o", color="C0", ms=4, label="followers"),
            Line2D([], [], color="m", marker="o", mfc="none", label="nearest pair")]
    axes[0].legend(handles=keys, fontsize=6, loc="upper left")
    fig.suptitle(heading, fontsize=8)
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.11, top=0.9, wspace=0.3, hspace=0.35)
    return fig, axes


def animate_closest(
    s: dict,
    path: Path,
    title: str,
    follower_idx: Sequence[int],
    ids: Sequence[int],
    world: World | None = None,
    half_s: float = HALF_WINDOW_S,
    fps: int = FPS,
) -> Clip | None:
    """The GIF of the swarm around the closest approach of ``s`` (module docstring) into
    ``path``; None, and nothing written, when :func:`writer_available` is false.

    Cheap: the still part (:func:`panels`) is drawn once, and each frame draws that picture
    and the few moving marks over it (a frame of full axes costs about 20 times more)."""
    if not writer_available():
        return None
    from matplotlib.lines import Line2D

    p, t, dmin = s["p"], s["t"], s["min_dist"]
    ca = closest_of(s, ids)
    steps = frame_steps(t, ca.k, half_s, fps)
    span = slice(steps[0], steps[-1] + 1)
    fig, axes = panels(p[span], world,
                       f"{title}: closest approach {ca.ids[0]}–{ca.ids[1]}, "
                       f"{ca.distance_m:.3f} m at t = {ca.t_s:.2f} s "
                       f"(window {t[steps[0]]:.2f}–{t[steps[-1]]:.2f} s)", t[span], dmin[span])
    fig.canvas.draw()
    still = np.asarray(fig.canvas.buffer_rgba()).copy()
    # data -> pixels of each panel as laid out, for the marks drawn over the still picture
    to_px = [ax.transData.frozen() for ax in axes]
    d_lim = axes[2].get_ylim()
    plt = pyplot()
    plt.close(fig)
    # a new figure without a layout engine: a frame is then a single draw
    fig = plt.figure(figsize=(still.shape[1] / DPI, still.shape[0] / DPI), dpi=DPI)
    fig.add_artist(Still(still))
    marks = []
    for view, tr in zip((View.TOP, View.SIDE), to_px, strict=False):
        pair = Line2D([], [], color="m", lw=1.5, marker="o", mfc="none", ms=9, transform=tr)
        leaders = Line2D([], [], ls="", marker="o", color="C3", ms=4, transform=tr)
        followers = Line2D([], [], ls="", marker="o", color="C0", ms=4, transform=tr)
        for mark in (pair, leaders, followers):
            fig.add_artist(mark)
        marks.append((*view.axes, pair, leaders, followers))
    cursor = fig.add_artist(Line2D([], [], color="r", lw=1.2, marker="o", ms=4,
                                   markevery=[1], transform=to_px[2]))
    now = fig.text(0.99, 0.01, "", ha="right", color="r", fontsize=8)  # redrawn per frame
    lead = [j for j in range(p.shape[1]) if j not in follower_idx]
    writer = gif_writer(fps)
    with writer.saving(fig, str(path), DPI):
        for i in steps:
            pi = p[i]
            na, nb, _ = _nearest_pair(pi)
            at_closest = int(i) == ca.k
            if at_closest:  # the pair of the recorded minimum, as in the paths figure
                na, nb = ca.pair
            for a, b, pair, leaders, followers in marks:
                pair.set_data([pi[na, a], pi[nb, a]], [pi[na, b], pi[nb, b]])
                pair.set(color="r" if at_closest else "m", lw=3.0 if at_closest else 1.5)
                leaders.set_data(pi[lead, a], pi[lead, b])
                followers.set_data(pi[follower_idx, a], pi[follower_idx, b])
            cursor.set_data([t[i], t[i]], [d_lim[0], dmin[i]])
            now.set_text(f"t = {t[i]:.2f} s")
            writer.grab_frame()
    plt.close(fig)
    return Clip(path, float(t[steps[0]]), float(t[steps[-1]]), len(steps), ca)
