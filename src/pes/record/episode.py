"""Episode records (docs/interfaces.md): one episode of one environment as versioned JSON.

A record holds ``version``, ``config`` (the full ``EnvConfig``), ``arena`` [width, height],
``buildings`` ([xmin, ymin, xmax, ymax] each, metres), ``building_heights``, ``altitudes``
(flight altitude of each vehicle), ``dt``, ``agents`` (``id`` and ``role``), ``frames`` and
``outcome``. Frame 0 is the start; frame k is the state after k control steps, with ``t``
(seconds), ``pos`` and ``vel`` ([[x, y], ...], pursuers then the evader), ``alive`` and
``crashed`` (one per pursuer), and ``pred`` (predicted evader positions [[x, y], ...]) when the
policy makes predictions. ``outcome`` holds ``success``, ``steps`` and ``crashes``.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

import torch

from pes.errors import CheckpointError
from pes.paths import prepare_output
from pes.sim.config import EnvConfig
from pes.sim.env import PursuitEvasionEnv, make_env

RECORD_VERSION = 1
REQUIRED_KEYS = ("version", "config", "arena", "buildings", "dt", "agents", "frames", "outcome")


def _round(values: Any, digits: int = 3) -> Any:
    if isinstance(values, list):
        return [_round(v, digits) for v in values]
    return round(float(values), digits)


class EpisodeRecorder:
    """Records environment ``index`` of ``env`` from its current state until its episode ends.

    Call :meth:`start` after ``reset`` (or at any step) and :meth:`add` after every
    ``env.step`` with its ``info``; :attr:`finished` turns true at the end of the episode and
    later steps are ignored. ``pred`` (K, 2) metres, when given to :meth:`add`, is stored with
    the frame.
    """

    def __init__(self, env: PursuitEvasionEnv, index: int = 0) -> None:
        self.env, self.index = env, index
        self.frames: list[dict[str, Any]] = []
        self.outcome: dict[str, Any] | None = None
        self.steps = 0

    @property
    def finished(self) -> bool:
        return self.outcome is not None

    def start(self, pred: torch.Tensor | None = None) -> None:
        i = self.index
        n = self.env.num_pursuers
        self.frames = []
        self.outcome = None
        self.steps = 0
        self._append(
            self.env.positions[i],
            self.env.velocities[i],
            self.env.alive[i],
            torch.zeros(n, dtype=torch.bool),
            pred,
        )

    def add(self, info: dict[str, torch.Tensor], pred: torch.Tensor | None = None) -> None:
        if self.finished:
            return
        i = self.index
        self.steps += 1
        self._append(
            info["positions"][i], info["velocities"][i], info["alive"][i], info["crashed"][i], pred
        )
        if bool(info["success"][i]) or self._ended(info):
            self.outcome = {
                "success": bool(info["success"][i]),
                "steps": int(info["steps"][i]),
                "crashes": int(info["crashes"][i]),
            }

    def _ended(self, info: dict[str, torch.Tensor]) -> bool:
        cfg = self.env.config
        i = self.index
        return (
            int(info["steps"][i]) >= cfg.max_steps
            or int(info["alive"][i].sum()) < cfg.capture_count
        )

    def _append(self, pos, vel, alive, crashed, pred) -> None:
        frame = {
            "t": round(self.steps * self.env.config.dt, 4),
            "pos": _round(pos.tolist()),
            "vel": _round(vel.tolist()),
            "alive": [bool(a) for a in alive.tolist()],
            "crashed": [bool(c) for c in crashed.tolist()],
        }
        if pred is not None:
            frame["pred"] = _round(pred.reshape(-1, 2).tolist())
        self.frames.append(frame)

    def record(self) -> dict[str, Any]:
        """The episode record (see the module docstring)."""
        if not self.frames:
            raise CheckpointError("nothing recorded: call start() first")
        return make_record(self.env.config, self.env, self.frames, self.outcome)


def make_record(
    config: EnvConfig,
    env: PursuitEvasionEnv,
    frames: list[dict[str, Any]],
    outcome: dict[str, Any] | None,
) -> dict[str, Any]:
    """Assemble a record dict from frames recorded in ``env``."""
    n = config.num_pursuers
    layout = env.layout
    last = frames[-1]
    if outcome is None:  # stopped before the episode ended
        outcome = {
            "success": False,
            "steps": len(frames) - 1,
            "crashes": sum(sum(f["crashed"]) for f in frames),
        }
    return {
        "version": RECORD_VERSION,
        "config": asdict(config),
        "arena": [layout.width, layout.height],
        "buildings": _round(layout.boxes.tolist()),
        "building_heights": _round(layout.heights.tolist()),
        "altitudes": [config.altitude + k * config.altitude_step for k in range(n + 1)],
        "dt": config.dt,
        "body_radius": config.body_radius,
        "capture_radius": config.capture_radius,
        "agents": [{"id": f"pursuer_{k}", "role": "pursuer"} for k in range(n)]
        + [{"id": "evader", "role": "evader"}],
        "frames": frames,
        "outcome": dict(outcome, final_alive=last["alive"]),
    }


def record_episode(policy, config: EnvConfig, seed: int = 0, device: str = "cpu") -> dict:
    """Play one episode of the pursuer ``policy`` (a :class:`pes.policies.Policy`) in the
    scenario ``config`` from the environment seed ``seed`` and return its record. Policies that
    predict the evader's path (``last_prediction``, arena units) get it recorded in metres."""
    env = make_env(config, num_envs=1, device=device, seed=seed, wait_kernels=True)
    obs, info = env.reset(seed=seed)
    policy.reset(None)
    recorder = EpisodeRecorder(env)
    arena = torch.tensor([config.arena_width, config.arena_height], device=env.device)

    def act():  # the actions, and the evader positions the policy predicts (m), if any
        actions = policy(obs, info)
        pred = getattr(policy, "last_prediction", None)
        return actions, None if pred is None else pred[0] * arena

    with torch.no_grad():
        actions, pred = act()
        recorder.start(pred)
        while not recorder.finished:
            obs, _, terminated, truncated, info = env.step(actions)
            if bool(terminated[0] | truncated[0]):  # obs is already the next episode's
                recorder.add(info)
            else:
                actions, pred = act()
                recorder.add(info, pred)
    return recorder.record()


def save_record(record: dict[str, Any], path: str | Path) -> Path:
    """Write ``record`` as JSON to ``path`` (parents created)."""
    path = prepare_output(path)
    path.write_text(json.dumps(record, separators=(",", ":")))
    return path


def load_record(path: str | Path) -> dict[str, Any]:
    """Read and check an episode record (:func:`check_record`); a one-line
    :class:`CheckpointError` for a missing, unreadable or malformed file."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"episode record not found: {path}")
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        reason = " ".join(str(exc).split())[:120]
        raise CheckpointError(f"{path}: not a JSON episode record ({reason})") from None
    except OSError as exc:
        raise CheckpointError(f"cannot read episode record {path}: {exc.strerror}") from None
    try:
        return check_record(record)
    except CheckpointError as exc:
        raise CheckpointError(f"{path}: {exc}") from None


# --- the one validator of records (``pes view``, ``pes render --record``, plots) ---------------


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _bad(where: str, what: str, value: Any) -> CheckpointError:
    return CheckpointError(f"episode record: {where} must be {what}, got {_show(value)}")


def _finite(value: Any, where: str, positive: bool = False) -> float:
    what = "a positive number" if positive else "a finite number"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _bad(where, what, value)
    if not math.isfinite(value) or (positive and value <= 0):
        raise _bad(where, what, value)
    return float(value)


def _points(value: Any, where: str, count: int | None, arena: list[float] | None = None) -> None:
    """A list of ``count`` (any number if None) [x, y] pairs of finite numbers; with ``arena``
    [width, height], no farther outside it than its own size (so that a picture can hold it)."""
    shape = f"a list of {count} [x, y] pairs" if count is not None else "a list of [x, y] pairs"
    if not isinstance(value, list) or (count is not None and len(value) != count):
        raise _bad(where, shape, value)
    for i, point in enumerate(value):
        if not isinstance(point, list) or len(point) != 2:
            raise _bad(f"{where}[{i}]", "[x, y]", point)
        for v in point:
            _finite(v, f"{where}[{i}]")
        if arena is not None and not all(-size <= v <= 2 * size for v, size in zip(point, arena)):
            raise _bad(f"{where}[{i}]", "inside the arena (or near it)", point)


def _flags(value: Any, where: str, count: int) -> None:
    if not isinstance(value, list) or len(value) != count:
        raise _bad(where, f"a list of {count} true/false values", value)
    for v in value:
        if not isinstance(v, bool) and v not in (0, 1):
            raise _bad(where, f"a list of {count} true/false values", value)


def check_record(record: Any) -> dict[str, Any]:
    """Check that ``record`` is an episode record of this version (see the module docstring)
    whose parts fit together: numbers finite, ``pos`` (and ``vel``, ``alive``, ``crashed``,
    ``pred`` where present) of the right lengths and types. Returns ``record``; raises a
    one-line :class:`CheckpointError` naming the bad part. Optional parts (``vel``,
    ``crashed``, ``t``, ``pred``, ``building_heights``, ``altitudes``, the radii) may be absent,
    but not wrong."""
    if not isinstance(record, dict):
        raise CheckpointError("not a JSON episode record (expected an object)")
    missing = [k for k in REQUIRED_KEYS if k not in record]
    if missing:
        raise CheckpointError(f"not an episode record (missing {', '.join(missing)})")
    if record["version"] != RECORD_VERSION:
        raise CheckpointError(
            f"episode record version {_show(record['version'])}, this PES reads version "
            f"{RECORD_VERSION}"
        )
    config = record["config"]
    if not isinstance(config, dict):
        raise _bad("config", "a mapping", config)
    # The few config values that the viewer and the renderer read, where present.
    for key in ("altitude", "altitude_step"):
        if config.get(key) is not None:
            _finite(config[key], f"config.{key}")
    for key in ("capture_radius", "body_radius"):
        if config.get(key) is not None:
            _finite(config[key], f"config.{key}", positive=True)
    if config.get("capture_count") is not None:
        count = config["capture_count"]
        if isinstance(count, bool) or not isinstance(count, int) or count < 1:
            raise _bad("config.capture_count", "a whole number >= 1", count)
    if config.get("building_height_range") is not None:
        span = config["building_height_range"]
        if not isinstance(span, list) or len(span) != 2:
            raise _bad("config.building_height_range", "[low, high]", span)
        for v in span:
            _finite(v, "config.building_height_range", positive=True)
    agents = record["agents"]
    if not isinstance(agents, list) or not all(
        isinstance(a, dict) and isinstance(a.get("id"), str) for a in agents
    ):
        raise _bad("agents", "a list of {id, role}", agents)
    roles = [a.get("role") for a in agents]
    n = len(agents) - 1
    if n < 1 or roles != ["pursuer"] * n + ["evader"]:
        raise _bad("agents", "pursuers then one evader", roles)
    arena = record["arena"]
    if not isinstance(arena, list) or len(arena) != 2:
        raise _bad("arena", "[width, height]", arena)
    arena = [_finite(v, "arena", positive=True) for v in arena]
    buildings = record["buildings"]
    if not isinstance(buildings, list):
        raise _bad("buildings", "a list of [xmin, ymin, xmax, ymax]", buildings)
    for i, box in enumerate(buildings):
        if not isinstance(box, list) or len(box) != 4:
            raise _bad(f"buildings[{i}]", "[xmin, ymin, xmax, ymax]", box)
        xmin, ymin, xmax, ymax = (_finite(v, f"buildings[{i}]") for v in box)
        if not (xmin < xmax and ymin < ymax):
            raise _bad(f"buildings[{i}]", "[xmin, ymin, xmax, ymax] with min < max", box)
    if "building_heights" in record:
        heights = record["building_heights"]
        if not isinstance(heights, list) or len(heights) != len(buildings):
            raise _bad("building_heights", f"a list of {len(buildings)} heights", heights)
        for v in heights:
            _finite(v, "building_heights", positive=True)
    if "altitudes" in record:
        altitudes = record["altitudes"]
        if not isinstance(altitudes, list) or len(altitudes) != n + 1:
            raise _bad("altitudes", f"a list of {n + 1} altitudes", altitudes)
        for v in altitudes:
            _finite(v, "altitudes")
    _finite(record["dt"], "dt", positive=True)
    for key in ("body_radius", "capture_radius"):
        if key in record:
            _finite(record[key], key, positive=True)
    frames = record["frames"]
    if not isinstance(frames, list):
        raise _bad("frames", "a list of frames", frames)
    if not frames:
        raise CheckpointError("the episode record has no frames")
    for k, frame in enumerate(frames):
        where = f"frame {k}"
        if not isinstance(frame, dict):
            raise _bad(where, "an object with pos and alive", frame)
        for key in ("pos", "alive"):
            if key not in frame:
                raise CheckpointError(f"episode record: {where} lacks '{key}'")
        _points(frame["pos"], f"{where}: pos", n + 1, arena)
        if frame.get("vel") is not None:
            _points(frame["vel"], f"{where}: vel", n + 1)
        _flags(frame["alive"], f"{where}: alive", n)
        if frame.get("crashed") is not None:
            _flags(frame["crashed"], f"{where}: crashed", n)
        if "t" in frame:
            _finite(frame["t"], f"{where}: t")
        if frame.get("pred") is not None:
            _points(frame["pred"], f"{where}: pred", None, arena)
    outcome = record["outcome"]
    if not isinstance(outcome, dict) or not {"success", "steps", "crashes"} <= set(outcome):
        raise _bad("outcome", "an object with success, steps and crashes", outcome)
    if not isinstance(outcome["success"], bool):
        raise _bad("outcome.success", "true or false", outcome["success"])
    for key in ("steps", "crashes"):
        value = outcome[key]
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise _bad(f"outcome.{key}", "a whole number >= 0", value)
    return record
