"""Looking at episodes: JSON records, top-down GIF/MP4 animations, trajectory plots, ONNX
export of trained policies (:mod:`pes.record.onnx_export`, needs the ``onnx`` extra)."""

from pes.record.episode import EpisodeRecorder, load_record, save_record
from pes.record.plot import plot_trajectories, save_plot
from pes.record.render import render_frames, save_gif, save_mp4

__all__ = [
    "EpisodeRecorder",
    "load_record",
    "plot_trajectories",
    "render_frames",
    "save_gif",
    "save_mp4",
    "save_plot",
    "save_record",
]
