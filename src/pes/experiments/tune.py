"""``pes tune``: the same hyper-parameter search for any learner (docs/reproduce.md, "A fair
comparison").

    pes tune --algo maddpg --trials 8 --out results/tuning/maddpg

A search samples ``trials`` settings of the learner's :attr:`~pes.learn.learner.Learner.
TUNE_SPACE` (two to four keys: learning rates, exploration or entropy, batch size, network
width) by random search from a fixed seed; trial 0 is the preset itself (its values of those
keys, written out, so that a trial's settings stay what they were when the preset later
changes). Each trial trains the quick preset with its settings under the chosen protocol, on
one torch thread, and the budget is experience, not time: ``env_steps`` control steps of one
environment (by default half of the preset's budget: 1,000,000 for the quick presets' 2,000,000,
so that a search of 8 trials costs about three of the trainings it tunes), the same work on
every machine and beside any other job.

The budget is spent by successive halving: every trial trains to ``env_steps / 2**halvings``
env steps and is scored; the better half trains on to twice that and is scored again; and so on
until the last ``ceil(trials / 2**halvings)`` reach ``env_steps`` (8 trials, 1 halving: 8 trials
to half the budget, the better 4 to all of it: six full trainings' worth). A trial that goes on
resumes its own run, so its last score is that of one run trained straight to its budget. A
trial's training and scores do not depend on the rounds after them, so a trial folder stays
valid when the search's rounds change (only its other settings must match). Each score is on
``eval_episodes`` held-out evaluation episodes, the same ones for every trial (the paper's
protocol: disturbance on, crashes disable, the default evader; seeds never used in training or
in ``pes reproduce``): success rate first, mean reward second. Every learner gets the same
budget: the same trials, halvings, env steps and evaluation.

Each trial runs in ``OUT/trials/<id>/`` (its training run in ``run/``, its score at each budget
in ``result-<env_steps>.json``, its run's ``progress.csv`` and ``config.yaml`` copied beside
them), so a search killed at any point resumes where it stopped; ``OUT/tuning.json`` and
``OUT/README.md`` list every trial's settings and scores with the command, and
``OUT/curves.png`` shows every trial's learning curve beside its scores.
"""

from __future__ import annotations

import json
import math
import random
import shutil
import time
from pathlib import Path
from typing import Any

from pes.algos import ALGOS, PURSUER_ALGOS, build_train_config, learner_class, train
from pes.algos.loading import load_pursuer_policy
from pes.errors import ConfigError
from pes.evaluate import evaluate, success_error
from pes.experiments.budgets import BUDGETS, EVAL_ENVS, eval_config, write_json
from pes.experiments.report import read_progress, trained_on
from pes.experiments.sweep import (
    RAY_TIMEOUT,
    SweepProgress,
    choose_runner,
    run_ray,
    run_sequential,
)
from pes.lock import check_free, folder_lock

TUNE_EVAL_SEED = 3_000_000
"""First seed of the held-out evaluation episodes of every trial."""


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


def rung_budgets(env_steps: int, halvings: int) -> list[int]:
    """The env steps of each round of successive halving: ``env_steps / 2**halvings``, twice
    that, ..., ``env_steps`` (e.g. 1,000,000 and 1: 500,000, 1,000,000)."""
    return [env_steps >> (halvings - k) for k in range(halvings + 1)]


def make_tune_trials(
    algo: str,
    trials: int,
    env_steps: int,
    halvings: int,
    eval_episodes: int,
    protocol: str,
    seed: int,
    preset: str = "quick",
) -> list[dict]:
    """The trial specs of a search (JSON-friendly dicts): trial 0 the preset's own values of the
    learner's search space, the others random settings of it drawn from ``seed``; ``budgets``
    lists the env steps of each round (:func:`rung_budgets`)."""
    cls = learner_class(algo)
    if algo not in PURSUER_ALGOS or not cls.TUNE_SPACE:
        raise ConfigError(f"pes tune takes the pursuer learners, not {algo}")
    if trials < 1 or eval_episodes < 1:
        raise ConfigError("trials and eval_episodes must be positive")
    if halvings < 0 or trials >> halvings < 1:
        raise ConfigError(
            f"halvings must be 0 to {trials.bit_length() - 1} for {trials} trials, got {halvings}"
        )
    if env_steps >> halvings < 1:
        raise ConfigError(f"env_steps {env_steps} is too small for {halvings} halvings")
    rng = random.Random(f"{algo}-{seed}")
    base = build_train_config(algo, preset, {}, protocol=protocol).learner
    specs = []
    for k in range(trials):
        if k == 0:
            values = {key: getattr(base, key) for key in cls.TUNE_SPACE}
        else:
            values = sample(cls.TUNE_SPACE, rng)
        build_train_config(algo, preset, dict(values), protocol=protocol)  # checks the values
        specs.append(
            {
                "id": f"t{k:02d}",
                "algo": algo,
                "preset": preset,
                "values": values,
                "budgets": rung_budgets(env_steps, halvings),
                "eval_episodes": eval_episodes,
                "protocol": protocol,
                "seed": seed,
                "eval_seed": TUNE_EVAL_SEED,
            }
        )
    return specs


def preset_env_steps(algo: str, preset: str, protocol: str) -> int:
    """``pes tune``'s default trial budget: half the env-step budget of ``algo``'s ``preset``
    (1,000,000 for the quick presets)."""
    steps = build_train_config(algo, preset, {}, protocol=protocol).env_steps // 2
    if steps < 1:
        raise ConfigError(
            f"the {preset} preset of {algo} has no env_steps budget: give --env-steps"
        )
    return steps


def run_folder(out: Path, spec: dict) -> Path:
    """Where trial ``spec`` trains (its checkpoint, not committed)."""
    return Path(out) / "trials" / spec["id"] / "run"


def result_path(out: Path, spec: dict, env_steps: int) -> Path:
    """Where trial ``spec``'s score at ``env_steps`` is kept."""
    return Path(out) / "trials" / spec["id"] / f"result-{env_steps}.json"


def check_trial(out: Path, spec: dict) -> None:
    """Refuse (a one-line error) a trial folder that holds a trial of other settings: its
    ``spec.json`` (written before its first training) or a score's, or the ``result.json`` of a
    search budgeted in CPU minutes."""
    folder = Path(out) / "trials" / spec["id"]
    if (folder / "result.json").is_file():
        raise ConfigError(
            f"'{folder}' holds a trial of a search budgeted in CPU minutes; choose another --out"
        )
    for held in stored_specs(folder):
        if not same_trial(held, spec):
            raise ConfigError(
                f"'{folder}' holds a trial run with other settings ({held}); choose another --out"
            )


def same_trial(a: dict, b: dict) -> bool:
    """Whether two trial specs train and score the same: every key but ``budgets``, the
    search's rounds, which a trial's run and its scores at each env-step budget do not depend on."""
    return {**a, "budgets": None} == {**b, "budgets": None}


def stored_specs(folder: Path) -> list[dict]:
    """The trial specs a trial folder holds: its ``spec.json`` and every score's."""
    held = []
    for path in sorted([*folder.glob("spec.json"), *folder.glob("result-*.json")]):
        record = json.loads(path.read_text())
        held.append(record.get("spec", record))  # a score holds its spec, spec.json is one
    return held


def started_values(out: Path, first: dict) -> dict[str, Any] | None:
    """The settings trial ``first`` (t00, the preset) began with in ``out``, if it began: the
    preset as it was then, which a search's best may have replaced since (None: not begun)."""
    for held in stored_specs(Path(out) / "trials" / first["id"]):
        if same_trial({**held, "values": first["values"]}, first):  # only the values differ
            return held["values"]
    return None


def finished(out: Path, spec: dict, env_steps: int) -> dict[str, Any] | None:
    """The score of trial ``spec`` at ``env_steps`` in ``out`` if it has one (None if not)
    (:func:`check_trial` first)."""
    check_trial(out, spec)
    done = result_path(out, spec, env_steps)
    return json.loads(done.read_text()) if done.is_file() else None


def run_tune_trial(
    spec: dict, out: Path, threads: int = 0, progress: bool = False
) -> dict[str, Any]:
    """Train trial ``spec`` in ``out/trials/<id>/run`` to ``spec["env_steps"]`` env steps
    (resumed from its checkpoint if one is there) and score it; returns the contents of its
    ``result-<env_steps>.json``. ``progress``: show the training's progress bar."""
    spec, env_steps = dict(spec), spec["env_steps"]
    del spec["env_steps"]
    record = finished(out, spec, env_steps)
    if record is not None:
        return record
    folder = Path(out) / "trials" / spec["id"]
    with folder_lock(folder, "pes tune"):  # a second attempt fails at once
        return _run_tune_trial(spec, env_steps, out, folder, threads, progress)


def _run_tune_trial(
    spec: dict, env_steps: int, out: Path, folder: Path, threads: int, progress: bool
) -> dict[str, Any]:
    record = finished(out, spec, env_steps)
    if record is not None:  # finished while this attempt waited to start
        return record
    if not (folder / "spec.json").is_file():
        write_json(folder / "spec.json", spec)
    values = {
        **spec["values"],
        "seed": spec["seed"],
        "env_steps": env_steps,  # experience: the same work on any machine, beside any job
        "time_limit": 0.0,
        "cpu_limit": 0.0,
        "episodes": 10**7,  # the env steps bind
        "eval_episodes": 0,
        "threads": threads or 1,
        "log_every": 50,
    }
    cfg = build_train_config(spec["algo"], spec["preset"], values, protocol=spec["protocol"])
    run = run_folder(out, spec)
    summary_path = run / "summary.json"
    trained = json.loads(summary_path.read_text())["env_steps"] if summary_path.is_file() else 0
    if trained < env_steps:
        train(cfg, run, resume=(run / "checkpoint.pt").is_file(), progress=progress)
    train_summary = json.loads(summary_path.read_text())
    env_cfg = eval_config(BUDGETS["quick"])
    policy, _ = load_pursuer_policy(run / "policy.pt", env_cfg)
    episodes = spec["eval_episodes"]
    result = evaluate(
        policy, env_cfg, episodes, num_envs=min(episodes, EVAL_ENVS), seed=spec["eval_seed"]
    ).summary()
    record = {
        "spec": spec,
        "env_steps": env_steps,
        "learner": cfg.learner.__dict__,
        "train": {
            k: train_summary[k]
            for k in ("episodes", "env_steps", "updates", "wall_s", "cpu_s", "cpus", "stopped_by")
        },
        "eval": result,
        "score": score(result),
    }
    write_json(result_path(out, spec, env_steps), record)
    return record


def score(result: dict[str, Any]) -> float:
    """A trial's score (higher is better): success rate, then the evaluation's mean reward (the
    paper's reward: nearer the evader, fewer crashes, sooner captures). Not fewer steps: where no
    trial captures, the fewest steps are those of swarms lost to crashes soonest."""
    return result["success_rate"] + 1e-5 * result["mean_reward"]


def chosen(results: list[dict], eval_episodes: int) -> dict[str, Any]:
    """The trial whose settings a search recommends, of ``results`` ranked best first (each with
    ``env_steps``, ``success_rate`` and its training's ``cpu_s``): the best-scored trial at the
    furthest budget, unless it captures and a trial there lies within one standard error of its
    success rate (sqrt(p (1 - p) / n) over the ``eval_episodes`` held-out episodes) and trained in
    at most half its CPU time; then the cheapest such trial (where the top trial captures nothing,
    the mean reward ranks, as in :func:`score`). This is the one-standard-error rule of model
    selection (Hastie, Tibshirani and Friedman, The Elements of Statistical Learning, 7.10) with
    training cost as the measure of simplicity: scores that the held-out episodes cannot tell
    apart do not buy a preset that costs twice the compute."""
    top = results[0]
    p = top["success_rate"]
    if p == 0:
        return top
    floor = p - success_error(p, eval_episodes)
    tied = [
        r
        for r in results
        if r["env_steps"] == top["env_steps"]
        and r["success_rate"] >= floor
        and 0 < r["cpu_s"] <= top["cpu_s"] / 2
    ]
    return min(tied, key=lambda r: (r["cpu_s"], r["id"])) if tied else top


def survivors(records: list[dict], keep: int) -> list[str]:
    """The ids of the ``keep`` best-scored records (ties: the lower id)."""
    ranked = sorted(records, key=lambda r: (-score(r["eval"]), r["spec"]["id"]))
    return [r["spec"]["id"] for r in ranked[:keep]]


def rounds(out: Path, specs: list[dict]) -> list[tuple[int, list[dict], dict[str, dict]]]:
    """The rounds of successive halving so far, each as its env steps, its trials and their
    scores there by id. Round k's trials are the ``ceil(trials / 2**k)`` best of round k - 1;
    a round is listed once the one before it is complete."""
    budgets = specs[0]["budgets"]
    alive, found = specs, []
    for k, budget in enumerate(budgets):
        scored = {s["id"]: r for s in alive if (r := finished(out, s, budget)) is not None}
        found.append((budget, alive, scored))
        if len(scored) < len(alive) or k == len(budgets) - 1:
            break
        keep = set(survivors(list(scored.values()), math.ceil(len(specs) / 2 ** (k + 1))))
        alive = [s for s in alive if s["id"] in keep]
    return found


def pending(found: list[tuple[int, list[dict], dict[str, dict]]]) -> tuple[int, list[dict]] | None:
    """The round still to run, from :func:`rounds`: its env steps and its trials without a
    score there yet (None once the search is complete)."""
    budget, alive, scored = found[-1]
    todo = [s for s in alive if s["id"] not in scored]
    return (budget, todo) if todo else None


def run_order(out: Path, todo: list[dict]) -> list[dict]:
    """``todo`` in the order its trials run: those that resume from a checkpoint
    (``trials/<id>/run/checkpoint.pt``) first, then the rest, each group by the CPU time the
    trial took in the last round it was scored in (a first round keeps the trials' order): a
    round's shortest work runs first, so that an interruption loses the least and the scores
    that cost least arrive first (a trial whose checkpoint is gone trains again from the start,
    under the same schedules: they count episodes, not the budget)."""

    def last_cpu_s(spec: dict) -> float:
        scored = (Path(out) / "trials" / spec["id"]).glob("result-*.json")
        records = [json.loads(path.read_text()) for path in scored]
        return max(records, key=lambda r: r["env_steps"])["train"]["cpu_s"] if records else 0.0

    return sorted(
        todo,
        key=lambda spec: (
            not (run_folder(out, spec) / "checkpoint.pt").is_file(),
            last_cpu_s(spec),
        ),
    )


def tune(
    algo: str,
    trials: int = 8,
    env_steps: int = 0,
    halvings: int = 1,
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
    ray_timeout: float = RAY_TIMEOUT,
) -> dict[str, Any]:
    """Run (or finish) the search of ``algo`` into ``out`` and write its report; returns a
    summary with every scored trial, best first. ``env_steps`` is the budget of the trials that
    go furthest (0: the preset's ``env_steps``), ``halvings`` the rounds of successive halving
    before them; ``preset`` is what each trial trains (``quick``; ``tiny`` for tests);
    ``report_only`` runs no trial and reports the scored ones; ``ray_timeout``: seconds to wait
    for the cluster at ``ray_address`` to answer."""
    if algo not in ALGOS:
        raise ConfigError(f"algo must be one of {', '.join(ALGOS)}, got '{algo}'")
    env_steps = env_steps or preset_env_steps(algo, preset, protocol)
    specs = make_tune_trials(
        algo, trials, env_steps, halvings, eval_episodes, protocol, seed, preset
    )
    out = Path(out or f"results/tuning/{algo}")
    out.mkdir(parents=True, exist_ok=True)
    specs[0]["values"] = started_values(out, specs[0]) or specs[0]["values"]
    use_ray = choose_runner(use_ray, ray_address)
    start = time.time()
    while not report_only and (round_ := pending(rounds(out, specs))) is not None:
        budget, todo = round_[0], run_order(out, round_[1])
        folders = [out / "trials" / s["id"] for s in todo]
        check_free(folders + [run_folder(out, s) for s in todo], "pes tune")
        view = SweepProgress(len(todo), 0, progress, f"tune {budget:,} env steps")
        batch = [{**s, "env_steps": budget} for s in todo]
        try:
            if use_ray:
                run_ray(
                    batch, out, ray_address, view, run_tune_trial, parallel, "tune", ray_timeout
                )
            else:
                run_sequential(batch, out, view, run_tune_trial)
        finally:
            view.close()
    with folder_lock(out, "pes tune", wait=True):  # one report writer at a time
        return write_tuning_report(out, specs, command, time.time() - start)


def copy_run_log(folder: Path) -> None:
    """Copy a trial's run's ``progress.csv`` and ``config.yaml`` beside its scores, unless the
    copy there is the longer log: a trial that starts over (its checkpoint lost) keeps the log
    of the run that was scored until the new run has logged as far."""
    log, copy = folder / "run" / "progress.csv", folder / "progress.csv"
    if not log.is_file():
        return
    if copy.is_file() and len(log.read_text().splitlines()) < len(copy.read_text().splitlines()):
        return
    for name in ("progress.csv", "config.yaml"):
        if (folder / "run" / name).is_file():
            shutil.copyfile(folder / "run" / name, folder / name)


def write_tuning_report(out: Path, specs: list[dict], command: str, seconds: float) -> dict:
    """``tuning.json`` and ``README.md`` of the scored trials: each trial's score at every round
    of the search it reached, the trials ranked by the furthest round they reached, then by
    their score there; each scored trial's learning curve and settings (its run's
    ``progress.csv`` and ``config.yaml``) beside its scores, where the run is (the run folder is
    not kept); ``curves.png`` (:func:`write_curves`)."""
    first = specs[0]
    budgets = first["budgets"]
    found = rounds(out, specs)
    results = []
    for spec in specs:
        scores = {b: scored[spec["id"]] for b, _, scored in found if spec["id"] in scored}
        if not scores:
            continue
        folder = out / "trials" / spec["id"]
        copy_run_log(folder)
        last = max(scores)
        record = scores[last]
        results.append(
            {
                "id": spec["id"],
                "values": spec["values"],
                "env_steps": last,
                "score": score(record["eval"]),
                "success_rate": record["eval"]["success_rate"],
                "mean_steps": record["eval"]["mean_steps"],
                "mean_crashes": record["eval"]["mean_crashes"],
                "lost_rate": record["eval"]["lost_rate"],
                "timeout_rate": record["eval"]["timeout_rate"],
                "train_episodes": record["train"]["episodes"],
                "updates": record["train"]["updates"],
                "cpu_s": record["train"]["cpu_s"],
                "cpus": record["train"].get("cpus"),
                "by_budget": {
                    str(b): {
                        "success_rate": r["eval"]["success_rate"],
                        "mean_reward": r["eval"]["mean_reward"],
                        "mean_steps": r["eval"]["mean_steps"],
                    }
                    for b, r in scores.items()
                },
            }
        )
    results.sort(key=lambda r: (-r["env_steps"], -r["score"], r["id"]))
    for r in results:
        r["score"] = round(r["score"], 8)  # the reward term is 1e-5 of it
    beyond = other_budgets(out, specs, budgets)
    finals = math.ceil(len(specs) / 2 ** (len(budgets) - 1))
    complete = pending(found) is None
    pick = chosen(results, first["eval_episodes"]) if results else None
    summary = {
        "algo": first["algo"],
        "protocol": first["protocol"],
        "trials": len(specs),
        "scored": len(results),
        "complete": complete,
        "budgets": budgets,
        "budget_unit": "env steps",
        "eval_episodes": first["eval_episodes"],
        "eval_seed": first["eval_seed"],
        "search_space": {k: list(v) for k, v in learner_class(first["algo"]).TUNE_SPACE.items()},
        "command": command,
        "seconds_this_run": round(seconds, 1),
        "best": pick["values"] if complete else None,
        "best_id": pick["id"] if complete else None,
        "results": results,
        "other_budgets": beyond,
    }
    write_json(out / "tuning.json", summary)
    heads = " | ".join(f"{b:,} steps" for b in budgets)
    lines = [
        f"# Tuning `{first['algo']}` ({first['protocol']} protocol)",
        "",
        f"{len(results)} of {len(specs)} trials scored"
        + ("; the search is complete." if complete else "; the search is not finished.")
        + f" Every trial trains the {first['preset']} preset with its settings on one torch "
        f"thread to {budgets[0]:,} env steps"
        + (
            "; by successive halving, the better half of them goes on to twice that, and so on "
            f"up to {budgets[-1]:,} env steps ({finals} trials)"
            if len(budgets) > 1
            else ""
        )
        + f". Each score is on the same {first['eval_episodes']} held-out episodes (disturbance "
        "on, crashes disable, the default evader): success rate, then mean reward. Trial t00 is "
        f"the {first['preset']} preset as it was when the search began. Trials are ranked by the "
        "furthest budget they reached, then by their score there. The best settings are the "
        "top trial's, unless it captures and a trial at the same budget scores within one "
        "standard error of its success rate in at most half its CPU time: then the cheapest "
        "such trial's (the "
        "one-standard-error rule of model selection, with training cost as simplicity)."
        + (
            f" Best: {describe_pick(pick, results[0], first['eval_episodes'])}." if complete else ""
        ),
        "",
        f"Command: `{command}`" if command else "",
        "",
        f"| trial | settings | {heads} | steps | crashes | lost | step limit | CPU hours |",
        "| --- | --- | " + "--- | " * len(budgets) + "--- | --- | --- | --- | --- |",
    ]
    for r in results:
        settings = ", ".join(f"{k}={v}" for k, v in r["values"].items())
        cells = " | ".join(
            f"{100 * r['by_budget'][str(b)]['success_rate']:.1f} % "
            f"({r['by_budget'][str(b)]['mean_reward']:.3f})"
            if str(b) in r["by_budget"]
            else ""
            for b in budgets
        )
        lines.append(
            f"| {r['id']} | {settings} | {cells} | {r['mean_steps']:.0f} | "
            f"{r['mean_crashes']:.2f} | {100 * r['lost_rate']:.1f} % | "
            f"{100 * r['timeout_rate']:.1f} % | {r['cpu_s'] / 3600:.2f} |"
        )
    machines = f" (trials trained on {cpus})" if (cpus := trained_on(results)) else ""
    lines += [
        "",
        "Each budget's cell: success rate (mean reward per step of the paper's reward). At the "
        "trial's furthest budget: steps and crashes, mean per episode; lost, step limit: the "
        "episodes that failed because too few pursuers were left or at the step limit; CPU "
        f"hours: its training's{machines}. `trials/<id>/progress.csv` is each trial's learning "
        "curve.",
    ]
    if beyond:
        lines += [
            "",
            "Scored at budgets outside this search's rounds (when the search had other rounds; "
            "not used to rank):",
            "",
            "| trial | env steps | success | steps | lost | step limit | CPU hours |",
            "| --- | --- | --- | --- | --- | --- | --- |",
        ]
        lines += [
            f"| {b['id']} | {b['env_steps']:,} | {100 * b['success_rate']:.1f} % | "
            f"{b['mean_steps']:.0f} | {100 * b['lost_rate']:.1f} % | "
            f"{100 * b['timeout_rate']:.1f} % | {b['cpu_s'] / 3600:.2f} |"
            for b in beyond
        ]
    if write_curves(out, results, budgets, beyond):
        lines += [
            "",
            "![learning curves](curves.png)",
            "",
            "`curves.png`: each scored trial's success rate over its training episodes (lines, "
            "one point per log row of `progress.csv`: exploration noise on, the training "
            "protocol's rules; under the `pes` protocol the first rows are the demonstrator's "
            "episodes) and on the held-out episodes at each budget it reached (dots"
            + ("; hollow: outside this search's rounds)." if beyond else ")."),
        ]
    (out / "README.md").write_text("\n".join(lines) + "\n")
    return {**summary, "out": str(out)}


def describe_pick(pick: dict, top: dict, eval_episodes: int) -> str:
    """One line on the trial :func:`chosen` picked, against the top-ranked trial ``top``."""
    if pick is top:
        return f"{pick['id']}, the top trial"
    p = top["success_rate"]
    error = 100 * success_error(p, eval_episodes)
    return (
        f"{pick['id']} ({100 * pick['success_rate']:.1f} %), within one standard error "
        f"({error:.1f} points over {eval_episodes} episodes) of {top['id']}'s "
        f"{100 * p:.1f} % in {pick['cpu_s'] / top['cpu_s']:.2f} of its CPU time"
    )


def other_budgets(out: Path, specs: list[dict], budgets: list[int]) -> list[dict]:
    """The scores of ``specs``' trials at env-step budgets that are not rounds of this search
    (``result-<env_steps>.json`` kept from a search of other rounds), by trial and budget."""
    found = []
    for spec in specs:
        for path in (Path(out) / "trials" / spec["id"]).glob("result-*.json"):
            record = json.loads(path.read_text())
            if record["env_steps"] in budgets or not same_trial(record["spec"], spec):
                continue
            ev = record["eval"]
            found.append(
                {
                    "id": spec["id"],
                    "env_steps": record["env_steps"],
                    "success_rate": ev["success_rate"],
                    "mean_steps": ev["mean_steps"],
                    "lost_rate": ev["lost_rate"],
                    "timeout_rate": ev["timeout_rate"],
                    "cpu_s": record["train"]["cpu_s"],
                }
            )
    return sorted(found, key=lambda b: (b["id"], b["env_steps"]))


def write_curves(
    out: Path, results: list[dict], budgets: list[int], beyond: list[dict] = ()
) -> bool:
    """``OUT/curves.png``: the training success rate (%) of every scored trial over env steps,
    from its copied ``progress.csv``, with its held-out success rate at each budget it reached
    as dots (hollow: the scores outside the search's rounds, ``beyond``, from
    :func:`other_budgets`) and the budgets as dashed lines; False (no figure, none left from
    before) when no trial has logged a row."""
    logs = {}
    for r in results:
        log = out / "trials" / r["id"] / "progress.csv"
        if log.is_file():
            data = read_progress(log)
            if data.size and {"env_steps", "success_rate"} <= set(data.dtype.names or ()):
                logs[r["id"]] = data
    if not logs:
        (out / "curves.png").unlink(missing_ok=True)
        return False
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    fig, ax = plt.subplots(figsize=(8, 4.8))
    for r in results:
        if r["id"] not in logs:
            continue
        data = logs[r["id"]]
        (line,) = ax.plot(
            data["env_steps"], 100 * data["success_rate"], lw=1.2, label=r["id"], alpha=0.85
        )
        held = sorted((int(b), v["success_rate"]) for b, v in r["by_budget"].items())
        ax.plot(
            [b for b, _ in held],
            [100 * v for _, v in held],
            "o",
            color=line.get_color(),
            markeredgecolor="black",
            markeredgewidth=0.5,
        )
        further = [b for b in beyond if b["id"] == r["id"]]
        if further:
            ax.plot(
                [b["env_steps"] for b in further],
                [100 * b["success_rate"] for b in further],
                "o",
                color=line.get_color(),
                markerfacecolor="none",
            )
    for b in budgets:
        ax.axvline(b, color="grey", ls="--", lw=0.8)
    ax.set_xlabel("env steps")
    ax.set_ylabel("success rate (%)")
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, ncol=2, title="trial (line: training; dot: held-out)")
    fig.tight_layout()
    fig.savefig(out / "curves.png", dpi=110)
    plt.close(fig)
    return True
