"""How often a swarm's pursuers fly at a wall faster than they could brake, and whether that
precedes its crashes (the measurement behind ``env.approach_weight``).

    python results/training/cbc_tp_paper_evader/crash_excess.py POLICY [POLICY ...]

For each policy: 200 episodes (seed 10000, disturbance on, crashes disable, the default
evader), each environment's first episode only. The excess of a pursuer on a step is its speed
towards its nearest obstacle minus sqrt(2 x 2.5 m/s^2 x its gap to it), floored at 0 (m/s):
what ``approach_weight`` charges. Prints the share of alive pursuer-steps with an excess and,
over the crashes, the largest excess of the crashing pursuer in the five steps before.
"""

import sys

import numpy as np
import torch

from pes.algos.loading import load_pursuer_policy
from pes.evaluate import evaluate
from pes.sim import scenario
from pes.sim.config import EnvConfig


def measure(path: str, cfg: EnvConfig, episodes: int = 200, seed: int = 10000) -> str:
    """One line of figures for the policy at ``path``."""
    n = cfg.num_pursuers
    policy, _ = load_pursuer_policy(path, cfg)
    rec: dict[str, list] = {"excess": [], "crashed": [], "alive": [], "ended": []}

    def on_step(env, info):
        v, _, _ = scenario.unpack(env.state)
        gap = v.obstacle_dist[:, :n]
        vel = info["velocities"][:, :n]
        toward = (vel[..., 0] * v.obstacle_dx[:, :n] + vel[..., 1] * v.obstacle_dy[:, :n]) / gap
        brake = torch.sqrt(2 * cfg.approach_decel * (gap - cfg.body_radius).clamp(min=0))
        rec["excess"].append((toward - brake).clamp(min=0))
        rec["crashed"].append(info["crashed"].clone())
        rec["alive"].append(info["alive"].clone())
        rec["ended"].append(
            info["success"]
            | (info["steps"] >= cfg.max_steps)
            | (info["alive"].sum(-1) < cfg.capture_count)
        )

    evaluate(policy, cfg, episodes=episodes, num_envs=episodes, seed=seed, on_step=on_step)
    ex, cr, al, end = (torch.stack(rec[k]).numpy() for k in ("excess", "crashed", "alive", "ended"))
    # Finished environments step on into a new episode: keep each one's first.
    first = (np.arange(len(end))[:, None] <= end.argmax(0)[None, :])[..., None]
    al, cr = al & first, cr & first
    before = np.array(
        [ex[max(0, t - 5) : t, e, i].max(initial=0.0) for t, e, i in zip(*cr.nonzero())]
    )
    return (
        f"{path}: {(ex[al] > 0).mean():.1%} of alive pursuer-steps with an excess; "
        f"{len(before)} crashes, {(before > 0).mean():.0%} after one (median largest excess "
        f"over the 5 steps before: {np.median(before):.1f} m/s)"
    )


if __name__ == "__main__":
    torch.set_num_threads(1)
    config = EnvConfig().for_evaluation(evader_policy="ddpg")
    for policy_path in sys.argv[1:]:
        print(measure(policy_path, config))
