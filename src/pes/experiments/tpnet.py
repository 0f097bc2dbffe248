"""Table V: how well TP Net predicts the evader's next k = 1 ... 5 positions.

One trial (seed s):

1. plays ``tp_train_episodes`` episodes of the evaluation scenario (the shipped CBC-TP Net
   swarm, else PID(PF), against the shipped DDPG evader, disturbance on) and keeps every step's
   history frame;
2. trains a TP Net (Fig. 3, eq. 7: 2 LSTM layers, horizon 5) on all the (n = 10 frame window,
   next 5 evader positions) pairs of those episodes;
3. measures it on ``tp_test_episodes`` held-out episodes (other seeds): for each k, FDE(k) is
   the mean distance between the predicted and the true evader position k steps ahead and
   ADE(k) the mean of FDE(1) ... FDE(k).

Errors are in arena units (metres divided by the arena side, 100 m by default), the positions'
normalisation of Table I; we read the paper's "normalised error" the same way (its k = 1 error,
0.026, would be 2.6 m here). Windows whose future runs past the episode's end are left out.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from pes.algos.cbc_tp import TPNet
from pes.algos.loading import load_pursuer_policy
from pes.experiments.budgets import EVAL_SEED, eval_config
from pes.models import is_shipped
from pes.policies import PIDPotentialField
from pes.sim.env import make_env

HORIZON = 5
"""k = 1 ... 5, as Table V."""


def collect(policy, config, episodes: int, seed: int) -> list[torch.Tensor]:
    """Play ``episodes`` episodes; returns each episode's history frames (T + 1, A, 4), the
    frame after the reset first and the final frame last."""
    num_envs = min(episodes, 50)
    env = make_env(config, num_envs=num_envs, seed=seed, wait_kernels=True)
    obs, info = env.reset(seed=seed)
    policy.reset(None)
    current: list[list[torch.Tensor]] = [[info["history"][i, -1]] for i in range(num_envs)]
    finished: list[torch.Tensor] = []
    with torch.no_grad():
        while len(finished) < episodes:
            obs, _, terminated, truncated, info = env.step(policy(obs, info))
            done = terminated | truncated
            for i in range(num_envs):
                if bool(done[i]):
                    current[i].append(info["final_history"][i, -1])
                    finished.append(torch.stack(current[i]))
                    current[i] = [info["history"][i, -1]]
                else:
                    current[i].append(info["history"][i, -1])
            if bool(done.any()):
                policy.reset(done)
    return finished[:episodes]


def windows(episodes: list[torch.Tensor], history: int) -> tuple[torch.Tensor, torch.Tensor]:
    """All (window, future) pairs: windows (B, n, A, 4) zero-padded at the episode's start as the
    environment's ``info["history"]``, futures (B, 5, 2) the evader's next positions."""
    xs, ys = [], []
    for frames in episodes:
        steps = frames.shape[0]
        if steps <= HORIZON:
            continue
        padded = torch.cat([frames.new_zeros(history - 1, *frames.shape[1:]), frames])
        win = padded.unfold(0, history, 1).permute(0, 3, 1, 2)  # (steps, n, A, 4)
        evader = frames[:, -1, :2]
        fut = torch.stack([evader[j : steps - HORIZON + j] for j in range(1, HORIZON + 1)], 1)
        xs.append(win[: steps - HORIZON])
        ys.append(fut)
    return torch.cat(xs), torch.cat(ys)


def errors(pred: torch.Tensor, future: torch.Tensor) -> dict[str, list[float]]:
    """pred, future (B, 5, 2) -> FDE(k) and ADE(k) for k = 1 ... 5 (arena units)."""
    dist = (pred - future).norm(dim=-1)  # (B, 5)
    fde = dist.mean(0)
    ade = torch.stack([dist[:, : k + 1].mean() for k in range(HORIZON)])
    return {"fde": fde.tolist(), "ade": ade.tolist()}


def run_tpnet(spec: dict, budget, folder: Path) -> dict[str, Any]:
    """One Table V trial; returns (and the caller stores) its FDE / ADE."""
    seed = spec["seed"]
    cfg = eval_config(budget)
    if is_shipped("cbc-tp"):
        policy, pursuers = load_pursuer_policy("cbc-tp", cfg)[0], "cbc-tp"
    else:
        policy, pursuers = PIDPotentialField(cfg), "pid-pf"
    train_eps = collect(policy, cfg, budget.tp_train_episodes, seed=10_000 * seed)
    test_eps = collect(policy, cfg, budget.tp_test_episodes, seed=EVAL_SEED + 10_000 * seed)
    x, y = windows(train_eps, cfg.history_length)
    x_test, y_test = windows(test_eps, cfg.history_length)

    gen = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    net = TPNet(budget.tp_hidden, 2, HORIZON)
    opt = torch.optim.Adam(net.parameters(), lr=1e-3)
    batch = min(512, len(x))
    for _ in range(budget.tp_steps):
        idx = torch.randint(len(x), (batch,), generator=gen)
        loss = ((net(x[idx]) - y[idx]) ** 2).sum(-1).mean()  # eq. (7)
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():
        pred = torch.cat([net(x_test[i : i + 4096]) for i in range(0, len(x_test), 4096)])
        baseline = x_test[:, -1, -1, :2].unsqueeze(1).expand_as(y_test)  # "stays where it is"
    torch.save(net.state_dict(), folder / "tpnet.pt")
    return {
        "pursuers": pursuers,
        "train_windows": len(x),
        "test_windows": len(x_test),
        **errors(pred, y_test),
        "constant_position": errors(baseline, y_test),
    }
