"""Checkpoints and policy files: written atomically, read with clear errors.

* A **checkpoint** (``checkpoint.pt`` in a run folder) holds everything needed to continue a
  run: networks, target networks, optimisers, the replay buffer, the noise state, RNG states and
  progress counters.
* A **policy file** (``policy.pt``) holds only what acting needs (the actor, and TP Net) with
  the configurations that rebuild it; the models shipped in :mod:`pes.models` are policy files.

Both are ``torch.save`` dicts of tensors and plain values, loaded with ``weights_only=True``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import torch
from torch import nn

from pes.errors import CheckpointError
from pes.models import MODELS_DIR, SHIPPED

CHECKPOINT_FORMAT = "pes-checkpoint"
POLICY_FORMAT = "pes-policy"
VERSION = 2
"""Version 2: the training configuration in sections (``learner``, ``protocol``, ``env``).
Policy files of version 1 (a flat configuration) still load (:mod:`pes.algos.loading`)."""
READABLE_POLICY_VERSIONS = (1, 2)


def save_atomic(obj: dict[str, Any], path: str | Path) -> None:
    """``torch.save`` to a temporary file beside ``path``, flushed to disk, then renamed over
    ``path``: a reader (or a run killed mid-write) sees the old file or the new one, never a
    torn one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as f:
        torch.save(obj, f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    try:
        fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError:
        pass


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file renamed over it: a reader (or a run
    killed mid-write) sees the old file or the new one, never a torn one."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def remove_stale_temporaries(folder: str | Path) -> list[Path]:
    """Delete the temporary files that writers killed mid-write left in ``folder`` (names
    ``.NAME.PID.tmp``); returns them."""
    stale = sorted(Path(folder).glob(".*.tmp"))
    for path in stale:
        path.unlink(missing_ok=True)
    return stale


def save_policy_file(
    path: str | Path,
    algo: str,
    train_config: dict[str, Any],
    env_config: dict[str, Any],
    policy: dict[str, Any],
    meta: dict[str, Any],
) -> dict[str, Any]:
    """Write a policy file atomically: the acting networks' state dicts (``policy``, e.g.
    ``{"actor": ..., "tp": ...}``), the configurations (as plain dicts) that rebuild them, and
    ``meta`` (counters such as episodes, env steps, updates, wall time in s). Returns what was
    written."""
    payload = {
        "format": POLICY_FORMAT,
        "version": VERSION,
        "algo": algo,
        "train_config": train_config,
        "env_config": env_config,
        "policy": policy,
        "meta": meta,
    }
    save_atomic(payload, path)
    return payload


def load_file(path: str | Path, expected: str | tuple[str, ...]) -> dict[str, Any]:
    """Read a checkpoint or policy file, checking its format; raise CheckpointError otherwise."""
    path = Path(path)
    expected = (expected,) if isinstance(expected, str) else expected
    if not path.is_file():
        raise CheckpointError(f"no checkpoint or policy file at '{path}'")
    try:
        obj = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any unreadable file is "corrupted"
        raise CheckpointError(
            f"'{path}' is corrupted or not a PES file ({type(exc).__name__})"
        ) from None
    if not isinstance(obj, dict) or obj.get("format") not in expected:
        raise CheckpointError(f"'{path}' is not a PES {' or '.join(expected)} file")
    readable = READABLE_POLICY_VERSIONS if obj["format"] == POLICY_FORMAT else (VERSION,)
    if obj.get("version") not in readable:
        raise CheckpointError(
            f"'{path}' has format version {obj.get('version')}, this PES reads {VERSION}"
        )
    return obj


def load_modules(modules: dict[str, nn.Module], states: dict[str, Any], source: str) -> None:
    """Load state dicts into modules; an architecture mismatch is a CheckpointError."""
    for name, module in modules.items():
        if name not in states:
            raise CheckpointError(f"'{source}' holds no '{name}' network")
        try:
            module.load_state_dict(states[name])
        except RuntimeError as exc:
            first = str(exc).strip().splitlines()[-1].strip()
            raise CheckpointError(
                f"'{source}' does not match this architecture ({name}: {first})"
            ) from None


def resolve_policy_path(spec: str | Path) -> Path:
    """A shipped model's file for an algorithm name, or ``spec`` itself as a path (a run
    folder means its ``policy.pt``, or its ``checkpoint.pt`` if training has not finished)."""
    if str(spec) in SHIPPED:
        path = MODELS_DIR / SHIPPED[str(spec)]
        if not path.is_file():
            raise CheckpointError(
                f"no shipped '{spec}' model in this installation (expected {path}); train one "
                f"with `pes train --algo {spec}` and pass its policy.pt"
            )
        return path
    path = Path(spec)
    if path.is_dir():
        for name in ("policy.pt", "checkpoint.pt"):
            if (path / name).is_file():
                return path / name
        raise CheckpointError(f"'{path}' holds no policy.pt or checkpoint.pt")
    return path
