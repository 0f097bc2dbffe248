"""A still picture of a whole episode: every vehicle's path over the map (matplotlib).

:func:`plot_trajectories` draws an episode record (see :mod:`pes.record.episode`) on a
matplotlib ``Axes``: the buildings, each pursuer's path from its start (circle) to its end
(triangle), the evader's path, the capture point with the capture radius, the pursuers that were
damaged (a cross where they stopped) and, where the policy made them, TP Net's predicted evader
positions. :func:`save_plot` writes one such picture to a PNG (or any format matplotlib knows).
Figures of several episodes side by side (the paper's Figs. 11-12) call
:func:`plot_trajectories` once per ``Axes``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Rectangle

from pes.errors import PESError
from pes.paths import prepare_output

BUILDING = "#6c757d"
EVADER = "#d62728"
PREDICTION = "#ff7f0e"
DAMAGED = "#495057"


def _pursuer_colours(n: int) -> list:
    from matplotlib import colormaps

    cmap = colormaps["winter" if n > 10 else "tab10"]
    if n > 10:
        return [cmap(i / max(n - 1, 1)) for i in range(n)]
    # tab10 without its red (index 3, the evader's) and orange (index 1, the predictions')
    return [cmap(i) for i in (0, 2, 4, 5, 6, 7, 8, 9, 0, 2)][:n]


def plot_trajectories(
    record: dict[str, Any],
    ax: Axes | None = None,
    *,
    title: str | None = None,
    predictions: bool = True,
    prediction_every: int = 10,
    legend: bool = True,
) -> Axes:
    """Draw the episode ``record`` (a dict as :func:`pes.record.load_record` returns) on ``ax``.

    Args:
        record: an episode record (positions in metres).
        ax: the Axes to draw on; a new 6 x 6 inch figure's if None.
        title: the Axes title; by default the outcome (captured or not, steps, seconds, how
            many pursuers were damaged).
        predictions: draw the frames' ``pred`` (TP Net's predicted evader positions), if any.
        prediction_every: draw the predictions of every this many steps.
        legend: add a legend.

    Returns:
        The Axes (x and y in metres, equal aspect, limited to the arena).
    """
    frames = record.get("frames") or []
    if not frames:
        raise PESError("the episode record has no frames")
    if ax is None:
        ax = Figure(figsize=(6, 6), layout="constrained").add_subplot()
    n = sum(1 for a in record["agents"] if a["role"] == "pursuer")
    width, height = record["arena"]
    capture_radius = record.get("capture_radius", 2.0)

    ax.add_patch(Rectangle((0, 0), width, height, fill=False, edgecolor="#343a40", lw=1.5))
    for xmin, ymin, xmax, ymax in record["buildings"]:
        ax.add_patch(
            Rectangle((xmin, ymin), xmax - xmin, ymax - ymin, color=BUILDING, alpha=0.85, lw=0)
        )

    if predictions and prediction_every > 0:
        for k in range(0, len(frames), prediction_every):
            pred = frames[k].get("pred")
            if pred:
                xs = [frames[k]["pos"][n][0]] + [p[0] for p in pred]
                ys = [frames[k]["pos"][n][1]] + [p[1] for p in pred]
                ax.plot(xs, ys, color=PREDICTION, lw=1.2, alpha=0.9, zorder=4)
                ax.plot(xs[1:], ys[1:], "o", color=PREDICTION, ms=2.5, zorder=4)

    colours = _pursuer_colours(n)
    damaged = 0
    for v in range(n):
        # A damaged pursuer's path ends where it was disabled (it no longer moves).
        alive = [f["alive"][v] for f in frames]
        last = len(frames) - 1 if all(alive) else max(alive.index(False), 0)
        xs = [f["pos"][v][0] for f in frames[: last + 1]]
        ys = [f["pos"][v][1] for f in frames[: last + 1]]
        ax.plot(xs, ys, color=colours[v], lw=1.4, zorder=3)
        ax.plot(xs[0], ys[0], "o", color=colours[v], ms=5, zorder=5)
        if all(alive):
            ax.plot(xs[-1], ys[-1], "^", color=colours[v], ms=7, mec="white", mew=0.6, zorder=5)
        else:
            damaged += 1
            ax.plot(xs[-1], ys[-1], "X", color=DAMAGED, ms=10, mec="white", mew=0.8, zorder=6)

    ex = [f["pos"][n][0] for f in frames]
    ey = [f["pos"][n][1] for f in frames]
    ax.plot(ex, ey, color=EVADER, lw=1.8, zorder=3)
    ax.plot(ex[0], ey[0], "o", color=EVADER, ms=6, zorder=5)
    outcome = record.get("outcome") or {}
    success = bool(outcome.get("success"))
    if success:
        ax.add_patch(
            Circle((ex[-1], ey[-1]), capture_radius, fill=False, ec=EVADER, lw=1, ls="--", zorder=6)
        )
        ax.plot(ex[-1], ey[-1], "*", color=EVADER, ms=14, mec="black", mew=0.6, zorder=7)
    else:
        ax.plot(ex[-1], ey[-1], "s", color=EVADER, ms=6, zorder=5)

    ax.set_xlim(0, width)
    ax.set_ylim(0, height)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    if title is None:
        steps = outcome.get("steps", len(frames) - 1)
        verdict = "captured" if success else "not captured"
        title = f"{n} pursuers, {verdict} in {steps} steps ({steps * record['dt']:.1f} s)"
        if damaged:
            title += f", {damaged} damaged"
    ax.set_title(title, fontsize=10)
    if legend:
        handles = [
            Line2D(
                [], [], color="#1f77b4", lw=1.4, marker="o", ms=4, label="pursuers (o start, ^ end)"
            ),
            Line2D([], [], color=EVADER, lw=1.8, label="evader"),
        ]
        if success:
            handles.append(Line2D([], [], ls="", marker="*", color=EVADER, ms=10, label="capture"))
        if damaged:
            handles.append(Line2D([], [], ls="", marker="X", color=DAMAGED, ms=8, label="damaged"))
        if predictions and any(f.get("pred") for f in frames):
            handles.append(
                Line2D([], [], color=PREDICTION, marker="o", ms=3, label="TP Net prediction")
            )
        ax.legend(handles=handles, loc="best", fontsize=7, framealpha=0.85)
    return ax


def save_plot(record: dict[str, Any], path: str | Path, dpi: int = 150, **kwargs: Any) -> Path:
    """Write :func:`plot_trajectories` of ``record`` to ``path`` (PNG, or another format
    matplotlib knows by the suffix); ``kwargs`` go to :func:`plot_trajectories`."""
    path = prepare_output(path)
    ax = plot_trajectories(record, **kwargs)
    ax.figure.savefig(path, dpi=dpi)
    return path


__all__ = ["plot_trajectories", "save_plot"]
