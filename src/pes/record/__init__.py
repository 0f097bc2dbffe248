"""Looking at episodes: JSON records, top-down GIFs."""

from pes.record.episode import EpisodeRecorder, load_record, save_record
from pes.record.render import render_frames, save_gif

__all__ = ["EpisodeRecorder", "load_record", "render_frames", "save_gif", "save_record"]
