"""The evaluation harness: run a pursuer policy for a fixed number of episodes and measure it.

Episodes run in a batch of environments. Each environment is given a fixed share of the
episodes in advance (environment ``i`` plays episodes ``i, i + E, i + 2E, ...``), so that the
result does not favour short episodes and is the same for the same seed whatever the speed of
the machine.

Metrics (as ``pes eval`` reports them, docs/cli.md): ``success_rate`` (captures / episodes),
``mean_steps`` (mean episode length over all episodes, failures at the limit included),
``mean_reward`` ("average reward": each episode's total reward divided by its steps, averaged
over episodes; the total reward of a step is the mean over the pursuers alive at its start). A
failure is either ``lost`` (fewer pursuers left alive than the capture needs: the episode ends
early) or ``timeout`` (the evader still free at the step limit); ``lost_rate`` and
``timeout_rate`` split the failures so.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from pes.errors import ConfigError
from pes.policies.base import Policy
from pes.sim.config import EnvConfig
from pes.sim.env import make_env


@dataclass
class EvalResult:
    """What :func:`evaluate` measured. ``per_episode`` holds the lists ``success``,
    ``steps``, ``reward``, ``crashes`` and ``outcome`` (``capture``, ``lost``, ``timeout``)
    in episode order."""

    episodes: int
    success_rate: float
    mean_steps: float
    mean_reward: float
    success_steps: float
    """Mean length of the successful episodes (NaN if none)."""
    mean_crashes: float
    """Mean pursuer crashes per episode."""
    lost_rate: float
    """Share of the episodes failed by losing the swarm (too few pursuers left to capture)."""
    timeout_rate: float
    """Share of the episodes failed by reaching the step limit."""
    success_rate_ci95: float
    """Half-width of the 95 % normal-approximation interval of the success rate."""
    seed: int
    per_episode: dict[str, list] = field(default_factory=dict, repr=False)

    def summary(self) -> dict[str, Any]:
        """The scalar metrics as a JSON-friendly dict."""
        out = {k: v for k, v in asdict(self).items() if k != "per_episode"}
        return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in out.items()}


def success_error(rate: float, episodes: int) -> float:
    """The standard error of a success rate ``rate`` (a fraction) measured over ``episodes``
    independent episodes: sqrt(rate (1 - rate) / episodes), as a fraction."""
    return math.sqrt(rate * (1 - rate) / episodes)


def _outcome(info: dict, terminated: torch.Tensor, i: int) -> str:
    """How the finished episode of environment ``i`` ended: ``capture``, ``lost`` (too few
    pursuers alive) or ``timeout`` (the step limit)."""
    if bool(info["success"][i]):
        return "capture"
    return "lost" if bool(terminated[i]) else "timeout"


def _act_on(policy: Policy, obs: torch.Tensor, info: dict, rows: torch.Tensor) -> torch.Tensor:
    """The (E, N, 2) actions of a row-wise ``policy`` computed for the environments ``rows``
    (E,) bool only; the other environments get zero actions."""
    index = torch.nonzero(rows).flatten()
    sub_info = {
        k: v.index_select(0, index) if torch.is_tensor(v) and v.dim() and len(v) == len(rows) else v
        for k, v in info.items()
    }
    actions = torch.zeros(*obs.shape[:2], 2, device=obs.device)
    actions[index] = policy(obs.index_select(0, index), sub_info)
    return actions


def episode_quota(episodes: int, num_envs: int) -> torch.Tensor:
    """(num_envs,) long: how many of ``episodes`` each environment of :func:`evaluate` plays
    and counts (the first ``episodes % num_envs`` one more); it keeps stepping past its share
    while the others finish theirs."""
    quota = torch.full((num_envs,), episodes // num_envs, dtype=torch.long)
    quota[: episodes % num_envs] += 1
    return quota


def evaluate(
    policy: Policy,
    config: EnvConfig,
    episodes: int = 100,
    num_envs: int = 100,
    seed: int = 0,
    device: str = "cpu",
    compile: bool = False,
    progress: bool = False,
    on_step: Callable[[Any, dict], None] | None = None,
) -> EvalResult:
    """Run ``policy`` for ``episodes`` episodes of the scenario ``config``.

    Args:
        policy: a :class:`pes.policies.Policy`.
        config: the scenario (``config.for_evaluation()`` gives the paper's evaluation
            protocol: disturbance on, crashes disable, the paper's reward).
        episodes: number of episodes to measure.
        num_envs: environments stepped together (at most ``episodes``).
        seed: environment ``i`` is seeded ``seed + i``.
        progress: show a progress bar of finished episodes.
        on_step: called as ``on_step(env, info)`` after every step (for recorders).
    """
    if episodes < 1:
        raise ConfigError(f"episodes must be at least 1, got {episodes}")
    num_envs = max(1, min(num_envs, episodes))
    env = make_env(
        config, num_envs=num_envs, device=device, seed=seed, compile=compile, wait_kernels=True
    )
    quota = episode_quota(episodes, num_envs)
    finished = torch.zeros(num_envs, dtype=torch.long)
    slot = {"success": [], "steps": [], "reward": [], "crashes": [], "outcome": []}
    results = {k: [[] for _ in range(num_envs)] for k in slot}

    obs, info = env.reset(seed=seed)
    policy.reset(None)
    # A row-wise policy acts only for the environments still playing their share: the others
    # step on, idle, while the slowest finish (most of the work of a long tail).
    subset = bool(getattr(policy, "row_wise", False)) and on_step is None
    reward_sum = torch.zeros(num_envs, device=env.device)
    bar = tqdm(total=episodes, desc="episodes", unit="ep", disable=not progress, leave=False)
    with torch.inference_mode():
        while bool((finished < quota).any()):
            alive = info["obs_mask"][:, :, 0].float()  # pursuers alive at the step start
            playing = finished < quota
            if subset and not bool(playing.all()):
                actions = _act_on(policy, obs, info, playing.to(env.device))
            else:
                actions = policy(obs, info)
            obs, reward, terminated, truncated, info = env.step(actions)
            team = (reward * alive).sum(-1) / alive.sum(-1).clamp(min=1.0)
            reward_sum += team
            if on_step is not None:
                on_step(env, info)
            done = terminated | truncated
            if bool(done.any()):
                for i in torch.nonzero(done).flatten().tolist():
                    if finished[i] < quota[i]:
                        steps = int(info["steps"][i])
                        results["success"][i].append(bool(info["success"][i]))
                        results["steps"][i].append(steps)
                        results["reward"][i].append(float(reward_sum[i]) / steps)
                        results["crashes"][i].append(int(info["crashes"][i]))
                        results["outcome"][i].append(_outcome(info, terminated, i))
                        finished[i] += 1
                        bar.update(1)
                reward_sum = torch.where(done, 0.0, reward_sum)
                policy.reset(done)
    bar.close()

    # Episode order: round j of every environment in turn (episode i + j * E).
    per_episode = {k: [] for k in slot}
    for j in range(int(quota.max())):
        for i in range(num_envs):
            if j < len(results["success"][i]):
                for k in slot:
                    per_episode[k].append(results[k][i][j])
    success = np.array(per_episode["success"], dtype=float)
    steps = np.array(per_episode["steps"], dtype=float)
    rate = float(success.mean())
    outcomes = per_episode["outcome"]
    return EvalResult(
        episodes=len(success),
        success_rate=rate,
        mean_steps=float(steps.mean()),
        mean_reward=float(np.mean(per_episode["reward"])),
        success_steps=float(steps[success > 0].mean()) if success.any() else float("nan"),
        mean_crashes=float(np.mean(per_episode["crashes"])),
        lost_rate=outcomes.count("lost") / len(outcomes),
        timeout_rate=outcomes.count("timeout") / len(outcomes),
        success_rate_ci95=float(1.96 * success_error(rate, len(success))),
        seed=seed,
        per_episode=per_episode,
    )
