"""Top-down pictures of an episode record: buildings, vehicles, trails, the capture radius.

Frames are drawn with Pillow straight from a record (see :mod:`pes.record.episode`), so that a
GIF or an MP4 (H.264, through imageio and the ffmpeg that the ``imageio-ffmpeg`` wheel bundles)
can be made from a run or from a saved JSON file alike.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from PIL import Image, ImageDraw, ImageFont

from pes.errors import PESError
from pes.paths import prepare_output

BACKGROUND = (236, 239, 242)
BORDER = (52, 58, 64)
BUILDING = (108, 117, 125)
BUILDING_EDGE = (73, 80, 87)
PURSUER = (31, 119, 180)
PURSUER_TRAIL = (120, 170, 215)
DEAD = (150, 150, 150)
EVADER = (214, 39, 40)
EVADER_TRAIL = (240, 140, 140)
CAPTURE = (214, 39, 40)
PREDICTION = (255, 127, 14)
TEXT = (33, 37, 41)


class _View:
    """Maps arena metres to pixels (y up in the arena, down in the image)."""

    def __init__(self, arena: list[float], size: int, header: int) -> None:
        self.scale = size / max(arena)
        # at least 2 pixels each way, however narrow the arena (the border needs them)
        self.width = max(2, int(round(arena[0] * self.scale)))
        self.height = max(2, int(round(arena[1] * self.scale)))
        self.header = header

    def point(self, x: float, y: float) -> tuple[float, float]:
        return x * self.scale, self.header + self.height - y * self.scale


def _circle(draw: ImageDraw.ImageDraw, centre: tuple[float, float], radius: float, **kw) -> None:
    x, y = centre
    draw.ellipse([x - radius, y - radius, x + radius, y + radius], **kw)


def _base(record: dict[str, Any], view: _View) -> Image.Image:
    image = Image.new("RGB", (view.width, view.height + view.header), (255, 255, 255))
    draw = ImageDraw.Draw(image)
    draw.rectangle(
        [0, view.header, view.width - 1, view.header + view.height - 1],
        fill=BACKGROUND,
        outline=BORDER,
        width=2,
    )
    for xmin, ymin, xmax, ymax in record["buildings"]:
        x0, y1 = view.point(xmin, ymin)
        x1, y0 = view.point(xmax, ymax)
        draw.rectangle([x0, y0, x1, y1], fill=BUILDING, outline=BUILDING_EDGE, width=1)
    return image


def _legend(draw: ImageDraw.ImageDraw, font, predictions: bool) -> None:
    """The header's second line: what each colour means (the predicted evader positions only
    where the policy made them)."""
    items = [(PURSUER, "pursuer"), (EVADER, "evader, its capture radius")]
    if predictions:
        items.append((PREDICTION, "TP Net's predicted evader positions"))
    items.append((DEAD, "x: disabled pursuer"))
    x, y = 8.0, 26.0
    for colour, label in items:
        _circle(draw, (x + 4, y + 5), 4, fill=colour + (255,))
        draw.text((x + 12, y), label, fill=TEXT, font=font)
        x += 12 + draw.textlength(label, font=font) + 14


def render_frames(
    record: dict[str, Any], size: int = 600, trail: int = 30, every: int = 1
) -> Iterator[Image.Image]:
    """Yield one RGB image per ``every`` frames of ``record`` (and always the last frame).

    ``size`` is the pixel size of the arena's longer side; ``trail`` the number of past frames
    drawn as each vehicle's trail.
    """
    frames = record["frames"]
    if not frames:
        raise PESError("the episode record has no frames")
    n = sum(1 for a in record["agents"] if a["role"] == "pursuer")
    header = 40
    view = _View(record["arena"], size, header)
    base = _base(record, view)
    font = ImageFont.load_default()
    _legend(ImageDraw.Draw(base, "RGBA"), font, any(f.get("pred") for f in frames))
    vehicle_px = max(4.0, record.get("body_radius", 0.3) * view.scale * 2)
    capture_px = record.get("capture_radius", 2.0) * view.scale
    indices = list(range(0, len(frames), every))
    if indices[-1] != len(frames) - 1:
        indices.append(len(frames) - 1)
    for k in indices:
        frame = frames[k]
        image = base.copy()
        draw = ImageDraw.Draw(image, "RGBA")
        first = max(0, k - trail)
        for v in range(n + 1):
            path = [view.point(*frames[j]["pos"][v]) for j in range(first, k + 1)]
            if len(path) > 1:
                colour = EVADER_TRAIL if v == n else PURSUER_TRAIL
                draw.line(path, fill=colour + (200,), width=2)
        for pred in frame.get("pred", []):
            _circle(draw, view.point(*pred), 3, fill=PREDICTION + (230,))
        ex, ey = view.point(*frame["pos"][n])
        _circle(draw, (ex, ey), capture_px, outline=CAPTURE + (160,), width=1)
        for v in range(n):
            centre = view.point(*frame["pos"][v])
            if frame["alive"][v]:
                _circle(draw, centre, vehicle_px, fill=PURSUER, outline=(255, 255, 255))
            else:
                x, y = centre
                r = vehicle_px
                draw.line([x - r, y - r, x + r, y + r], fill=DEAD, width=3)
                draw.line([x - r, y + r, x + r, y - r], fill=DEAD, width=3)
        _circle(draw, (ex, ey), vehicle_px, fill=EVADER, outline=(255, 255, 255))

        evader = frame["pos"][n]
        gaps = [math.dist(frame["pos"][v], evader) for v in range(n) if frame["alive"][v]]
        near = sum(g < record.get("capture_radius", 2.0) for g in gaps)
        text = f"step {k:3d}   t = {frame['t']:5.1f} s   nearest {min(gaps, default=0):5.1f} m"
        text += f"   within capture radius: {near}"
        outcome = record.get("outcome") or {}
        if k == len(frames) - 1 and "steps" in outcome:
            text += "   CAPTURED" if outcome["success"] else "   escaped"
        draw.text((6, 8), text, fill=TEXT, font=font)
        yield image


def save_gif(
    record: dict[str, Any], path: str | Path, fps: int = 20, every: int = 1, size: int = 600
) -> Path:
    """Write the episode as an animated GIF at ``fps`` frames per second."""
    path = prepare_output(path)
    images = list(render_frames(record, size=size, every=every))
    palette = [im.convert("P", palette=Image.Palette.ADAPTIVE, colors=64) for im in images]
    durations = [int(1000 / fps)] * len(palette)
    durations[-1] = 2000  # hold the outcome
    palette[0].save(
        path,
        save_all=True,
        append_images=palette[1:],
        duration=durations,
        loop=0,
        optimize=False,
        disposal=1,
    )
    return path


def save_mp4(
    record: dict[str, Any],
    path: str | Path,
    fps: int = 20,
    every: int = 1,
    size: int = 600,
    hold: float = 1.0,
) -> Path:
    """Write the episode as an H.264 MP4 (yuv420p, playable in browsers) at ``fps`` frames per
    second: the frames of :func:`render_frames`, then the last one repeated for ``hold``
    seconds. The picture is padded with white to even width and height, as H.264 needs."""
    import imageio.v2 as imageio
    import numpy as np

    path = prepare_output(path)
    writer = imageio.get_writer(
        path,
        format="FFMPEG",
        mode="I",
        fps=fps,
        codec="libx264",
        pixelformat="yuv420p",
        macro_block_size=1,
        quality=8,
        ffmpeg_log_level="error",
    )
    try:
        frame = None
        for image in render_frames(record, size=size, every=every):
            frame = np.asarray(image)
            h, w = frame.shape[:2]
            if h % 2 or w % 2:
                frame = np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), constant_values=255)
            writer.append_data(frame)
        for _ in range(int(round(hold * fps))):
            writer.append_data(frame)
    finally:
        writer.close()
    return path
