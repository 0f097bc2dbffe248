"""Where and why a pursuer policy crashes: every crash of an evaluation, summarised.

    python scripts/crash_sites.py cbc-tp --episodes 1000 --out results/crash_sites_cbc_tp.json

Runs ``--episodes`` episodes under the paper's protocol (disturbance on, crashes disable)
against the default DDPG evader and records, for every crash, the step, where it happened,
the pursuer's speed and distance to the evader on the step before, and whether a building
stood between the crash site and the evader (the straight line from one to the other crosses
it). Prints and writes (``--out``) a JSON summary: the evaluation's figures, the share of the
crashes with the evader hidden behind a building, before step 50, against the arena wall,
quantiles of distance, speed and step, and a 10 x 10 map of the crash sites (10 m cells, row 0
the arena's north edge).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from pes.algos.loading import load_pursuer_policy  # noqa: E402
from pes.evaluate import episode_quota, evaluate  # noqa: E402
from pes.models import default_evader_policy  # noqa: E402
from pes.sim.config import EnvConfig  # noqa: E402
from pes.sim.geometry import segment_clear  # noqa: E402

WALL_BAND = 0.6  # m: a crash site this close to the arena's border is a crash into its wall
EARLY = 50  # steps


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy", help="a run folder, policy file or shipped name (cbc-tp)")
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--num-envs", type=int, default=500)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path, help="write the summary here (JSON)")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    config = EnvConfig(evader_policy=default_evader_policy()).for_evaluation()
    policy, _ = load_pursuer_policy(args.policy, config)
    crashes: list[dict] = []
    before: dict[str, torch.Tensor] = {}
    # Count each environment's episodes and keep the crashes of the ones evaluate() counts.
    num_envs = max(1, min(args.num_envs, args.episodes))
    quota = episode_quota(args.episodes, num_envs)
    episode = torch.full((num_envs,), -1)

    def on_step(env, info) -> None:
        episode.add_((info["steps"] == 1).long())  # the first step of an episode
        counted = info["crashed"] & (episode < quota)[:, None]
        if before and bool(counted.any()):
            boxes = env.scenario.boxes
            for e, i in torch.nonzero(counted).tolist():
                site, evader = info["positions"][e, i], info["positions"][e, -1]
                crashes.append(
                    {
                        "step": int(info["steps"][e]),
                        "x": float(site[0]),
                        "y": float(site[1]),
                        "speed": float(before["velocities"][e, i].norm()),
                        "distance": float(before["distances"][e, i]),
                        "hidden": not bool(segment_clear(site, evader, boxes)),
                        "wall": bool(min(site.min(), *(env.scenario.arena - site)) < WALL_BAND),
                    }
                )
        before["velocities"] = info["velocities"].clone()
        before["distances"] = info["distances"].clone()

    result = evaluate(
        policy, config, args.episodes, num_envs, seed=args.seed, on_step=on_step
    ).summary()
    if not crashes:
        summary = {"evaluation": result, "crashes": 0}
    else:
        col = {k: np.array([c[k] for c in crashes], dtype=float) for k in crashes[0]}
        quantiles = [0.1, 0.25, 0.5, 0.75, 0.9]
        cells, _, _ = np.histogram2d(
            col["x"], col["y"], bins=10, range=[[0, config.arena_width], [0, config.arena_height]]
        )
        summary = {
            "evaluation": result,
            "crashes": len(crashes),
            "share_evader_hidden": round(float(col["hidden"].mean()), 3),
            f"share_before_step_{EARLY}": round(float((col["step"] < EARLY).mean()), 3),
            f"share_hidden_before_step_{EARLY}": round(
                float(col["hidden"][col["step"] < EARLY].mean()), 3
            ),
            "share_arena_wall": round(float(col["wall"].mean()), 3),
            "quantiles": quantiles,
            "distance_to_evader_m": np.quantile(col["distance"], quantiles).round(1).tolist(),
            "speed_m_s": np.quantile(col["speed"], quantiles).round(1).tolist(),
            "step": np.quantile(col["step"], quantiles).round(0).tolist(),
            "map_10m_north_up": cells.T[::-1].astype(int).tolist(),
        }
    summary["command"] = "python scripts/crash_sites.py " + " ".join(argv or sys.argv[1:])
    text = json.dumps(summary, indent=2)
    if args.out:
        args.out.write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
