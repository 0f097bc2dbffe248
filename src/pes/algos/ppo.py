"""PPO baseline (Table IV): proximal policy optimisation (Schulman et al., 2017) with GAE,
on-policy, collected from ``num_envs`` environments at once.

Each pursuer is an independent learner on its own Table I observation (IPPO): a Gaussian actor
and a value function V(o_i), both MLPs on the flattened observation
(:class:`pes.algos.nets.FlatObsMLP`). With ``shared=True`` (the default) all pursuers share
one actor and one value network, and every pursuer's samples train them (parameter sharing);
``shared=False`` gives each pursuer its own pair.

One update (``update()``, once per full rollout of ``rollout_steps`` vector steps):

1. advantages by GAE (gamma, ``gae_lambda``) per pursuer, cut where the episode ends or the
   pursuer dies; a truncated episode bootstraps from V of its final observation;
2. ``ppo_epochs`` passes over the rollout in minibatches of ``batch_size`` transitions (each
   with its N pursuer samples): the clipped surrogate (``clip_coef``) with per-minibatch
   normalised advantages, minus ``ent_coef`` times the entropy, and the squared error of V
   against the GAE returns; optional early stop at ``target_kl``.

Actions are sampled from N(mean, exp(log_std)) with a state-independent log_std, and clipped to
[-1, 1] for the environment (the log-probabilities are those of the unclipped samples, as
CleanRL's continuous PPO). Evaluation acts with the clipped mean. Dead pursuers (damaged ones,
``crash_mode="disable"``) are zero rows with a 0 flag in everyone's input, and their samples
are left out of every loss.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from pes.algos.buffer import RolloutBuffer, gae
from pes.algos.common import (
    ActorPolicy,
    StochasticActorLearner,
    gaussian_log_prob,
    masked_mean,
    optimise,
    pursuer_score,
)
from pes.algos.config import TrainConfig
from pes.algos.features import pursuer_obs
from pes.algos.nets import FlatObsMLP, PerAgent
from pes.sim.config import EnvConfig


class GaussianActor(nn.Module):
    """A diagonal Gaussian policy: mean from a :class:`FlatObsMLP`, log std a free parameter
    (independent of the state)."""

    def __init__(self, cfg: TrainConfig, num_pursuers: int) -> None:
        super().__init__()
        self.mean = FlatObsMLP(num_pursuers, cfg.hidden, 2, 2, cfg.obstacle_scale, cfg.target_scale)
        self.log_std = nn.Parameter(torch.full((2,), cfg.log_std_init))

    def forward(self, obs: Tensor, mask: Tensor) -> Tensor:
        """obs (B, N, 8), mask (B, N) -> (B, 4): mean (2) and log std (2)."""
        mean = self.mean(obs, mask)
        return torch.cat([mean, self.log_std.expand_as(mean)], dim=-1)


class PPOActors(nn.Module):
    """The pursuers' Gaussian actors (shared or one each), on observations (B, N, N, 8)."""

    def __init__(self, cfg: TrainConfig, num_pursuers: int) -> None:
        super().__init__()
        self.nets = PerAgent(lambda: GaussianActor(cfg, num_pursuers), num_pursuers, cfg.shared)

    def forward(self, obs: Tensor, mask: Tensor) -> tuple[Tensor, Tensor]:
        """obs (B, N, N, 8), mask (B, N, N) -> mean and log std, each (B, N, 2)."""
        out = self.nets(obs, mask)
        return out[..., :2], out[..., 2:]

    def mean_action(self, obs: Tensor, mask: Tensor) -> Tensor:
        """(B, N, 2) deterministic actions: the mean, clipped to [-1, 1]."""
        return self(obs, mask)[0].clamp(-1.0, 1.0)


class PPO(StochasticActorLearner):
    """The PPO learner (independent learners, parameter-shared by default)."""

    name = "ppo"
    Actor = PPOActors
    on_policy = True

    def __init__(self, cfg: TrainConfig, env_cfg: EnvConfig, device: torch.device) -> None:
        self.cfg = cfg
        self.n = n = env_cfg.num_pursuers
        self.max_steps = env_cfg.max_steps
        self.device = device
        self.actor = self.Actor(cfg, n).to(device)
        self.value = PerAgent(
            lambda: FlatObsMLP(n, cfg.hidden, 1, 2, cfg.obstacle_scale, cfg.target_scale),
            n,
            cfg.shared,
        ).to(device)
        self.policy = ActorPolicy(self.actor)
        self.opt_actor = torch.optim.Adam(self.actor.parameters(), lr=cfg.lr_actor, eps=1e-5)
        self.opt_critic = torch.optim.Adam(self.value.parameters(), lr=cfg.lr_critic, eps=1e-5)
        self.buffer = RolloutBuffer(
            cfg.rollout_steps,
            cfg.num_envs,
            {
                "state": ((n + 1, 8), torch.float32),
                "alive": ((n,), torch.bool),
                "action": ((n, 2), torch.float32),  # the unclipped Gaussian sample
                "logp": ((n,), torch.float32),
                "value": ((n,), torch.float32),
                "reward": ((n,), torch.float32),
                "next_nonterminal": ((n,), torch.float32),
            },
            device,
        )
        self.noise = None  # exploration is the policy's own sampling
        self.updates = 0
        self._acting: dict[str, Tensor] = {}
        self._last_value: Tensor | None = None

    @staticmethod
    def adapt_env(env_cfg: EnvConfig) -> EnvConfig:
        """The training scenario (unchanged: the configured evader plays)."""
        return env_cfg

    # --- acting ----------------------------------------------------------------------------------
    def values(self, state: Tensor, alive: Tensor) -> Tensor:
        """V(o_i) for every pursuer: state (B, A, 8), alive (B, N) -> (B, N)."""
        obs, mask = pursuer_obs(state, alive)
        return self.value(obs, mask).squeeze(-1)

    @torch.no_grad()
    def act(self, obs: Tensor, info: dict[str, Tensor], noise_scale: float, gen):
        """(E, N, 2) sampled actions clipped to [-1, 1] (``noise_scale`` is unused: PPO explores
        by its policy's own spread), and no evader actions."""
        mean, log_std = self.actor(obs, info["obs_mask"])
        eps = torch.randn(mean.shape, generator=gen).to(mean.device)
        sample = mean + eps * log_std.exp()
        self._acting = {
            "action": sample,
            "logp": gaussian_log_prob(sample, mean, log_std),
            "value": self.value(obs, info["obs_mask"]).squeeze(-1),
        }
        return sample.clamp(-1.0, 1.0), None

    @torch.no_grad()
    def record(self, before, actions, evader_actions, reward, terminated, after) -> None:
        """Store one vector step. An agent's episode continues unless its environment finished
        or it died in this step; a truncated episode's reward gains gamma * V(final obs)."""
        truncated = ~terminated & (after["steps"] >= self.max_steps)
        next_alive = after["final_obs_mask"][:, :, 0]
        next_nonterminal = (~(terminated | truncated)).unsqueeze(-1) & next_alive
        reward = reward.clone()
        if bool(truncated.any()):
            bootstrap = self.values(after["final_state"], next_alive)
            keep = truncated.unsqueeze(-1) & next_alive
            reward += self.cfg.gamma * bootstrap * keep.float()
        self.buffer.add(
            state=before["state"],
            alive=before["obs_mask"][:, :, 0],
            reward=reward,
            next_nonterminal=next_nonterminal.float(),
            **self._acting,
        )
        if self.buffer.full:
            self._last_value = self.values(after["state"], after["obs_mask"][:, :, 0])

    def episode_reset(self, done: Tensor) -> None:
        """Stateless between episodes."""

    # --- learning --------------------------------------------------------------------------------
    def ready(self) -> bool:
        """An update consumes a full rollout."""
        return self.buffer.full

    def update(self, gen: torch.Generator) -> dict[str, float]:
        """``ppo_epochs`` passes of clipped-surrogate and value updates over the rollout, which
        is then cleared; returns the mean metrics."""
        cfg, data = self.cfg, self.buffer.data
        adv, ret = gae(
            data["reward"],
            data["value"],
            data["next_nonterminal"],
            self._last_value,
            cfg.gamma,
            cfg.gae_lambda,
        )
        rows = self.buffer.filled * self.buffer.num_envs
        alive = data["alive"].flatten(0, 1)
        obs, mask = pursuer_obs(data["state"].flatten(0, 1), alive)
        flat = {
            "action": data["action"].flatten(0, 1),
            "logp": data["logp"].flatten(0, 1),
            "adv": adv.flatten(0, 1),
            "ret": ret.flatten(0, 1),
        }
        sums: dict[str, float] = {}
        steps = 0
        stop = False
        for _ in range(cfg.ppo_epochs):
            order = torch.randperm(rows, generator=gen).to(self.device)
            for start in range(0, rows, cfg.batch_size):
                idx = order[start : start + cfg.batch_size]
                live = alive[idx]
                if not bool(live.any()):
                    continue
                batch = {k: v[idx] for k, v in flat.items()}
                stats = self._minibatch(obs[idx], mask[idx], live, batch)
                for k, v in stats.items():
                    sums[k] = sums.get(k, 0.0) + v
                steps += 1
                if cfg.target_kl > 0 and stats["approx_kl"] > cfg.target_kl:
                    stop = True
                    break
            if stop:
                break
        self.buffer.clear()
        self.updates += 1
        out = {k: v / max(steps, 1) for k, v in sums.items()}
        out["q_mean"] = float(masked_mean(data["value"], data["alive"]))
        return out

    def _minibatch(self, obs, mask, live, batch) -> dict[str, float]:
        """One gradient step of the actor and of V on a minibatch (B transitions, N pursuers)."""
        cfg = self.cfg
        mean, log_std = self.actor(obs, mask)
        logp = gaussian_log_prob(batch["action"], mean, log_std)
        log_ratio = logp - batch["logp"]
        ratio = log_ratio.exp()
        adv = batch["adv"]
        live_adv = adv[live]
        adv = (adv - live_adv.mean()) / (live_adv.std(unbiased=False) + 1e-8)
        surrogate = torch.min(ratio * adv, ratio.clamp(1 - cfg.clip_coef, 1 + cfg.clip_coef) * adv)
        entropy = (log_std + 0.5 * math.log(2 * math.pi * math.e)).sum(-1)
        actor_loss = -masked_mean(surrogate, live) - cfg.ent_coef * masked_mean(entropy, live)
        optimise(self.opt_actor, actor_loss, self.actor.parameters(), cfg.grad_clip)
        v = self.value(obs, mask).squeeze(-1)
        critic_loss = masked_mean((v - batch["ret"]) ** 2, live)
        optimise(self.opt_critic, critic_loss, self.value.parameters(), cfg.grad_clip)
        with torch.no_grad():
            approx_kl = masked_mean((ratio - 1) - log_ratio, live)
            clipped = ((ratio - 1).abs() > cfg.clip_coef).float()
            return {
                "actor_loss": float(actor_loss),
                "critic_loss": float(critic_loss),
                "entropy": float(masked_mean(entropy, live)),
                "approx_kl": float(approx_kl),
                "clip_frac": float(masked_mean(clipped, live)),
                "noise": float(masked_mean(log_std.exp().mean(-1), live)),
            }

    score = staticmethod(pursuer_score)

    # --- saving ----------------------------------------------------------------------------------
    def modules(self) -> dict[str, nn.Module]:
        return {"actor": self.actor, "value": self.value}

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"actor": self.opt_actor, "value": self.opt_critic}

    def policy_modules(self) -> dict[str, nn.Module]:
        """What a deployed policy needs: the actor."""
        return {"actor": self.actor}
