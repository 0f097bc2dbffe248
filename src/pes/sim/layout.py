"""City layouts: axis-aligned rectangular buildings inside a walled arena.

A layout is a :class:`Layout`: the arena size and an array of boxes ``[xmin, ymin, xmax, ymax]``
(metres) with a height each (metres, for renderers). Three sources:

* :func:`grid_layout`: a grid of blocks with streets between them, from a few parameters
  (rows, cols, block size, street width, jitter, random removal, seed), the paper's "new urban
  map by replacing a few parameters" (§II-A);
* :func:`load_layout_file`: a YAML file with a ``buildings`` list, or an ASCII grid where ``#``
  is a building cell and ``.`` is free;
* ``empty``: no buildings.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from pes.errors import ConfigError
from pes.sim.config import EnvConfig
from pes.strict import read_text_file


@dataclass(frozen=True)
class Layout:
    """Arena of ``width`` x ``height`` metres with ``boxes`` (B, 4) = [xmin, ymin, xmax, ymax]
    and ``heights`` (B,) in metres."""

    width: float
    height: float
    boxes: np.ndarray
    heights: np.ndarray

    def __post_init__(self) -> None:
        boxes = np.asarray(self.boxes, dtype=np.float64)
        if boxes.size == 0:
            boxes = boxes.reshape(0, 4)
        if boxes.ndim != 2 or boxes.shape[1] != 4:
            raise ConfigError(
                f"buildings must be a list of [xmin, ymin, xmax, ymax], got shape {boxes.shape}"
            )
        if not np.all(np.isfinite(boxes)):
            raise ConfigError("every building coordinate must be a finite number (no NaN or inf)")
        if np.any(boxes[:, 2] <= boxes[:, 0]) or np.any(boxes[:, 3] <= boxes[:, 1]):
            raise ConfigError("every building needs xmin < xmax and ymin < ymax")
        object.__setattr__(self, "boxes", boxes)
        object.__setattr__(self, "heights", np.asarray(self.heights, dtype=np.float64))


def _heights(count: int, config: EnvConfig, rng: random.Random) -> np.ndarray:
    low, high = config.building_height_range
    return np.array([rng.uniform(low, high) for _ in range(count)])


def grid_layout(config: EnvConfig) -> Layout:
    """A ``grid_rows`` x ``grid_cols`` grid of ``block_size`` blocks, centred in the arena,
    separated by ``street_width`` streets, with optional jitter and removal (seeded)."""
    rng = random.Random(config.layout_seed)
    span_x = config.grid_cols * config.block_size + (config.grid_cols - 1) * config.street_width
    span_y = config.grid_rows * config.block_size + (config.grid_rows - 1) * config.street_width
    if span_x > config.arena_width or span_y > config.arena_height:
        raise ConfigError(
            f"the block grid ({span_x:g} m x {span_y:g} m) does not fit in the arena "
            f"({config.arena_width:g} m x {config.arena_height:g} m)"
        )
    x0 = (config.arena_width - span_x) / 2
    y0 = (config.arena_height - span_y) / 2
    removed = {tuple(pair) for pair in config.removed_blocks}
    boxes = []
    pitch = config.block_size + config.street_width
    for row in range(config.grid_rows):
        for col in range(config.grid_cols):
            # Draw every random number whether or not the block survives, so that one block's
            # removal does not reshuffle the others.
            drop = rng.random() < config.block_removal_prob
            shrink = [rng.uniform(0, config.block_jitter) for _ in range(4)]
            if (row, col) in removed or drop:
                continue
            xmin = x0 + col * pitch + shrink[0]
            xmax = x0 + col * pitch + config.block_size - shrink[1]
            ymin = y0 + row * pitch + shrink[2]
            ymax = y0 + row * pitch + config.block_size - shrink[3]
            if xmax - xmin > 0.5 and ymax - ymin > 0.5:
                boxes.append([xmin, ymin, xmax, ymax])
    return Layout(
        config.arena_width,
        config.arena_height,
        np.array(boxes).reshape(-1, 4),
        _heights(len(boxes), config, rng),
    )


def _ascii_boxes(lines: list[str], width: float, height: float) -> list[list[float]]:
    """Merge the ``#`` cells of an ASCII grid into rectangles (row runs, merged downwards).

    The first line is the top of the map (largest y), as the file reads on screen.
    """
    rows, cols = len(lines), max(len(line) for line in lines)
    cell_w, cell_h = width / cols, height / rows
    grid = [[c == "#" for c in line.ljust(cols, ".")] for line in lines]
    for line in lines:
        bad = set(line) - {"#", "."}
        if bad:
            raise ConfigError(f"ASCII layout may hold only '#' and '.', found {sorted(bad)}")
    open_runs: dict[tuple[int, int], list[int]] = {}  # (c0, c1) -> [first_row, last_row]
    rects: list[tuple[int, int, int, int]] = []
    for r in range(rows):
        runs, c = [], 0
        while c < cols:
            if grid[r][c]:
                c0 = c
                while c < cols and grid[r][c]:
                    c += 1
                runs.append((c0, c))
            else:
                c += 1
        next_open = {}
        for run in runs:
            if run in open_runs:
                open_runs[run][1] = r
                next_open[run] = open_runs.pop(run)
            else:
                next_open[run] = [r, r]
        rects += [(c0, c1, r0, r1) for (c0, c1), (r0, r1) in open_runs.items()]
        open_runs = next_open
    rects += [(c0, c1, r0, r1) for (c0, c1), (r0, r1) in open_runs.items()]
    return [
        [c0 * cell_w, height - (r1 + 1) * cell_h, c1 * cell_w, height - r0 * cell_h]
        for c0, c1, r0, r1 in rects
    ]


def _numbers(value: object, field: str, meaning: str) -> list[float]:
    """``value`` as a list of finite numbers, or a :class:`ConfigError` naming ``field``."""
    if not isinstance(value, (list, tuple)):
        raise ConfigError(f"{field} must be a list of numbers ({meaning}), got {value!r}")
    for item in value:
        if isinstance(item, bool) or not isinstance(item, (int, float)):
            raise ConfigError(f"{field} must be a list of numbers ({meaning}), got {item!r}")
        if not math.isfinite(item):
            raise ConfigError(f"{field} must hold finite numbers ({meaning}), got {item!r}")
    return [float(v) for v in value]


def load_layout_file(path: str | Path, config: EnvConfig) -> Layout:
    """Read a layout file.

    YAML (``.yaml``/``.yml``)::

        arena: [100, 100]            # optional; else the config's arena size
        buildings:                   # [xmin, ymin, xmax, ymax] in metres
          - [20, 20, 38, 38]
        heights: [30]                # optional, metres

    ASCII (any other suffix): one character per cell, ``#`` building, ``.`` free; the grid is
    stretched over the arena, the first line at the top (largest y).
    """
    path = Path(path)
    rng = random.Random(config.layout_seed)
    text = read_text_file(path, "layout file")
    width, height = config.arena_width, config.arena_height
    if path.suffix in (".yaml", ".yml"):
        try:
            data = yaml.safe_load(text) or {}
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
        if not isinstance(data, dict) or "buildings" not in data:
            raise ConfigError(f"{path}: a layout file needs a 'buildings' list")
        unknown = set(data) - {"arena", "buildings", "heights"}
        if unknown:
            raise ConfigError(f"{path}: unknown layout keys {sorted(map(str, unknown))}")
        if "arena" in data:
            arena = _numbers(data["arena"], f"{path}: arena", "[width, height] in metres")
            if len(arena) != 2:
                raise ConfigError(f"{path}: arena must be [width, height] in metres, got {arena}")
            if arena != [width, height]:
                raise ConfigError(
                    f"{path}: arena {data['arena']} differs from the config's arena "
                    f"[{width:g}, {height:g}]; set arena_width/arena_height to match"
                )
        buildings = data["buildings"]
        if buildings is None:
            buildings = []
        if not isinstance(buildings, list):
            raise ConfigError(
                f"{path}: buildings must be a list of [xmin, ymin, xmax, ymax], got {buildings!r}"
            )
        rows = [
            _numbers(row, f"{path}: buildings[{i}]", "[xmin, ymin, xmax, ymax] in metres")
            for i, row in enumerate(buildings)
        ]
        for i, row in enumerate(rows):
            if len(row) != 4:
                raise ConfigError(
                    f"{path}: buildings[{i}] must be [xmin, ymin, xmax, ymax] (4 numbers), "
                    f"got {len(row)}"
                )
        boxes = np.array(rows, dtype=np.float64).reshape(-1, 4)
        if "heights" in data and data["heights"] is not None:
            heights = _numbers(data["heights"], f"{path}: heights", "building heights in metres")
            if not all(h > 0 for h in heights):
                raise ConfigError(f"{path}: heights must be positive numbers, got {heights}")
        else:
            heights = _heights(len(boxes), config, rng)
        if len(heights) != len(boxes):
            raise ConfigError(f"{path}: {len(heights)} heights for {len(boxes)} buildings")
    else:
        lines = [line.rstrip() for line in text.splitlines() if line.strip()]
        if not lines:
            raise ConfigError(f"{path}: the ASCII layout is empty")
        boxes = np.array(_ascii_boxes(lines, width, height)).reshape(-1, 4)
        heights = _heights(len(boxes), config, rng)
    if np.any(boxes[:, :2] < 0) or np.any(boxes[:, 2] > width) or np.any(boxes[:, 3] > height):
        raise ConfigError(f"{path}: a building lies outside the {width:g} x {height:g} m arena")
    return Layout(width, height, boxes, np.asarray(heights, dtype=np.float64))


def make_layout(config: EnvConfig) -> Layout:
    """The layout named by ``config.layout``."""
    if config.layout == "grid":
        return grid_layout(config)
    if config.layout == "empty":
        return Layout(config.arena_width, config.arena_height, np.zeros((0, 4)), np.zeros(0))
    return load_layout_file(config.layout, config)
