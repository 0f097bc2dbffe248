"""Choose the evader snapshot that matches the paper's calibration anchor.

    pes train --algo evader-ddpg --set threads=1 --set snapshots=true --set log_every=25 \
        --set time_limit=7 --set eval_episodes=0 --out runs/evader-snap
    python scripts/pick_evader.py runs/evader-snap --out results/evader_snapshots.json

The paper gives one number for the strength of its frozen DDPG evader: PID(PF) captures it in
27.3 % of the episodes (Table IV, disturbance on). This script evaluates PID(PF) against every
snapshot of an evader run (``snapshots=true`` keeps the policy of every log row) with the same
protocol (``--episodes`` episodes, disturbance on, ``crash_mode="disable"``, one seed), writes
every snapshot's figures to ``--out`` and prints the snapshot closest to ``--target``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from pes.evaluate import evaluate  # noqa: E402
from pes.policies import PIDPotentialField  # noqa: E402
from pes.sim.config import EnvConfig  # noqa: E402

PAPER_PID_PF_SUCCESS = 0.273
"""PID(PF)'s success rate against the paper's DDPG evader (Table IV)."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="an evader-ddpg run trained with snapshots=true")
    parser.add_argument("--out", type=Path, required=True, help="JSON file of every snapshot")
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--target", type=float, default=PAPER_PID_PF_SUCCESS)
    parser.add_argument("--min-episode", type=int, default=0, help="skip earlier snapshots")
    parser.add_argument("--max-episode", type=int, default=10**9, help="skip later snapshots")
    args = parser.parse_args()
    torch.set_num_threads(2)

    snapshots = sorted((args.run / "snapshots").glob("ep*.pt"))
    if not snapshots:
        sys.exit(f"error: no snapshots in '{args.run / 'snapshots'}' (train with snapshots=true)")
    base = EnvConfig().for_evaluation(evader_policy="ddpg")
    pid = PIDPotentialField(base)
    rows = []
    for path in snapshots:
        episode = int(path.stem[2:])
        if not args.min_episode <= episode <= args.max_episode:
            continue
        cfg = base.replace(evader_model=str(path))
        result = evaluate(
            pid, cfg, episodes=args.episodes, num_envs=args.episodes, seed=args.seed, progress=False
        )
        row = {"snapshot": str(path), "episode": episode, **result.summary()}
        rows.append(row)
        print(
            f"{path.name}: PID(PF) success {100 * row['success_rate']:.1f} %, "
            f"{row['mean_steps']:.0f} steps",
            flush=True,
        )
    best = min(rows, key=lambda r: (abs(r["success_rate"] - args.target), -r["episode"]))
    report = {
        "protocol": {
            "pursuers": "pid-pf",
            "episodes": args.episodes,
            "seed": args.seed,
            "disturbance": True,
            "crash_mode": "disable",
        },
        "target_success_rate": args.target,
        "chosen": best["snapshot"],
        "snapshots": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"closest to {100 * args.target:.1f} %: {best['snapshot']}")


if __name__ == "__main__":
    main()
