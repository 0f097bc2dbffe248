"""Looking at episodes: JSON records, top-down GIFs, the 3-D browser replay."""

from pes.record.episode import EpisodeRecorder, load_record, save_record
from pes.record.render import render_frames, save_gif
from pes.record.viewer import build_page, write_page

__all__ = [
    "EpisodeRecorder",
    "build_page",
    "load_record",
    "render_frames",
    "save_gif",
    "save_record",
    "write_page",
]
