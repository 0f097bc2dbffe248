"""What a reproduction's budget means (training presets, evaluation size) and the evaluation
scenario every trial shares."""

from __future__ import annotations

import json
import os
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pes.models import default_evader_policy
from pes.sim.config import EnvConfig

EVAL_SEED = 1_000_000
"""Evaluation episodes of seed s start at EVAL_SEED + 10_000 s (never a training seed)."""
EVAL_ENVS = 250
"""Environments an evaluation steps at once (1000 episodes: 4 batches)."""


@dataclass(frozen=True)
class Budget:
    """How much each trial of a reproduction runs."""

    preset: str
    """Training preset of every method (``pes train --preset``)."""
    eval_episodes: int
    """Episodes of each evaluation (the paper: 1000)."""
    eval_env: dict[str, Any] = field(default_factory=dict)
    """Scenario overrides of the evaluations (only the tiny budget shortens episodes)."""
    train: dict[str, Any] = field(default_factory=dict)
    """Training overrides on top of the preset."""
    tp_train_episodes: int = 200
    """Table V: episodes whose trajectories train TP Net."""
    tp_test_episodes: int = 100
    """Table V: held-out episodes it is measured on."""
    tp_steps: int = 3000
    """Table V: TP Net gradient steps."""
    tp_hidden: int = 64
    """Table V: TP Net LSTM units."""


BUDGETS = {
    "paper": Budget(
        "paper",
        1000,
        train={"time_limit": 0.0},
        tp_train_episodes=1000,
        tp_test_episodes=200,
        tp_steps=20_000,
        tp_hidden=256,
    ),
    "quick": Budget("quick", 1000, train={"time_limit": 0.0, "log_every": 50}),
    "tiny": Budget(
        "tiny",
        6,
        eval_env={"max_steps": 60},
        train={"episodes": 12, "env": {"max_steps": 60}, "log_every": 4, "compile_env": False},
        tp_train_episodes=4,
        tp_test_episodes=2,
        tp_steps=10,
        tp_hidden=16,
    ),
}
"""``pes reproduce --budget``: ``paper`` trains each method with its paper preset (the paper's
4000 episodes); ``quick`` with its whole quick preset (1,000,000 env steps, the same for every
method: docs/reproduce.md). Neither has a time limit, so a trial does not depend on the
machine's speed or load; both evaluate on 1000 episodes. ``tiny`` runs the whole pipeline in a
minute (tests)."""

DAMAGED = (1, 2)
"""Table VI: pursuers damaged at the start of the CBC-TP Net evaluations."""


def source_commit(package: Path | None = None) -> str | None:
    """The git commit of the PES source that runs (``-dirty`` appended when the package's
    tracked files differ from it; results, docs and notes beside it do not count), or None
    outside a git checkout."""
    package = package or Path(__file__).resolve().parents[1]  # src/pes of a checkout
    git = ["git", "-C", str(package.parents[1])]
    try:
        head = subprocess.run(
            [*git, "rev-parse", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            [*git, "status", "--porcelain", "--untracked-files=no", "--", str(package)],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return head + ("-dirty" if dirty else "")


def write_json(path: Path, obj: Any) -> None:
    """Write ``obj`` to ``path`` atomically (a reader never sees half a file)."""
    tmp = path.with_suffix(path.suffix + f".tmp{os.getpid()}")
    tmp.write_text(json.dumps(obj, indent=2) + "\n")
    tmp.replace(path)


def eval_config(budget: Budget, damaged: int = 0, scenario: dict[str, Any] | None = None):
    """The paper's evaluation scenario (§V-B): disturbance on, damaged pursuers disabled, the
    shipped DDPG evader calibrated to the paper's (``flee`` if this installation has none);
    ``scenario``: :class:`pes.EnvConfig` keys that change the task itself (as in training),
    e.g. ``{"evader_max_speed": 8.0}`` for the positive control."""
    return EnvConfig().for_evaluation(
        evader_policy=default_evader_policy(),
        damaged=damaged,
        **budget.eval_env,
        **(scenario or {}),
    )
