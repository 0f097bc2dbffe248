"""The DDPG evader (docs/algorithms/evader_ddpg.md): trained in the PES against scripted pursuers,
then frozen and used as the default opponent of evaluations.

A single DDPG agent (Lillicrap et al.) controls the evader through ``evader_policy="external"``.
It sees ``info["evader_obs"]`` (its own row and one row per pursuer, Table I style) through a
permutation-invariant encoder (:class:`DeepSetActor`), so the frozen evader
plays against any number of pursuers, and earns the environment's evader reward
(docs/scenario.md). Its opponents during training are ``opponent`` pursuers (PID(PF) by
default).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor, nn

from pes.errors import ConfigError
from pes.learn.buffer import ReplayBuffer
from pes.learn.common import adam, optimise, soft_update, target_copy
from pes.learn.config import OffPolicyConfig, TrainConfig
from pes.learn.learner import Learner
from pes.learn.nets import mlp
from pes.learn.noise import OUNoise
from pes.learn.presets import TINY_PROTOCOL, TINY_RUN, gpu_preset
from pes.policies import SCRIPTED
from pes.sim.config import EnvConfig


@dataclass
class EvaderDDPGConfig(OffPolicyConfig):
    """The DDPG evader's settings (the paper's, §V-A, with 128 units)."""

    action_reg: float = 1e-3
    """Weight of the squared action in the actor loss."""
    hidden: int = 128
    """Units of the actor's and the critic's layers."""
    opponent: str = "pid-pf"
    """Pursuers the evader trains against (``pid-pf`` or ``random``)."""

    POSITIVE: ClassVar[tuple[str, ...]] = (*OffPolicyConfig.POSITIVE, "hidden")
    NON_NEGATIVE: ClassVar[tuple[str, ...]] = (*OffPolicyConfig.NON_NEGATIVE, "action_reg")

    def check(self) -> None:
        if self.opponent not in ("pid-pf", "random"):
            raise ConfigError(f"opponent must be pid-pf or random, got '{self.opponent}'")


EVADER_PRESETS: dict[str, dict[str, Any]] = {
    "paper": dict(episodes=4000, num_envs=1),
    # Settings of the shipped evader (src/pes/models/evader_ddpg.md): with the paper's gamma
    # 0.95 and lr 5e-4 the evader's policy collapsed onto the arena wall (see
    # docs/algorithms/evader_ddpg.md); its noise falls from 0.3 to 0.1 over 720 episodes.
    "quick": dict(
        episodes=1200,
        num_envs=32,
        gamma=0.99,
        lr_actor=1e-4,
        lr_critic=5e-4,
        action_reg=0.01,
        buffer_size=300_000,
        batch_size=256,
        update_every=16,
        warmup=10_000,
        time_limit=15.0,
        log_every=50,
        protocol=dict(noise=dict(sigma=0.3, sigma_final=0.1, decay_episodes=720)),
    ),
    "tiny": dict(
        TINY_RUN,
        hidden=32,
        buffer_size=20_000,
        batch_size=64,
        update_every=8,
        warmup=500,
        protocol=TINY_PROTOCOL,
    ),
}
EVADER_PRESETS["gpu"] = gpu_preset(EVADER_PRESETS["quick"])
"""The evader's presets; it trains under the ``paper`` protocol by default."""


class DeepSetActor(nn.Module):
    """The DDPG evader's actor: its own row, plus the max and mean of an embedding of each alive
    pursuer's row (so it plays against any number of pursuers), through an MLP to its action.

    Input: ``info["evader_obs"]`` (B, A, 8) as built by :func:`pes.sim.scenario.observe`."""

    def __init__(self, hidden: int = 128, action_dim: int = 0) -> None:
        super().__init__()
        self.embed = mlp([8, hidden, hidden], nn.ReLU())
        self.head = mlp([8 + action_dim + 2 * hidden, hidden, hidden, 1 if action_dim else 2])
        self.squash = nn.Identity() if action_dim else nn.Tanh()

    def features(self, obs: Tensor) -> Tensor:
        others = obs[:, 1:]
        present = (others.abs().sum(-1) > 0).unsqueeze(-1)
        emb = self.embed(others)
        w = present.to(obs.dtype)
        mean = (emb * w).sum(1) / w.sum(1).clamp(min=1.0)
        top = emb.masked_fill(~present, 0.0).amax(1)  # embeddings are >= 0 (ReLU)
        return torch.cat([mean, top], dim=-1)

    def forward(self, obs: Tensor, action: Tensor | None = None) -> Tensor:
        """obs (B, A, 8) -> action (B, 2) in [-1, 1]; with ``action`` (critic) -> Q (B,)."""
        parts = [obs[:, 0]] + ([action] if action is not None else []) + [self.features(obs)]
        out = self.squash(self.head(torch.cat(parts, dim=-1)))
        return out.squeeze(-1) if action is not None else out


class DeepSetCritic(DeepSetActor):
    """The DDPG evader's critic: :class:`DeepSetActor`'s body with the action beside its own
    row, giving Q (B,)."""

    def __init__(self, hidden: int = 128) -> None:
        super().__init__(hidden, action_dim=2)


class EvaderDDPG(Learner):
    """The DDPG evader learner."""

    name = "evader-ddpg"
    Config = EvaderDDPGConfig
    PRESETS = EVADER_PRESETS
    pursuer = False
    default_protocol = "paper"
    AIDS: ClassVar[dict[str, str]] = {"noise": ""}

    def __init__(self, cfg: TrainConfig, env_cfg: EnvConfig, device: torch.device) -> None:
        super().__init__(cfg, env_cfg, device)
        self.lc = lc = cfg.learner
        a = env_cfg.num_pursuers + 1
        self.actor = DeepSetActor(lc.hidden).to(device)
        self.critic = DeepSetCritic(lc.hidden).to(device)
        self.actor_target = target_copy(self.actor)
        self.critic_target = target_copy(self.critic)
        self.opt_actor = adam(self.actor.parameters(), lc.lr_actor)
        self.opt_critic = adam(self.critic.parameters(), lc.lr_critic)
        self.pursuers = SCRIPTED[lc.opponent](env_cfg)
        self.buffer = ReplayBuffer(
            lc.buffer_size,
            cfg.num_envs,
            {
                "obs": ((a, 8), torch.float32),
                "action": ((2,), torch.float32),
                "reward": ((), torch.float32),
                "next_obs": ((a, 8), torch.float32),
                "terminated": ((), torch.bool),
            },
            device,
        )
        self.noise = OUNoise((cfg.num_envs, 2), cfg.protocol.noise.theta, 1.0, device=device)

    @staticmethod
    def adapt_env(env_cfg: EnvConfig) -> EnvConfig:
        """The training scenario: the evader's actions come from this learner."""
        return env_cfg.replace(evader_policy="external")

    @torch.no_grad()
    def act(self, obs: Tensor, info: dict[str, Tensor], noise_scale: float, gen):
        """The opponents' (E, N, 2) actions and the evader's (E, 2), with OU noise."""
        evader = self.actor(info["evader_obs"])
        if noise_scale > 0:
            evader = evader + self.noise.sample(gen, noise_scale)
        return self.pursuers(obs, info), evader.clamp(-1.0, 1.0)

    def record(self, before, actions, evader_actions, reward, terminated, after) -> None:
        self.buffer.add(
            obs=before["evader_obs"],
            action=evader_actions,
            reward=after["evader_reward"],
            next_obs=after["final_evader_obs"],
            terminated=terminated,
            ep_step=(after["steps"] - 1).to(torch.int32),
        )

    def episode_reset(self, done: Tensor) -> None:
        self.noise.reset(done)
        self.pursuers.reset(done)

    def ready(self) -> bool:
        return len(self.buffer) >= max(self.lc.warmup, self.lc.batch_size)

    def update_credit(self) -> float:
        return self.cfg.num_envs / self.lc.update_every

    def update(self, gen: torch.Generator) -> dict[str, float]:
        cfg, buf = self.lc, self.buffer
        row, env = buf.sample_index(cfg.batch_size, gen)
        obs, action = buf.get("obs", row, env), buf.get("action", row, env)
        reward, next_obs = buf.get("reward", row, env), buf.get("next_obs", row, env)
        terminated = buf.get("terminated", row, env)
        with torch.no_grad():
            q_next = self.critic_target(next_obs, self.actor_target(next_obs))
            y = reward + cfg.gamma * (~terminated).float() * q_next
        q = self.critic(obs, action)
        critic_loss = ((q - y) ** 2).mean()
        optimise(self.opt_critic, critic_loss, self.critic.parameters(), cfg.grad_clip)
        new_action = self.actor(obs)
        for p in self.critic.parameters():
            p.requires_grad_(False)
        actor_loss = -self.critic(obs, new_action).mean()
        actor_loss = actor_loss + cfg.action_reg * (new_action**2).sum(-1).mean()
        for p in self.critic.parameters():
            p.requires_grad_(True)
        optimise(self.opt_actor, actor_loss, self.actor.parameters(), cfg.grad_clip)
        soft_update(self.actor_target, self.actor, cfg.tau)
        soft_update(self.critic_target, self.critic, cfg.tau)
        self.updates += 1
        return {
            "critic_loss": float(critic_loss.detach()),
            "actor_loss": float(actor_loss.detach()),
            "q_mean": float(q.detach().mean()),
        }

    @staticmethod
    def score(success_rate: float, episode_steps: float) -> float:
        """Training score of a log row (higher is better): the pursuers' failure, then the
        evader's survival time."""
        return -success_rate + 1e-5 * episode_steps

    def modules(self) -> dict[str, nn.Module]:
        return {
            "actor": self.actor,
            "critic": self.critic,
            "actor_target": self.actor_target,
            "critic_target": self.critic_target,
        }

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"actor": self.opt_actor, "critic": self.opt_critic}

    def policy_modules(self) -> dict[str, nn.Module]:
        return {"actor": self.actor}

    def state_dict(self) -> dict[str, Any]:
        pursuers = getattr(self.pursuers, "state_dict", None)
        return {"noise": self.noise.state_dict(), "pursuers": pursuers() if pursuers else None}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.noise.load_state_dict(state["noise"])
        if state["pursuers"] is not None:
            self.pursuers.load_state_dict(state["pursuers"])

    @classmethod
    def build_policy(cls, cfg: TrainConfig, env_cfg: EnvConfig, device):
        """What plays against a trained evader in its evaluation: its opponent pursuers (the
        evader itself is the environment's, ``evader_model``)."""
        return SCRIPTED[cfg.learner.opponent](env_cfg), {}
