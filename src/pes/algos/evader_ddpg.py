"""The DDPG evader (SPEC §2, "Evader policies"): trained in the PES against scripted pursuers,
then frozen and used as the default opponent of evaluations.

A single DDPG agent (Lillicrap et al.) controls the evader through ``evader_policy="external"``.
It sees ``info["evader_obs"]`` (its own row and one row per pursuer, Table I style) through a
permutation-invariant encoder (:class:`pes.algos.nets.DeepSetActor`), so the frozen evader
plays against any number of pursuers, and earns the environment's evader reward
(docs/scenario.md). Its opponents during training are ``cfg.opponent`` pursuers (PID(PF) by
default).
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from pes.algos.buffer import ReplayBuffer
from pes.algos.common import optimise, soft_update, target_copy
from pes.algos.config import TrainConfig
from pes.algos.nets import DeepSetActor, DeepSetCritic
from pes.algos.noise import OUNoise
from pes.policies import SCRIPTED
from pes.sim.config import EnvConfig


class EvaderDDPG:
    """The DDPG evader learner."""

    name = "evader-ddpg"

    def __init__(self, cfg: TrainConfig, env_cfg: EnvConfig, device: torch.device) -> None:
        self.cfg = cfg
        a = env_cfg.num_pursuers + 1
        self.actor = DeepSetActor(cfg.hidden).to(device)
        self.critic = DeepSetCritic(cfg.hidden).to(device)
        self.actor_target = target_copy(self.actor)
        self.critic_target = target_copy(self.critic)
        self.opt_actor = torch.optim.Adam(self.actor.parameters(), lr=cfg.lr_actor)
        self.opt_critic = torch.optim.Adam(self.critic.parameters(), lr=cfg.lr_critic)
        self.pursuers = SCRIPTED[cfg.opponent](env_cfg)
        self.buffer = ReplayBuffer(
            cfg.buffer_size,
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
        self.noise = OUNoise((cfg.num_envs, 2), cfg.noise_theta, 1.0, device=device)

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
        return len(self.buffer) >= max(self.cfg.warmup, self.cfg.batch_size)

    def update(self, gen: torch.Generator) -> dict[str, float]:
        cfg, buf = self.cfg, self.buffer
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
