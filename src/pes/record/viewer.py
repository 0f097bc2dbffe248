"""The 3-D replay of an episode record as one self-contained HTML page (``pes view``).

The page inlines everything it needs — three.js (bundled from npm by
``scripts/build_viewer_assets.py``, MIT licence in ``viewer/three.LICENSE``), the viewer script
``viewer/viewer.js``, its style sheet and the episode itself — so it works opened from disk,
offline. Python prepares the scene (:func:`scene_data`): it checks the record and fills in what
an older or hand-made record may lack, so the script draws one shape of data.

Defaults for missing fields (see docs/viewer.md): building heights are the middle of the
record's ``config.building_height_range`` (else :data:`DEFAULT_BUILDING_HEIGHT`); flight
altitudes are ``config.altitude + k * config.altitude_step`` for vehicle k (pursuers then the
evader; else 10 m + k m); the capture radius and body radius come from ``config``.
"""

from __future__ import annotations

import json
import re
from importlib import resources
from pathlib import Path
from typing import Any

from pes.errors import CheckpointError, ConfigError
from pes.paths import prepare_output
from pes.record.episode import check_record, load_record

DEFAULT_BUILDING_HEIGHT = 30.0
"""Building height (m) when the record has neither heights nor a height range."""

ASSETS = ("viewer.html", "viewer.css", "viewer.js", "three.min.js", "three.LICENSE")
"""The files in ``viewer/`` that a page is made of (package data, see pyproject.toml)."""
_MARKER = re.compile(r"/\*PES:(\w+)\*/")


def _asset(name: str) -> str:
    return (resources.files("pes.record") / "viewer" / name).read_text(encoding="utf-8")


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CheckpointError(f"episode record: {what} is not a number ({value!r})")
    return float(value)


def _first_step(frames: list[dict[str, Any]], key: str, vehicle: int, flag: bool) -> int | None:
    """The first frame whose ``key`` of ``vehicle`` equals ``flag``, or None."""
    for k, frame in enumerate(frames):
        if bool(frame[key][vehicle]) == flag:
            return k
    return None


def scene_data(record: dict[str, Any], title: str = "episode") -> dict[str, Any]:
    """What the page draws, from an episode record (docs/interfaces.md, :mod:`pes.record.episode`).

    Returns a dict with ``title``, ``arena`` [width, height] (m), ``buildings`` (each
    ``[xmin, ymin, xmax, ymax, height]``, m), ``heights_from`` (``"record"``, ``"config"`` or
    ``"default"``), ``altitudes`` (one per vehicle, m), ``agents``, ``num_pursuers``, ``dt``
    (s), ``capture_radius``, ``capture_count``, ``body_radius`` (m), ``frames`` (``t``, ``pos``
    (N+1, 2) m, ``vel`` (N+1, 2) m/s, ``alive`` (N,), ``pred`` (K, 2) m or absent),
    ``down_step`` and ``crash_step`` (per pursuer: the first frame where it is disabled / has
    crashed, or None), ``outcome`` and ``scenario`` (a few config values for the caption).
    Raises :class:`CheckpointError` for a record whose parts are missing or do not fit together.
    """
    check_record(record)
    try:
        return _scene_data(record, title)
    except (TypeError, KeyError, ValueError, IndexError, AttributeError) as exc:
        raise CheckpointError(f"not a well-formed episode record ({exc!r})") from None


def _scene_data(record: dict[str, Any], title: str) -> dict[str, Any]:
    """:func:`scene_data` without the catch-all for malformed records."""
    config = record.get("config") or {}
    if not isinstance(config, dict):
        raise CheckpointError("episode record: 'config' is not a mapping")
    agents = record["agents"]
    if not isinstance(agents, list) or not all(isinstance(a, dict) for a in agents):
        raise CheckpointError("episode record: 'agents' is not a list of {id, role}")
    n = sum(1 for a in agents if a.get("role") == "pursuer")
    if n == 0 or len(agents) != n + 1:
        raise CheckpointError(
            f"episode record: expected pursuers and one evader in 'agents', got {len(agents)}"
        )
    arena = [_number(v, "arena") for v in record["arena"]]
    if len(arena) != 2 or min(arena) <= 0:
        raise CheckpointError(f"episode record: arena {record['arena']} is not [width, height]")

    boxes = record["buildings"]
    heights = record.get("building_heights")
    heights_from = "record"
    if not isinstance(heights, list) or len(heights) != len(boxes):
        span = config.get("building_height_range")
        if isinstance(span, list) and len(span) == 2:
            heights = [(_number(span[0], "height") + _number(span[1], "height")) / 2] * len(boxes)
            heights_from = "config"
        else:
            heights = [DEFAULT_BUILDING_HEIGHT] * len(boxes)
            heights_from = "default"
    buildings = []
    for box, height in zip(boxes, heights):
        if not isinstance(box, list) or len(box) != 4:
            raise CheckpointError(
                f"episode record: building {box!r} is not [xmin, ymin, xmax, ymax]"
            )
        buildings.append([_number(v, "building") for v in box] + [_number(height, "height")])

    altitudes = record.get("altitudes")
    if not isinstance(altitudes, list) or len(altitudes) != n + 1:
        base = float(config.get("altitude", 10.0))
        step = float(config.get("altitude_step", 1.0))
        altitudes = [base + k * step for k in range(n + 1)]

    frames = []
    for k, frame in enumerate(record["frames"]):
        try:
            pos, alive = frame["pos"], frame["alive"]
            vel = frame.get("vel") or [[0.0, 0.0]] * (n + 1)
            crashed = frame.get("crashed") or [False] * n
        except (TypeError, KeyError) as exc:
            raise CheckpointError(f"episode record: frame {k} lacks {exc}") from None
        if len(pos) != n + 1 or len(vel) != n + 1 or len(alive) != n or len(crashed) != n:
            raise CheckpointError(
                f"episode record: frame {k} does not hold {n} pursuers and an evader"
            )
        item = {"t": float(frame.get("t", k * record["dt"])), "pos": pos, "vel": vel}
        item["alive"] = [bool(a) for a in alive]
        item["crashed"] = [bool(c) for c in crashed]
        if frame.get("pred"):
            item["pred"] = frame["pred"]
        frames.append(item)

    outcome = record["outcome"]
    if not isinstance(outcome, dict) or not {"success", "steps", "crashes"} <= set(outcome):
        raise CheckpointError("episode record: 'outcome' lacks success, steps or crashes")
    return {
        "title": title,
        "arena": arena,
        "buildings": buildings,
        "heights_from": heights_from,
        "altitudes": [float(a) for a in altitudes],
        "agents": agents,
        "num_pursuers": n,
        "dt": _number(record["dt"], "dt"),
        "capture_radius": float(record.get("capture_radius", config.get("capture_radius", 2.0))),
        "capture_count": int(config.get("capture_count", min(3, n))),
        "body_radius": float(record.get("body_radius", config.get("body_radius", 0.3))),
        "frames": frames,
        "down_step": [_first_step(frames, "alive", v, False) for v in range(n)],
        "crash_step": [_first_step(frames, "crashed", v, True) for v in range(n)],
        "outcome": outcome,
        "scenario": {
            key: config[key]
            for key in ("evader_policy", "disturbance", "damaged", "crash_mode", "layout")
            if key in config
        },
    }


def _inline_script(code: str) -> str:
    """JavaScript ``code`` made safe inside ``<script>``: ``</`` (as in ``</script>``) becomes
    ``<\\/``, the same string or regular expression to JavaScript."""
    if "<!--" in code:  # would switch the HTML parser's script state; never in our assets
        raise ValueError("'<!--' in a viewer asset")
    return code.replace("</", "<\\/")


def build_page(record: dict[str, Any], title: str = "episode") -> str:
    """The self-contained HTML page replaying ``record`` (no network access needed)."""
    data = json.dumps(scene_data(record, title), separators=(",", ":"), allow_nan=False)
    data = data.replace("<", "\\u003c")  # "<" only occurs inside JSON strings
    parts = {
        "TITLE": title.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;"),
        "CSS": _asset("viewer.css").replace("</", "<\\/"),
        "DATA": data,
        "THREE": _inline_script(_asset("three.min.js")),
        "THREE_LICENSE": _asset("three.LICENSE").replace("--", "- -"),
        "VIEWER": _inline_script(_asset("viewer.js")),
    }
    # one pass over the template: inserted text is never searched for markers again
    return _MARKER.sub(lambda m: parts[m.group(1)], _asset("viewer.html"))


def write_page(record_path: str | Path, out: str | Path | None = None) -> tuple[Path, dict]:
    """Read the record at ``record_path`` and write its page to ``out`` (default: the record's
    path with ``.html``). Returns the page's path and the record."""
    record_path = Path(record_path)
    record = load_record(record_path)
    out = Path(out) if out is not None else record_path.with_suffix(".html")
    if out.suffix.lower() not in (".html", ".htm"):
        raise ConfigError(f"--out must end in .html, got '{out.name}'")
    prepare_output(out)
    try:
        page = build_page(record, title=record_path.name)
    except CheckpointError as exc:
        raise CheckpointError(f"{record_path}: {exc}") from None
    out.write_text(page, encoding="utf-8")
    return out, record
