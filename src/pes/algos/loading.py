"""Turning a policy file or checkpoint back into something that acts."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from torch import nn

from pes.algos.evader_ddpg import DeepSetActor
from pes.algos.registry import ALGOS, PURSUER_ALGOS
from pes.errors import CheckpointError, ConfigError
from pes.learn.checkpoint import (
    CHECKPOINT_FORMAT,
    POLICY_FORMAT,
    load_file,
    load_modules,
    resolve_policy_path,
)
from pes.learn.config import TrainConfig, train_config_from_dict
from pes.models import SHIPPED
from pes.sim.config import EnvConfig


def resolve(spec: str | Path) -> Path:
    """The file behind a policy spec: a shipped model's name, a run folder, or a path; an
    algorithm's name with no shipped model is a clear error."""
    if str(spec) in ALGOS and str(spec) not in SHIPPED and not Path(spec).exists():
        raise CheckpointError(
            f"no '{spec}' model is shipped; train one with `pes train --algo {spec}` and pass "
            "its run folder or policy.pt"
        )
    return resolve_policy_path(spec)


def recorded_config(obj: dict[str, Any], path: Path) -> TrainConfig:
    """The training configuration recorded in a policy file or checkpoint. Policy files of
    format version 1 hold it flat (the learner's keys beside the run's): the learner's and the
    run's keys are picked from it, the rest (that version's training aids) ignored."""
    values = dict(obj.get("train_config") or {})
    algo = values.get("algo")
    if algo not in ALGOS:
        raise CheckpointError(f"'{path}' holds a model of an unknown method '{algo}'")
    cls = ALGOS[algo]
    if obj.get("version") == 1:
        learner_keys = {f for f in cls.Config.__dataclass_fields__}
        run_keys = {f for f in TrainConfig.__dataclass_fields__} - {"protocol", "learner"}
        values = {k: v for k, v in values.items() if k in run_keys} | {
            "learner": {k: v for k, v in values.items() if k in learner_keys},
            "protocol": {},
            "preset": str(values.get("preset", "quick")),
        }
    try:
        cfg = train_config_from_dict(values, cls.Config)
    except ConfigError as exc:
        raise CheckpointError(
            f"'{path}' holds an unreadable training configuration: {exc}"
        ) from None
    if obj.get("version") == 1:
        cfg.protocol.name = "unrecorded"  # its aids were flat keys, dropped above
    return cfg


def _read(spec: str | Path) -> tuple[Path, dict, TrainConfig, dict]:
    path = resolve(spec)
    obj = load_file(path, (POLICY_FORMAT, CHECKPOINT_FORMAT))
    cfg = recorded_config(obj, path)
    states = obj["policy"] if obj["format"] == POLICY_FORMAT else obj["modules"]
    return path, obj, cfg, states


def load_pursuer_policy(spec: str | Path, env_cfg: EnvConfig, device="cpu"):
    """The pursuer policy in a policy file, run folder, checkpoint or shipped model name, built
    for the scenario ``env_cfg``. Returns (policy, train_config)."""
    path, _, cfg, states = _read(spec)
    if cfg.algo not in PURSUER_ALGOS:
        raise CheckpointError(f"'{path}' holds a '{cfg.algo}' model, not a pursuer policy")
    learner = ALGOS[cfg.algo]
    trained_n = cfg.env_config().num_pursuers
    reason = learner.fixed_swarm(cfg)
    if reason and env_cfg.num_pursuers != trained_n:
        raise CheckpointError(
            f"'{path}' {reason} for {trained_n} pursuers; the scenario has {env_cfg.num_pursuers}"
        )
    policy, modules = learner.build_policy(cfg, env_cfg, device)
    load_modules(modules, states, str(path))
    policy.eval()
    return policy, cfg


def load_evader_actor(spec: str | Path, device: torch.device | str = "cpu") -> nn.Module:
    """The frozen actor of a DDPG evader (policy file, run folder, checkpoint, or
    ``evader-ddpg`` for the shipped one)."""
    path, _, cfg, states = _read(spec)
    if cfg.algo != "evader-ddpg":
        raise CheckpointError(f"'{path}' holds a '{cfg.algo}' model, not a DDPG evader")
    actor = DeepSetActor(cfg.learner.hidden)
    load_modules({"actor": actor}, states, str(path))
    actor = actor.to(device).eval()
    actor.requires_grad_(False)
    return actor


def describe(spec: str | Path) -> dict:
    """The metadata of a policy file or checkpoint (algorithm, configs, progress)."""
    path, obj, cfg, _ = _read(spec)
    return {
        "path": str(path),
        "format": obj["format"],
        "algo": cfg.algo,
        "train_config": cfg.to_dict(),
        "progress": obj.get("progress", {}),
        "meta": obj.get("meta", {}),
    }


def is_policy_spec(spec: str) -> bool:
    """Whether ``spec`` names a learned policy (an algorithm or an existing path)."""
    return spec in PURSUER_ALGOS or Path(spec).exists() or spec.endswith(".pt")


__all__ = [
    "describe",
    "is_policy_spec",
    "load_evader_actor",
    "load_pursuer_policy",
    "recorded_config",
]
