"""How long the quick reproduction of Table IV takes, from the trials it has already run.

    python benchmarks/reproduction_time.py     # writes benchmarks/results/reproduction_time.json
    python benchmarks/reproduction_time.py --cores 4 --source maac=results/quick --out /tmp/t.json

Every trial of ``pes reproduce table4`` leaves ``trials/<method>-s<seed>/done.json``: the CPU
seconds of its training (``train.cpu_s``, one torch thread) and the wall seconds of the whole
trial (``seconds_this_run``, whose rest beyond the training's ``wall_s`` is its 1000-episode
evaluation). This script reads them for every method of Table IV, each from the folder whose
trials ran its current preset (``--source``), and adds them up: the CPU hours of all trials
(``--seeds`` per method; a method with fewer finished seeds counts the missing ones at the
mean of its finished ones, and says so), and the hours a machine of ``--cores`` cores takes
running that many trials at a time, longest first. A trial resumed after an interruption counts
its whole training (``cpu_s`` is carried across resumptions) but only its last run's
evaluation, which is why the evaluation is taken as ``seconds_this_run - wall_s`` only where
that is positive.

Progress goes to stderr; the JSON object to stdout and to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SOURCES = {
    "pid-pf": "results/quick",
    "ppo": "results/quick_current",
    "mappo": "results/quick_current",
    "ddpg": "results/quick_current",
    "maddpg": "results/quick",
    "bicnet": "results/quick_current",
    "maac": "results/quick_current",
    "cbc": "results/quick",
    "cbc-tp": "results/quick_current",
}
"""Where each method's trials of its current quick preset are (docs/reproduce.md, "Budgets")."""


def trial_seconds(done: dict) -> tuple[float, float]:
    """(training CPU seconds, evaluation wall seconds) of one finished trial's ``done.json``."""
    train = done.get("train")
    if train is None:  # a scripted method: the trial is its evaluation
        return 0.0, float(done["seconds_this_run"])
    return float(train["cpu_s"]), max(0.0, float(done["seconds_this_run"]) - float(train["wall_s"]))


def method_trials(method: str, folder: Path, seeds: int) -> dict:
    """The finished trials of ``method`` under ``folder/trials`` (seeds 0 to ``seeds - 1``):
    each one's training CPU minutes and evaluation seconds, and how many were missing."""
    found = []
    for seed in range(seeds):
        done = folder / "trials" / f"{method}-s{seed}" / "done.json"
        if done.is_file():
            cpu_s, eval_s = trial_seconds(json.loads(done.read_text()))
            found.append(
                {"seed": seed, "train_cpu_min": round(cpu_s / 60, 1), "eval_s": round(eval_s)}
            )
    if not found:
        raise SystemExit(f"error: no finished trial of {method} under {folder / 'trials'}")
    return {
        "folder": str(folder.relative_to(ROOT)) if folder.is_relative_to(ROOT) else str(folder),
        "trials": found,
        "missing_seeds": seeds - len(found),
    }


def schedule(durations: list[float], cores: int) -> float:
    """The time (same unit as ``durations``) that ``cores`` trials at a time take, each next
    trial (longest first) starting on the core that frees first."""
    load = [0.0] * cores
    for d in sorted(durations, reverse=True):
        load[load.index(min(load))] += d
    return max(load)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=3, help="seeds per method (default 3)")
    parser.add_argument("--cores", type=int, default=2, help="trials at a time (default 2)")
    parser.add_argument(
        "--source",
        nargs="*",
        default=[],
        metavar="METHOD=FOLDER",
        help="read METHOD's trials from FOLDER instead (relative to the repository)",
    )
    parser.add_argument(
        "--out", type=Path, default=ROOT / "benchmarks/results/reproduction_time.json"
    )
    args = parser.parse_args(argv)
    sources = dict(SOURCES)
    for item in args.source:
        method, sep, folder = item.partition("=")
        if not sep or method not in SOURCES:
            parser.error(
                f"--source takes METHOD=FOLDER, METHOD one of {', '.join(SOURCES)}; got {item!r}"
            )
        sources[method] = folder
    methods, durations = {}, []
    for method, folder in sources.items():
        record = method_trials(method, ROOT / folder, args.seeds)
        trials = record["trials"]
        minutes = [t["train_cpu_min"] + t["eval_s"] / 60 for t in trials]
        mean = statistics.mean(minutes)
        durations += minutes + [mean] * record["missing_seeds"]
        record["mean_trial_min"] = round(mean, 1)
        methods[method] = record
        print(f"{method}: {len(trials)} trial(s), {mean:.1f} min each on average", file=sys.stderr)
    result = {
        "seeds": args.seeds,
        "cores": args.cores,
        "methods": methods,
        "total_cpu_h": round(sum(durations) / 60, 2),
        "hours_on_cores": round(schedule(durations, args.cores) / 60, 2),
        "estimated_trials": sum(m["missing_seeds"] for m in methods.values()),
    }
    text = json.dumps(result, indent=1)
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text + "\n")
    return result


if __name__ == "__main__":
    main()
