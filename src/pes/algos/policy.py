"""Turning a policy file or checkpoint back into something that acts."""

from __future__ import annotations

from pathlib import Path

from torch import nn

from pes.algos.config import TrainConfig
from pes.algos.io import (
    CHECKPOINT_FORMAT,
    POLICY_FORMAT,
    load_file,
    load_modules,
    resolve_policy_path,
)
from pes.config import from_dict
from pes.errors import CheckpointError
from pes.sim.config import EnvConfig


def _read(spec: str | Path) -> tuple[Path, dict, TrainConfig, dict]:
    path = resolve_policy_path(spec)
    obj = load_file(path, (POLICY_FORMAT, CHECKPOINT_FORMAT))
    try:
        cfg = from_dict(TrainConfig, obj["train_config"])
    except Exception as exc:  # noqa: BLE001
        raise CheckpointError(
            f"'{path}' holds an unreadable training configuration: {exc}"
        ) from None
    states = obj["policy"] if obj["format"] == POLICY_FORMAT else obj["modules"]
    return path, obj, cfg, states


def load_pursuer_policy(spec: str | Path, env_cfg: EnvConfig, device="cpu"):
    """The pursuer policy in a policy file, run folder, checkpoint or shipped model name, built
    for the scenario ``env_cfg``. Returns (policy, train_config)."""
    from pes.algos import ALGOS, PURSUER_ALGOS  # noqa: PLC0415

    path, _, cfg, states = _read(spec)
    if cfg.algo not in PURSUER_ALGOS:
        raise CheckpointError(f"'{path}' holds a '{cfg.algo}' model, not a pursuer policy")
    trained_n = cfg.env_config().num_pursuers
    if not cfg.shared and env_cfg.num_pursuers != trained_n:
        raise CheckpointError(
            f"'{path}' has one network per pursuer for {trained_n} pursuers; the scenario has "
            f"{env_cfg.num_pursuers}"
        )
    policy, modules = ALGOS[cfg.algo].build_policy(cfg, env_cfg, device)
    load_modules(modules, states, str(path))
    policy.eval()
    return policy, cfg


def load_evader_actor(spec: str | Path, device="cpu") -> nn.Module:
    """The frozen actor of a DDPG evader (policy file, run folder, checkpoint, or
    ``evader-ddpg`` for the shipped one)."""
    from pes.algos.nets import DeepSetActor  # noqa: PLC0415

    path, _, cfg, states = _read(spec)
    if cfg.algo != "evader-ddpg":
        raise CheckpointError(f"'{path}' holds a '{cfg.algo}' model, not a DDPG evader")
    actor = DeepSetActor(cfg.hidden)
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
        "train_config": obj["train_config"],
        "progress": obj.get("progress", {}),
        "meta": obj.get("meta", {}),
    }


def is_policy_spec(spec: str) -> bool:
    """Whether ``spec`` names a learned policy (an algorithm or an existing path)."""
    from pes.algos import PURSUER_ALGOS  # noqa: PLC0415

    return spec in PURSUER_ALGOS or Path(spec).exists() or spec.endswith(".pt")


__all__ = ["describe", "is_policy_spec", "load_evader_actor", "load_pursuer_policy"]
