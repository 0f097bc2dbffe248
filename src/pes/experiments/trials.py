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
import time
from pathlib import Path
from typing import Any

import torch

from pes.algos import ALGOS, build_train_config, train
from pes.algos.loading import load_pursuer_policy
from pes.errors import ConfigError
from pes.evaluate import evaluate
from pes.experiments.budgets import (
    BUDGETS,
    DAMAGED,
    EVAL_ENVS,
    EVAL_SEED,
    Budget,
    eval_config,
    source_commit,
    write_json,
)
from pes.experiments.tpnet import run_tpnet
from pes.lock import folder_lock
from pes.policies import PIDPotentialField

__all__ = ["BUDGETS", "DAMAGED", "EVAL_SEED", "eval_config", "make_trials", "run_trial"]


def trial_id(kind: str, algo: str, seed: int) -> str:
    return f"{algo}-s{seed}" if kind != "tpnet" else f"tpnet-s{seed}"


def make_trials(
    methods: list[str],
    seeds: int,
    budget: str,
    tpnet: bool,
    protocol: str = "pes",
    overrides: dict[str, Any] | None = None,
    scenario: dict[str, Any] | None = None,
) -> list[dict]:
    """The trial specs (JSON-friendly dicts) for ``methods`` x ``seeds`` (and Table V's); the
    learners train under ``protocol`` with ``overrides`` (``pes train --set`` keys, e.g.
    ``{"protocol.n_step": 1}``) on top of their presets, kept in the spec as ``set``.
    ``scenario``: :class:`pes.EnvConfig` keys that change the task for the training and the
    evaluations of every method (PID(PF) included), kept in the spec as ``scenario``; Table
    V's trials play the shipped swarm in the default task and take none."""
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
            spec = {"id": trial_id(kind, algo, s), "kind": kind, "algo": algo, "seed": s}
            spec["budget"] = budget
            if scenario:
                spec["scenario"] = dict(scenario)
            if kind == "train":
                spec["protocol"] = protocol
                if overrides:
                    spec["set"] = dict(overrides)
            specs.append(spec)
    return specs


def evaluations(spec: dict) -> dict[str, int]:
    """Evaluation name -> pursuers damaged, for a trial."""
    out = {"table4": 0}
    if spec["algo"] == "cbc-tp":
        out.update({f"damaged{k}": k for k in DAMAGED})
    return out


def run_trial(spec: dict, out: Path, threads: int = 0, progress: bool = False) -> dict[str, Any]:
    """Run (or finish) one trial in ``out/trials/<id>``; returns its ``done.json`` contents.
    ``progress``: show the training's progress bar."""
    folder = Path(out) / "trials" / spec["id"]
    done = folder / "done.json"
    if done.is_file():
        return json.loads(done.read_text())
    with folder_lock(folder, "pes reproduce"):  # a second attempt fails at once
        return _run_trial(spec, folder, threads, progress)


def _run_trial(spec: dict, folder: Path, threads: int, progress: bool) -> dict[str, Any]:
    done = folder / "done.json"
    if done.is_file():  # finished while this attempt waited to start
        return json.loads(done.read_text())
    if not (folder / "spec.json").is_file():  # what a resumed run must match (check_trials)
        write_json(folder / "spec.json", spec)
    if threads:
        torch.set_num_threads(threads)
    budget = BUDGETS[spec["budget"]]
    start = time.time()
    if spec["kind"] == "tpnet":
        result = {"table5": run_tpnet(spec, budget, folder)}
    else:
        result = _run_policy_trial(spec, budget, folder, threads, progress)
    record = {
        "spec": spec,
        "commit": source_commit(),
        "seconds_this_run": round(time.time() - start, 1),
        **result,
    }
    write_json(done, record)
    return record


def _run_policy_trial(
    spec: dict, budget: Budget, folder: Path, threads: int, progress: bool
) -> dict:
    train_summary = None
    if spec["kind"] == "train":
        train_summary = _train(spec, budget, folder, threads, progress)
    results = {}
    for name, damaged in evaluations(spec).items():
        path = folder / f"eval_{name}.json"
        if not path.is_file():
            cfg = eval_config(budget, damaged, spec.get("scenario"))
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
    """The :class:`pes.learn.config.TrainConfig` of a ``train`` trial: the method's preset of
    the budget's name, the budget's overrides, the seed, the spec's ``scenario`` (as ``env``
    keys) and ``set`` keys."""
    values = {**budget.train, "seed": spec["seed"], "eval_episodes": 0, "threads": threads}
    values["env"] = dict(budget.train.get("env", {})) | spec.get("scenario", {})
    values.update(spec.get("set", {}))
    protocol = spec.get("protocol")
    return build_train_config(spec["algo"], budget.preset, values, protocol=protocol)


def _train(spec: dict, budget: Budget, folder: Path, threads: int, progress: bool) -> dict:
    run = folder / "run"
    if (run / "summary.json").is_file():
        summary = json.loads((run / "summary.json").read_text())
        if summary["stopped_by"] != "interrupted":  # else the checkpoint's run goes on
            return summary
    cfg = train_config(spec, budget, threads)
    return train(cfg, run, resume=(run / "checkpoint.pt").is_file(), progress=progress)


def _policy(spec: dict, folder: Path, cfg):
    if spec["kind"] == "pid-pf":
        return PIDPotentialField(cfg)
    return load_pursuer_policy(folder / "run" / "policy.pt", cfg)[0]
