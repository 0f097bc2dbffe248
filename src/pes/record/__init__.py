"""Looking at episodes: JSON records, top-down GIF/MP4 animations, trajectory plots, the 3-D
browser replay (``pes view``), ONNX export of trained policies (:mod:`pes.algos.cbc_tp_onnx`,
needs the ``onnx`` extra)."""

from typing import Any

from pes.record.episode import (
    EpisodeRecorder,
    check_record,
    load_record,
    record_episode,
    save_record,
)
from pes.record.render import render_frames, save_gif, save_mp4
from pes.record.viewer import build_page, write_page


def __getattr__(name: str) -> Any:
    # The plots import matplotlib (about a second), so only when they are asked for.
    if name in ("plot_trajectories", "save_plot"):
        from pes.record import plot

        return getattr(plot, name)
    raise AttributeError(f"module 'pes.record' has no attribute '{name}'")


__all__ = [
    "EpisodeRecorder",
    "build_page",
    "check_record",
    "load_record",
    "plot_trajectories",
    "record_episode",
    "render_frames",
    "save_gif",
    "save_mp4",
    "save_plot",
    "save_record",
    "write_page",
]
