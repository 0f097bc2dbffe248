"""``pes tune``: the same hyper-parameter search for any learner (SPEC §3, "fair comparison").

    pes tune --algo maddpg --trials 8 --minutes 30 --out results/tuning/maddpg

A search samples ``trials`` settings of the learner's :attr:`~pes.learn.learner.Learner.
TUNE_SPACE` (two to four keys: learning rates, exploration or entropy, batch size, network
width) by random search from a fixed seed; trial 0 is the quick preset itself. Each trial trains
the quick preset with its settings under the chosen protocol for ``minutes`` minutes of CPU time
on one torch thread (the run key ``cpu_limit``: the same work whatever else shares the
machine), then is scored on ``eval_episodes`` held-out evaluation episodes (the
paper's protocol: disturbance on, crashes disable, the default evader; seeds never used in
training or in ``pes reproduce``): success rate first, mean reward second. Every learner gets
the same budget: the same trial count, minutes and evaluation.

Each trial runs in ``OUT/trials/<id>/`` (its training run in ``run/``, its score in
``result.json``), so a search killed at any point resumes where it stopped; ``OUT/tuning.json``
and ``OUT/README.md`` list every trial's settings and score with the command.
"""

from __future__ import annotations

import json
import math
import random
import time
from pathlib import Path
from typing import Any

from pes.algos import ALGOS, PURSUER_ALGOS, build_train_config, learner_class, train
from pes.algos.policy import load_pursuer_policy
from pes.errors import ConfigError
from pes.evaluate import evaluate
from pes.experiments.budgets import BUDGETS, eval_config, write_json
from pes.experiments.sweep import SweepProgress, choose_runner, run_ray, run_sequential

TUNE_EVAL_SEED = 3_000_000
"""First seed of the held-out evaluation episodes of a trial (trial k: + 10,000 k)."""


def sample(space: dict[str, tuple], rng: random.Random) -> dict[str, Any]:
    """One setting of a search space: ``("log", low, high)`` draws log-uniformly (rounded to
    three significant digits), ``("choice", [values])`` uniformly among the values."""
    values: dict[str, Any] = {}
    for key, (kind, *args) in space.items():
        if kind == "log":
            low, high = args
            value = math.exp(rng.uniform(math.log(low), math.log(high)))
            values[key] = float(f"{value:.3g}")
        elif kind == "choice":
            values[key] = rng.choice(args[0])
        else:
            raise ValueError(f"unknown search kind '{kind}' for {key}")
    return values


def make_tune_trials(
    algo: str,
    trials: int,
    minutes: float,
    eval_episodes: int,
    protocol: str,
    seed: int,
    preset: str = "quick",
) -> list[dict]:
    """The trial specs of a search (JSON-friendly dicts): trial 0 the quick preset, the others
    random settings of the learner's search space, drawn from ``seed``."""
    cls = learner_class(algo)
    if algo not in PURSUER_ALGOS or not cls.TUNE_SPACE:
        raise ConfigError(f"pes tune takes the pursuer learners, not {algo}")
    if trials < 1 or minutes <= 0 or eval_episodes < 1:
        raise ConfigError("trials, minutes and eval_episodes must be positive")
    rng = random.Random(f"{algo}-{seed}")
    specs = []
    for k in range(trials):
        values = {} if k == 0 else sample(cls.TUNE_SPACE, rng)
        build_train_config(algo, preset, dict(values), protocol=protocol)  # checks the values
        specs.append(
            {
                "id": f"t{k:02d}",
                "algo": algo,
                "preset": preset,
                "values": values,
                "minutes": minutes,
                "clock": "cpu",
                "eval_episodes": eval_episodes,
                "protocol": protocol,
                "seed": seed,
                "eval_seed": TUNE_EVAL_SEED + 10_000 * k,
            }
        )
    return specs


def finished(out: Path, spec: dict) -> dict[str, Any] | None:
    """The result of trial ``spec`` in ``out`` if it has finished (None if not); a trial of the
    same id run with other settings is a one-line error."""
    done = Path(out) / "trials" / spec["id"] / "result.json"
    if not done.is_file():
        return None
    record = json.loads(done.read_text())
    if record["spec"] != spec:
        raise ConfigError(
            f"'{done.parent}' holds a trial run with other settings ({record['spec']}); "
            "choose another --out"
        )
    return record


def run_tune_trial(spec: dict, out: Path, threads: int = 0) -> dict[str, Any]:
    """Train and score one trial in ``out/trials/<id>`` (resumed from its checkpoint if one is
    there); returns its ``result.json`` contents."""
    folder = Path(out) / "trials" / spec["id"]
    done = folder / "result.json"
    record = finished(out, spec)
    if record is not None:
        return record
    folder.mkdir(parents=True, exist_ok=True)
    values = {
        **spec["values"],
        "seed": spec["seed"],
        "cpu_limit": spec["minutes"],  # CPU minutes: the same work beside other jobs
        "time_limit": 0.0,
        "episodes": 10**7,  # the minutes bind
        "eval_episodes": 0,
        "threads": threads or 1,
        "log_every": 50,
    }
    cfg = build_train_config(spec["algo"], spec["preset"], values, protocol=spec["protocol"])
    run = folder / "run"
    summary_path = run / "summary.json"
    stopped = json.loads(summary_path.read_text())["stopped_by"] if summary_path.is_file() else ""
    if stopped in ("", "interrupted"):
        train(cfg, run, resume=(run / "checkpoint.pt").is_file(), progress=False)
    train_summary = json.loads((run / "summary.json").read_text())
    env_cfg = eval_config(BUDGETS["quick"])
    policy, _ = load_pursuer_policy(run / "policy.pt", env_cfg)
    episodes = spec["eval_episodes"]
    result = evaluate(
        policy, env_cfg, episodes, num_envs=min(episodes, 250), seed=spec["eval_seed"]
    ).summary()
    record = {
        "spec": spec,
        "learner": cfg.learner.__dict__,
        "train": {
            k: train_summary[k] for k in ("episodes", "env_steps", "updates", "wall_s", "cpu_s")
        },
        "eval": result,
        "score": score(result),
    }
    write_json(done, record)
    return record


def score(result: dict[str, Any]) -> float:
    """A trial's score (higher is better): success rate, then the evaluation's mean reward (the
    paper's reward: nearer the evader, fewer crashes, sooner captures). Not fewer steps: where no
    trial captures, the fewest steps are those of swarms lost to crashes soonest."""
    return result["success_rate"] + 1e-5 * result["mean_reward"]


def tune(
    algo: str,
    trials: int = 8,
    minutes: float = 30.0,
    eval_episodes: int = 200,
    protocol: str = "pes",
    seed: int = 0,
    out: str | Path | None = None,
    use_ray: bool | None = None,
    ray_address: str | None = None,
    parallel: int = 0,
    progress: bool = True,
    command: str = "",
    preset: str = "quick",
    report_only: bool = False,
) -> dict[str, Any]:
    """Run (or finish) the search of ``algo`` into ``out`` and write its report; returns a
    summary with every finished trial, best first. ``preset`` is the budget each trial trains
    (``quick``; ``tiny`` for tests); ``report_only`` runs no trial and reports the scored ones."""
    if algo not in ALGOS:
        raise ConfigError(f"algo must be one of {', '.join(ALGOS)}, got '{algo}'")
    specs = make_tune_trials(algo, trials, minutes, eval_episodes, protocol, seed, preset)
    out = Path(out or f"results/tuning/{algo}")
    out.mkdir(parents=True, exist_ok=True)
    use_ray = choose_runner(use_ray, ray_address)
    todo = [] if report_only else [s for s in specs if finished(out, s) is None]
    start = time.time()
    view = SweepProgress(len(specs), len(specs) - len(todo), progress and bool(todo), "tune")
    try:
        if todo and use_ray:
            run_ray(todo, out, ray_address, view, run_tune_trial, parallel, "tune")
        elif todo:
            run_sequential(todo, out, view, run_tune_trial)
    finally:
        view.close()
    return write_tuning_report(out, specs, command, time.time() - start)


def write_tuning_report(out: Path, specs: list[dict], command: str, seconds: float) -> dict:
    """``tuning.json`` and ``README.md`` of the finished trials, best first."""
    results = []
    for spec in specs:
        path = out / "trials" / spec["id"] / "result.json"
        if path.is_file():
            record = json.loads(path.read_text())
            record["score"] = score(record["eval"])  # today's score of trials scored before
            results.append(record)
    results.sort(key=lambda r: r["score"], reverse=True)
    first = specs[0]
    summary = {
        "algo": first["algo"],
        "protocol": first["protocol"],
        "trials": len(specs),
        "finished": len(results),
        "minutes_per_trial": first["minutes"],
        "clock": "cpu",
        "eval_episodes": first["eval_episodes"],
        "search_space": {k: list(v) for k, v in learner_class(first["algo"]).TUNE_SPACE.items()},
        "command": command,
        "seconds_this_run": round(seconds, 1),
        "best": results[0]["spec"]["values"] if results else None,
        "results": [
            {
                "id": r["spec"]["id"],
                "values": r["spec"]["values"],
                "score": round(r["score"], 5),
                "success_rate": r["eval"]["success_rate"],
                "mean_steps": r["eval"]["mean_steps"],
                "mean_crashes": r["eval"]["mean_crashes"],
                "train_episodes": r["train"]["episodes"],
                "train_env_steps": r["train"]["env_steps"],
                "updates": r["train"]["updates"],
            }
            for r in results
        ],
    }
    write_json(out / "tuning.json", summary)
    lines = [
        f"# Tuning `{first['algo']}` ({first['protocol']} protocol)",
        "",
        f"{len(results)} of {len(specs)} trials finished; each trains the quick preset with its "
        f"settings for {first['minutes']:g} minutes of CPU time on one torch thread and is "
        "scored on "
        f"{first['eval_episodes']} held-out episodes (disturbance on, crashes disable, the "
        "default evader). Trial t00 is the quick preset itself.",
        "",
        f"Command: `{command}`" if command else "",
        "",
        "| trial | settings | success | steps | crashes | training episodes | env steps |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in summary["results"]:
        settings = ", ".join(f"{k}={v}" for k, v in r["values"].items()) or "(quick preset)"
        lines.append(
            f"| {r['id']} | {settings} | {100 * r['success_rate']:.1f} % | "
            f"{r['mean_steps']:.0f} | {r['mean_crashes']:.2f} | {r['train_episodes']} | "
            f"{r['train_env_steps']:,} |"
        )
    (out / "README.md").write_text("\n".join(lines) + "\n")
    return {**summary, "out": str(out)}
