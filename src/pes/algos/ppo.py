"""PPO baseline (Table IV): proximal policy optimisation (Schulman et al., 2017) with GAE,
on-policy, collected from ``num_envs`` environments at once.

Each pursuer is an independent learner on its own Table I observation (IPPO): a Gaussian actor
and a value function V(o_i), both MLPs on the flattened observation
(:class:`pes.learn.nets.FlatObsMLP`). With ``shared=True`` (the default) all pursuers share
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
from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor, nn

from pes.errors import ConfigError
from pes.learn.buffer import RolloutBuffer, gae
from pes.learn.common import ActorPolicy, gaussian_log_prob, masked_mean, optimise
from pes.learn.config import LearnerConfig, TrainConfig
from pes.learn.features import pursuer_obs
from pes.learn.learner import Learner
from pes.learn.nets import FlatObsMLP, PerAgent
from pes.learn.presets import QUICK_RUN, TINY_PROTOCOL, TINY_RUN
from pes.learn.td import exit_charge
from pes.sim.config import EnvConfig


@dataclass
class PPOConfig(LearnerConfig):
    """PPO's settings: gamma and the minibatch from the paper (§V-A), the rest from the PPO
    paper (Schulman et al., 2017, MuJoCo settings), as the paper gives none for its baselines."""

    gamma: float = 0.95
    """Discount factor."""
    lr_actor: float = 3e-4
    """Adam learning rate of the actor."""
    lr_critic: float = 3e-4
    """Adam learning rate of the value function."""
    hidden: int = 64
    """Units of each of the two hidden layers of the actor's and the value function's MLPs."""
    shared: bool = True
    """One actor and one value function for all pursuers (False: one pair per pursuer)."""
    obstacle_scale: float = 20.0
    """Factor on the obstacle-vector columns of the observation rows (``RowScaled``)."""
    target_scale: float = 5.0
    """Factor on the vector to the evader in the observation rows."""
    rollout_steps: int = 2048
    """Vector steps per rollout (a rollout holds ``rollout_steps * num_envs`` transitions, each
    with N pursuer samples)."""
    ppo_epochs: int = 10
    """Passes over each rollout."""
    batch_size: int = 512
    """Minibatch in transitions."""
    gae_lambda: float = 0.95
    """Lambda of generalised advantage estimation."""
    clip_coef: float = 0.2
    """Clipping range of the probability ratio."""
    ent_coef: float = 0.0
    """Weight of the entropy bonus in the actor loss."""
    target_kl: float = 0.0
    """Stop a rollout's epochs once the approximate KL exceeds this (0 = never)."""
    log_std_init: float = -0.5
    """Initial log standard deviation of the Gaussian policy (in action units)."""
    grad_clip: float = 1.0
    """Gradient norm clip (0 = none)."""

    POSITIVE: ClassVar[tuple[str, ...]] = (
        "lr_actor",
        "lr_critic",
        "hidden",
        "rollout_steps",
        "ppo_epochs",
        "batch_size",
    )
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = (
        "obstacle_scale",
        "target_scale",
        "ent_coef",
        "target_kl",
        "grad_clip",
    )

    def check(self) -> None:
        for name in ("gae_lambda", "clip_coef"):
            if not 0.0 < getattr(self, name) <= 1.0:
                raise ConfigError(f"ppo: {name} must be in (0, 1], got {getattr(self, name)}")


PPO_TUNED: dict[str, Any] = dict(lr_actor=6.12e-4, lr_critic=7.8e-4, ent_coef=1e-3, hidden=128)
"""The best of PPO's search (results/tuning/ppo, trial t03: 0.0 % of the held-out episodes after
1,000,000 env steps, the best mean reward); the search began at lr_actor 3e-4, lr_critic 1e-3,
ent_coef 0, hidden 64."""

PPO_PRESETS: dict[str, dict[str, Any]] = {
    "paper": dict(episodes=4000, num_envs=1, env=dict(evader_policy="ddpg")),
    # 64 environments x 64 steps per rollout, 4 minibatches, 10 epochs; ~1 s per update on
    # one CPU thread, about as long as the rollout's collection.
    "quick": dict(
        QUICK_RUN,
        num_envs=64,
        lr_actor=3e-4,
        lr_critic=1e-3,
        rollout_steps=64,
        batch_size=1024,
    )
    | PPO_TUNED,
    "tiny": dict(
        TINY_RUN,
        hidden=32,
        rollout_steps=16,
        batch_size=32,
        ppo_epochs=4,
        protocol=TINY_PROTOCOL,
    ),
}


class GaussianActor(nn.Module):
    """A diagonal Gaussian policy: mean from a :class:`FlatObsMLP`, log std a free parameter
    (independent of the state)."""

    def __init__(self, lc: PPOConfig, num_pursuers: int) -> None:
        super().__init__()
        self.mean = FlatObsMLP(num_pursuers, lc.hidden, 2, 2, lc.obstacle_scale, lc.target_scale)
        self.log_std = nn.Parameter(torch.full((2,), lc.log_std_init))

    def forward(self, obs: Tensor, mask: Tensor) -> Tensor:
        """obs (B, N, 8), mask (B, N) -> (B, 4): mean (2) and log std (2)."""
        mean = self.mean(obs, mask)
        return torch.cat([mean, self.log_std.expand_as(mean)], dim=-1)


class PPOActors(nn.Module):
    """The pursuers' Gaussian actors (shared or one each), on observations (B, N, N, 8)."""

    def __init__(self, lc: PPOConfig, num_pursuers: int) -> None:
        super().__init__()
        self.nets = PerAgent(lambda: GaussianActor(lc, num_pursuers), num_pursuers, lc.shared)

    def forward(self, obs: Tensor, mask: Tensor) -> tuple[Tensor, Tensor]:
        """obs (B, N, N, 8), mask (B, N, N) -> mean and log std, each (B, N, 2)."""
        out = self.nets(obs, mask)
        return out[..., :2], out[..., 2:]

    def mean_action(self, obs: Tensor, mask: Tensor) -> Tensor:
        """(B, N, 2) deterministic actions: the mean, clipped to [-1, 1]."""
        return self(obs, mask)[0].clamp(-1.0, 1.0)


class PPO(Learner):
    """The PPO learner (independent learners, parameter-shared by default)."""

    name = "ppo"
    Config = PPOConfig
    PRESETS = PPO_PRESETS
    TUNE_SPACE: ClassVar[dict[str, tuple]] = {
        "lr_actor": ("log", 1e-4, 1e-3),
        "lr_critic": ("log", 3e-4, 3e-3),
        "ent_coef": ("choice", [0.0, 1e-3, 1e-2]),
        "hidden": ("choice", [64, 128, 256]),
    }
    on_policy = True
    AIDS: ClassVar[dict[str, str]] = {
        "noise": "not applied: PPO explores by its Gaussian policy's own spread (log_std_init, "
        "ent_coef)",
        "n_step": "not applied: PPO's targets are GAE returns over the whole rollout (gae_lambda)",
        "greedy_envs": "not applied: an on-policy update needs every sample drawn from the policy",
        "demonstrations": "not applied: an on-policy update learns only from the current "
        "policy's samples, and a replay buffer to hold demonstrations is what PPO lacks",
        "charge_exits": "",
    }

    def __init__(self, cfg: TrainConfig, env_cfg: EnvConfig, device: torch.device) -> None:
        super().__init__(cfg, env_cfg, device)
        self.lc = lc = cfg.learner
        self.n = n = env_cfg.num_pursuers
        self.max_steps = env_cfg.max_steps
        crash = cfg.protocol.crash_curriculum
        self.exits = (
            (env_cfg.capture_count, env_cfg.crash_reward)
            if crash is not None and crash.charge_exits
            else None
        )
        self.actor = PPOActors(lc, n).to(device)
        self.value = PerAgent(
            lambda: FlatObsMLP(n, lc.hidden, 1, 2, lc.obstacle_scale, lc.target_scale),
            n,
            lc.shared,
        ).to(device)
        self.policy = ActorPolicy(self.actor)
        self.opt_actor = torch.optim.Adam(self.actor.parameters(), lr=lc.lr_actor, eps=1e-5)
        self.opt_critic = torch.optim.Adam(self.value.parameters(), lr=lc.lr_critic, eps=1e-5)
        self.buffer = RolloutBuffer(
            lc.rollout_steps,
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
        self._acting: dict[str, Tensor] = {}
        self._last_value: Tensor | None = None

    @staticmethod
    def fixed_swarm(cfg: TrainConfig) -> str | None:
        return "has MLPs whose inputs are sized"

    @classmethod
    def build_policy(cls, cfg: TrainConfig, env_cfg: EnvConfig, device):
        actor = PPOActors(cfg.learner, env_cfg.num_pursuers).to(device)
        return ActorPolicy(actor), {"actor": actor}

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
        gamma = self.lc.gamma
        if bool(truncated.any()):
            bootstrap = self.values(after["final_state"], next_alive)
            keep = truncated.unsqueeze(-1) & next_alive
            reward += gamma * bootstrap * keep.float()
        if self.exits is not None:  # a pursuer leaving owes what the TD learners charge it
            alive = before["obs_mask"][:, :, 0]
            reward += exit_charge(reward, alive, next_alive, terminated, gamma, *self.exits)
        self.buffer.add(
            state=before["state"],
            alive=before["obs_mask"][:, :, 0],
            reward=reward,
            next_nonterminal=next_nonterminal.float(),
            **self._acting,
        )
        if self.buffer.full:
            self._last_value = self.values(after["state"], after["obs_mask"][:, :, 0])

    def on_restart(self) -> None:
        """A rollout does not span a restart of the environments: it starts afresh."""
        self.buffer.clear()

    # --- learning --------------------------------------------------------------------------------
    def ready(self) -> bool:
        """An update consumes a full rollout."""
        return self.buffer.full

    def update(self, gen: torch.Generator) -> dict[str, float]:
        """``ppo_epochs`` passes of clipped-surrogate and value updates over the rollout, which
        is then cleared; returns the mean metrics."""
        cfg, data = self.lc, self.buffer.data
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
        cfg = self.lc
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

    # --- saving ----------------------------------------------------------------------------------
    def modules(self) -> dict[str, nn.Module]:
        return {"actor": self.actor, "value": self.value}

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"actor": self.opt_actor, "value": self.opt_critic}

    def policy_modules(self) -> dict[str, nn.Module]:
        """What a deployed policy needs: the actor."""
        return {"actor": self.actor}
