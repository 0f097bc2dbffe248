"""Does this machine spend the CPU time a committed run spent? A check before a run budgeted in
CPU minutes (`cpu_limit`, e.g. Table IV at equal compute) joins runs made elsewhere.

    python benchmarks/host_speed.py          # benchmarks/results/host_speed.json

It trains a committed run again from its `config.yaml` (the same seed and settings) for its
first ``--env-steps`` env steps on one torch thread, in a temporary folder, and compares the CPU
time that took with the run's own `progress.csv` over the same log rows: those after the
demonstrator has stopped playing (its `demonstrating` column 0), where the learner's own
updates set the cost, from the first such row on (so that compiling the simulator's step is
left out too). The replay does the run's work (the same update counts at every row,
``same_work``), so the ratio ``cpu_ratio`` (here / then) measures the machine alone: near 1 on
the CPU the run trained on; virtual machines may name CPUs that differ by 1.5x alike ("AMD
EPYC"). ``replayed`` says whether it is also the same training to the bit (the same training
success at every row as well); CPUs with other vector instructions may round differently and
part from it without changing the work. Run it with nothing else on the machine, or with as
many other jobs as the compared run had beside it.

    python benchmarks/host_speed.py --run A --against B --out /tmp/ratio.json

reads two runs of the same settings instead (B another seed of A, perhaps on another CPU) and
compares their CPU time per env step over the env steps both logged after the demonstrations
(each log's ``cpu_s`` interpolated at that stretch's ends), with each run's updates per env step
there (the same settings do the same work per env step): the ratio that ``cpu_scale`` takes when
B, trained on a slower CPU, resumes to the work of A's ``cpu_limit`` (docs/training.md).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from pes.experiments.report import read_progress
from pes.sim.bench import machine_info

DEFAULT_RUN = "results/quick_current/trials/bicnet-s0/run"


def log_rows(progress: Path) -> list[dict[str, float]]:
    """The rows of a run's ``progress.csv`` as numbers: env_steps, updates, cpu_s, success_rate
    and demonstrating (0 in logs older than that column)."""
    rows = read_progress(progress)
    keys = ["env_steps", "updates", "cpu_s", "success_rate"]
    keys += ["demonstrating"] if "demonstrating" in rows.dtype.names else []
    return [{"demonstrating": 0.0} | {k: float(row[k]) for k in keys} for row in rows]


def replay(run: Path, env_steps: int, folder: Path) -> list[dict[str, float]]:
    """Train ``run``'s config.yaml again for ``env_steps`` env steps into ``folder`` on one torch
    thread; its log rows."""
    algo = next(
        line.split(":", 1)[1].strip()
        for line in (run / "config.yaml").read_text().splitlines()
        if line.startswith("algo:")
    )
    command = [sys.executable, "-m", "pes.cli", "train", "--algo", algo, "--config"]
    command += [str(run / "config.yaml"), "--out", str(folder), "--json"]
    for key, value in (
        ("env_steps", env_steps),
        ("threads", 1),
        ("eval_episodes", 0),
        ("tensorboard", "false"),
        ("checkpoint_every", 1e6),
    ):
        command += ["--set", f"{key}={value}"]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    subprocess.run(command, check=True, env=env, stdout=subprocess.DEVNULL)
    return log_rows(folder / "progress.csv")


def compare(then: list[dict[str, float]], here: list[dict[str, float]]) -> dict:
    """The CPU time of the rows both logs have after the demonstrations, from their first to
    their last; whether the replay did the run's work (the same updates at every such row) and
    whether it is the run's training (the same training success as well)."""
    by_steps = {row["env_steps"]: row for row in then if not row["demonstrating"]}
    shared = [(by_steps[row["env_steps"]], row) for row in here if row["env_steps"] in by_steps]
    if len(shared) < 2:
        raise SystemExit(
            "host_speed: the replay and the run share fewer than two log rows after the "
            "demonstrations; replay more env steps (--env-steps)"
        )
    (first_then, first_here), (last_then, last_here) = shared[0], shared[-1]
    cpu_then = last_then["cpu_s"] - first_then["cpu_s"]
    cpu_here = last_here["cpu_s"] - first_here["cpu_s"]
    same_work = all(a["updates"] == b["updates"] for a, b in shared)
    same_success = all(abs(a["success_rate"] - b["success_rate"]) < 1e-9 for a, b in shared)
    return {
        "env_steps": [int(first_here["env_steps"]), int(last_here["env_steps"])],
        "cpu_s_then": round(cpu_then, 1),
        "cpu_s_here": round(cpu_here, 1),
        "cpu_ratio": round(cpu_here / cpu_then, 3),
        "same_work": same_work,
        "replayed": same_work and same_success,
    }


def against(then: list[dict[str, float]], here: list[dict[str, float]]) -> dict:
    """``here``'s CPU time per env step over ``then``'s (two runs of the same settings, each
    seed its own log rows) over the env steps both logged after the demonstrations, and each
    run's updates per env step there."""
    own = [[row for row in rows if not row["demonstrating"]] for rows in (then, here)]
    if not all(own):
        raise SystemExit("host_speed: a run logged no row after the demonstrations")
    start = max(rows[0]["env_steps"] for rows in own)
    end = min(rows[-1]["env_steps"] for rows in own)
    if end <= start:
        raise SystemExit(
            "host_speed: the two runs share no stretch of env steps after the demonstrations"
        )

    def gained(rows: list[dict[str, float]], key: str) -> float:
        steps = [row["env_steps"] for row in rows]
        values = [row[key] for row in rows]
        return float(np.interp(end, steps, values) - np.interp(start, steps, values))

    cpu_then, cpu_here = gained(own[0], "cpu_s"), gained(own[1], "cpu_s")
    return {
        "env_steps": [int(start), int(end)],
        "cpu_s_then": round(cpu_then, 1),
        "cpu_s_here": round(cpu_here, 1),
        "cpu_ratio": round(cpu_here / cpu_then, 3),
        "updates_per_env_step": [
            float(f"{gained(rows, 'updates') / (end - start):.4g}") for rows in own
        ],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--run", default=DEFAULT_RUN, help=f"a committed run (default {DEFAULT_RUN})"
    )
    parser.add_argument(
        "--env-steps", type=int, default=300_000, help="env steps to replay (default 300,000)"
    )
    parser.add_argument(
        "--against",
        default=None,
        help="another run of the same settings: compare the two logs, replay nothing",
    )
    parser.add_argument("--out", default="benchmarks/results/host_speed.json")
    args = parser.parse_args()
    run = Path(args.run)
    if not (run / "config.yaml").is_file() or not (run / "progress.csv").is_file():
        raise SystemExit(f"host_speed: {run} holds no config.yaml and progress.csv")
    command = "python benchmarks/host_speed.py " + " ".join(sys.argv[1:])
    if args.against is not None:
        other = Path(args.against)
        if not (other / "progress.csv").is_file():
            raise SystemExit(f"host_speed: {other} holds no progress.csv")
        then, here = log_rows(run / "progress.csv"), log_rows(other / "progress.csv")
        result = {"run": str(run), "against": str(other), **against(then, here)}
    else:
        with tempfile.TemporaryDirectory() as tmp:
            here = replay(run, args.env_steps, Path(tmp) / "run")
        result = {
            "machine": machine_info(),
            "run": str(run),
            **compare(log_rows(run / "progress.csv"), here),
        }
    result["command"] = command
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
