"""Why do BenchMARL's IPPO and MAPPO diverge on PES? Their logs and last checkpoints.

    python research/probes/benchmarl_ppo_saturation.py results/benchmarl/ippo-s0 \\
        results/benchmarl/mappo-s0 results/benchmarl/mappo-s1 results/benchmarl/mappo-s2 \\
        --out results/benchmarl/ppo_saturation.json

For each reference run folder (``python -m pes.benchmarl.reference``): from BenchMARL's CSV
logs, the policy's entropy estimate (``train_pursuers_entropy``) by frames, the frames where it
first exceeds 100, and the policy loss and its gradient norm over the last iterations. From
every checkpoint still in the folder (checkpoints are not committed: only on the machine that
trained the run), the policy's pre-tanh Gaussian on the first observations of 200 evaluation
games (``eval_config``, seed 5): the median |mean| and the median scale of each action axis
over games and pursuers, and the share of deterministic actions (tanh of the mean) beyond
0.99 in magnitude. Writes one JSON object (the command, then each run's figures). The
report: research/benchmarl_ppo_divergence.md.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from pathlib import Path

import torch
from benchmarl.experiment.callback import Callback
from torchrl.envs.utils import ExplorationType, set_exploration_type

import pes
from pes.benchmarl.reload import load_benchmarl_policy
from pes.experiments.budgets import BUDGETS, eval_config
from pes.torchrl import GROUP


class CpuClock(Callback):
    """Runs made before the reference command ran through its importable module pickled their
    callback as ``__main__.CpuClock``: this name lets their config.pkl load here."""


def _column(scalars: Path, name: str) -> dict[int, float | None]:
    """Iteration -> value (None where the log holds NaN or infinity). A run resumed from a
    checkpoint logs its repeated iterations twice: the later attempt's values are kept."""
    with open(scalars / f"{name}.csv") as f:
        rows = {int(row[0]): float(row[1]) for row in csv.reader(f)}
    return {i: v if math.isfinite(v) else None for i, v in rows.items()}


def logs(run: Path) -> dict:
    (scalars,) = run.glob("*/*/scalars")
    frames = _column(scalars, "counters_total_frames")
    entropy = _column(scalars, "train_pursuers_entropy")
    loss = _column(scalars, "train_pursuers_loss_objective")
    grad = _column(scalars, "train_pursuers_grad_norm_loss_objective")
    finite = [(frames[i], v) for i, v in entropy.items() if v is not None]
    every = max(1, len(finite) // 10)
    last = sorted(loss)[-6:]
    return {
        "entropy_by_frames": [(int(f), round(v, 1)) for f, v in finite[::every]],
        "entropy_last": [int(finite[-1][0]), round(finite[-1][1], 1)],
        "entropy_first_over_100_at": next((int(f) for f, v in finite if v > 100), None),
        "policy_loss_last": [[int(frames[i]), loss[i]] for i in last],
        "grad_norm_last": [[int(frames[i]), grad[i]] for i in last],
    }


def checkpoints(run: Path) -> dict:
    cfg = eval_config(BUDGETS["quick"])
    env = pes.make_env(cfg, num_envs=200, seed=5)
    obs, info = env.reset(seed=5)
    found = {}
    for path in sorted(run.glob("*/checkpoints/checkpoint_*.pt")):
        policy = load_benchmarl_policy(path, cfg)
        with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
            out = policy.module(policy.tensordict(obs, info))
        loc, scale, action = (out[GROUP, k].flatten(0, 1) for k in ("loc", "scale", "action"))
        found[path.stem] = {
            "median_abs_mean_per_axis": [round(v, 2) for v in loc.abs().median(0).values.tolist()],
            "median_scale_per_axis": [round(v, 2) for v in scale.median(0).values.tolist()],
            "share_action_beyond_0.99_per_axis": (action.abs() > 0.99).float().mean(0).tolist(),
        }
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    torch.set_num_threads(1)
    report = {
        "command": " ".join(
            ["python", "research/probes/benchmarl_ppo_saturation.py", *sys.argv[1:]]
        ),
        "runs": {str(run): {**logs(run), "checkpoints": checkpoints(run)} for run in args.runs},
    }
    text = json.dumps(report, indent=1, allow_nan=False)
    args.out.write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
