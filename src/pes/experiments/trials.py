"""The trials of a reproduction: what each one runs and where it leaves its results.

A trial is one (method, seed) of one budget, run in its own folder ``<out>/trials/<id>/``:

* ``train`` trials (every learned method): ``pes train`` into ``run/`` (resumed from its
  checkpoint if one is there), then the evaluations of Table IV (and, for CBC-TP Net, Table VI)
  of the final policy, each into ``eval_<name>.json``;
* ``pid-pf`` trials: the Table IV evaluation of PID(PF) (no training; seeds differ only in the
  evaluation episodes);
* ``tpnet`` trials (Table V): see :mod:`pes.experiments.tpnet`.

Every step writes its file only when it is complete (atomically), and is skipped when its file
is there, so a trial killed at any point continues where it stopped, and a finished trial
(``done.json``) is not run again. Trials share nothing but the shipped evader, so they can run
in any order, in parallel, on any machine that sees the output folder.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from pes.errors import ConfigError

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
    episode_fraction: float = 1.0
    """Training episodes of each method: this fraction of its preset's ``episodes``."""
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
    "quick": Budget(
        "quick", 1000, train={"time_limit": 0.0, "log_every": 50}, episode_fraction=0.2
    ),
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
episode budgets); ``quick`` with a fifth of the episodes of its quick preset (CBC-TP Net: 2000),
so that the 3-seed sweep of all methods runs in a few hours on a 2-core CPU (docs/reproduce.md).
Neither has a wall-clock limit, so a trial does not depend on the machine's speed or load; both
evaluate on 1000 episodes. ``tiny`` runs the whole pipeline in a minute (tests)."""

DAMAGED = (1, 2)
"""Table VI: pursuers damaged at the start of the CBC-TP Net evaluations."""


def trial_id(kind: str, algo: str, seed: int) -> str:
    return f"{algo}-s{seed}" if kind != "tpnet" else f"tpnet-s{seed}"


def make_trials(methods: list[str], seeds: int, budget: str, tpnet: bool) -> list[dict]:
    """The trial specs (JSON-friendly dicts) for ``methods`` x ``seeds`` (and Table V's)."""
    from pes.algos import ALGOS  # noqa: PLC0415

    for algo in methods:
        if algo != "pid-pf" and algo not in ALGOS:
            raise ConfigError(f"unknown method '{algo}' (available: pid-pf, {', '.join(ALGOS)})")
    specs = []
    for s in range(seeds):  # seed-major: a partial sweep has every method at its first seeds
        if tpnet:
            specs.append(
                {
                    "id": trial_id("tpnet", "", s),
                    "kind": "tpnet",
                    "algo": "tpnet",
                    "seed": s,
                    "budget": budget,
                }
            )
        for algo in methods:
            kind = "pid-pf" if algo == "pid-pf" else "train"
            specs.append(
                {
                    "id": trial_id(kind, algo, s),
                    "kind": kind,
                    "algo": algo,
                    "seed": s,
                    "budget": budget,
                }
            )
    return specs


def write_json(path: Path, obj: Any) -> None:
    """Write ``obj`` to ``path`` atomically (a reader never sees half a file)."""
    tmp = path.with_suffix(path.suffix + f".tmp{os.getpid()}")
    tmp.write_text(json.dumps(obj, indent=2) + "\n")
    tmp.replace(path)


def eval_config(budget: Budget, damaged: int = 0):
    """The paper's evaluation scenario (§V-B): disturbance on, damaged pursuers disabled, the
    shipped DDPG evader calibrated to the paper's (``flee`` if this installation has none)."""
    from pes.algos.io import default_evader_policy  # noqa: PLC0415
    from pes.sim.config import EnvConfig  # noqa: PLC0415

    return EnvConfig().for_evaluation(
        evader_policy=default_evader_policy(), damaged=damaged, **budget.eval_env
    )


def evaluations(spec: dict) -> dict[str, int]:
    """Evaluation name -> pursuers damaged, for a trial."""
    out = {"table4": 0}
    if spec["algo"] == "cbc-tp":
        out.update({f"damaged{k}": k for k in DAMAGED})
    return out


def run_trial(spec: dict, out: Path, threads: int = 0) -> dict[str, Any]:
    """Run (or finish) one trial in ``out/trials/<id>``; returns its ``done.json`` contents."""
    folder = Path(out) / "trials" / spec["id"]
    done = folder / "done.json"
    if done.is_file():
        return json.loads(done.read_text())
    folder.mkdir(parents=True, exist_ok=True)
    if threads:
        torch.set_num_threads(threads)
    budget = BUDGETS[spec["budget"]]
    start = time.time()
    if spec["kind"] == "tpnet":
        from pes.experiments.tpnet import run_tpnet  # noqa: PLC0415

        result = {"table5": run_tpnet(spec, budget, folder)}
    else:
        result = _run_policy_trial(spec, budget, folder, threads)
    record = {"spec": spec, "seconds_this_run": round(time.time() - start, 1), **result}
    write_json(done, record)
    return record


def _run_policy_trial(spec: dict, budget: Budget, folder: Path, threads: int) -> dict:
    from pes.evaluate import evaluate  # noqa: PLC0415

    train_summary = None
    if spec["kind"] == "train":
        train_summary = _train(spec, budget, folder, threads)
    results = {}
    for name, damaged in evaluations(spec).items():
        path = folder / f"eval_{name}.json"
        if not path.is_file():
            cfg = eval_config(budget, damaged)
            policy = _policy(spec, folder, cfg)
            seed = EVAL_SEED + 10_000 * spec["seed"]
            res = evaluate(policy, cfg, budget.eval_episodes, num_envs=EVAL_ENVS, seed=seed)
            write_json(
                path,
                {
                    **res.summary(),
                    "damaged": damaged,
                    "evader": cfg.evader_policy,
                    "per_episode": res.per_episode,
                },
            )
        summary = json.loads(path.read_text())
        summary.pop("per_episode")
        results[name] = summary
    return {"train": train_summary, "evals": results}


def train_config(spec: dict, budget: Budget, threads: int = 0):
    """The :class:`pes.algos.config.TrainConfig` of a ``train`` trial: the method's preset of
    the budget's name, the budget's overrides and share of the preset's episodes, the seed."""
    from pes.algos.config import build_train_config  # noqa: PLC0415

    values = {**budget.train, "seed": spec["seed"], "eval_episodes": 0, "threads": threads}
    values["env"] = dict(budget.train.get("env", {}))
    cfg = build_train_config(spec["algo"], budget.preset, values)
    if budget.episode_fraction != 1.0:
        values["episodes"] = max(1, round(cfg.episodes * budget.episode_fraction))
        cfg = build_train_config(spec["algo"], budget.preset, values)
    return cfg


def _train(spec: dict, budget: Budget, folder: Path, threads: int) -> dict:
    from pes.algos.trainer import train  # noqa: PLC0415

    run = folder / "run"
    if (run / "summary.json").is_file():
        return json.loads((run / "summary.json").read_text())
    cfg = train_config(spec, budget, threads)
    return train(cfg, run, resume=(run / "checkpoint.pt").is_file(), progress=False)


def _policy(spec: dict, folder: Path, cfg):
    from pes.algos.policy import load_pursuer_policy  # noqa: PLC0415
    from pes.policies import PIDPotentialField  # noqa: PLC0415

    if spec["kind"] == "pid-pf":
        return PIDPotentialField(cfg)
    return load_pursuer_policy(folder / "run" / "policy.pt", cfg)[0]
