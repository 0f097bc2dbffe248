"""The deterministic-policy actor-critic that the DDPG family shares (CBC Net, CBC-TP Net,
MADDPG, DDPG, BiCNet): acting with OU noise, replay of multi-agent transitions, n-step TD
targets, target networks, demonstrations.

A method subclasses :class:`ActorCritic` and gives its networks (:meth:`make_actor`,
:meth:`make_critic`) and, where its actor's gradient differs, :meth:`actor_step`. One update:

1. critic: y = n-step TD target (:func:`pes.learn.td.td_target`) with the target critic on
   the target actor's actions at the window's last next state; squared error averaged over
   the pursuers alive in s;
2. actor (:meth:`actor_step`): ascend the critic's Q of the actor's actions, plus
   ``action_reg`` times the squared pre-tanh action (MADDPG's regulariser), plus
   behaviour cloning of the demonstrations where the protocol's ``bc_weight`` asks for it;
3. soft target updates with rate ``tau``.

The networks' interface: the actor maps ``(obs (B, N, N, 8), mask (B, N, N), pred (B, N, 2k) or
None)`` to actions (B, N, 2) in [-1, 1] and has ``pre_activation`` (before the tanh); the
critic maps ``(state (B, A, 8), alive (B, N), actions (B, N, 2), pred (B, k, 2) or None)`` to
Q (B, N).
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor, nn

from pes.learn.buffer import ReplayBuffer, transition, transition_fields
from pes.learn.common import adam, masked_mean, optimise, soft_update, target_copy
from pes.learn.config import OffPolicyConfig, TrainConfig
from pes.learn.features import pursuer_obs
from pes.learn.learner import Learner
from pes.learn.noise import OUNoise
from pes.learn.td import TDWindows, sample_windows, td_target
from pes.policies import SCRIPTED
from pes.sim.config import EnvConfig


@dataclass
class ActorCriticConfig(OffPolicyConfig):
    """Settings every :class:`ActorCritic` reads (the paper's, §V-A, by default)."""

    action_reg: float = 1e-3
    """Weight of the squared pre-tanh action in the actor loss (MADDPG's regulariser)."""
    obstacle_scale: float = 20.0
    """Factor on the obstacle-vector columns of the observation rows before the networks: in
    arena units the 2 m safety margin is only 0.02 (see ``pes.learn.nets.RowScaled``)."""
    target_scale: float = 5.0
    """Factor on the vector to the evader (and on a predicted path) before the networks."""

    NON_NEGATIVE: ClassVar[tuple[str, ...]] = (
        *OffPolicyConfig.NON_NEGATIVE,
        "action_reg",
        "obstacle_scale",
        "target_scale",
    )


class DeterministicPolicy(nn.Module):
    """A trained actor as a :class:`pes.policies.Policy`: ``actor(obs, info["obs_mask"],
    None)``."""

    row_wise = True  # see pes.policies.Policy

    def __init__(self, actor: nn.Module) -> None:
        super().__init__()
        self.actor = actor
        self.last_prediction: Tensor | None = None
        """(E, k, 2) the latest predicted evader positions (None: the policy predicts none)."""

    @torch.no_grad()
    def __call__(self, obs: Tensor, info: dict[str, Tensor]) -> Tensor:
        return self.act(obs, info)

    def act(self, obs: Tensor, info: dict[str, Tensor]) -> Tensor:
        """obs (E, N, N, 8) -> actions (E, N, 2)."""
        return self.actor(obs, info["obs_mask"], None)

    def reset(self, mask: Tensor | None = None) -> None:
        """Stateless between steps."""


class ActorCritic(Learner):
    """A deterministic-policy actor-critic with OU exploration (see the module docstring)."""

    Config: ClassVar[type[ActorCriticConfig]] = ActorCriticConfig
    AIDS: ClassVar[dict[str, str]] = {
        "noise": "",
        "n_step": "",
        "greedy_envs": "",
        "demonstrations": "",
        "charge_exits": "",
    }
    TUNE_SPACE: ClassVar[dict[str, tuple]] = {
        "lr_actor": ("log", 1e-4, 2e-3),
        "lr_critic": ("log", 3e-4, 3e-3),
        "batch_size": ("choice", [128, 256, 512]),
        "update_every": ("choice", [16, 32, 64]),
        "gamma": ("choice", [0.95, 0.98, 0.99]),
    }

    def __init__(self, cfg: TrainConfig, env_cfg: EnvConfig, device: torch.device) -> None:
        super().__init__(cfg, env_cfg, device)
        lc, protocol = cfg.learner, cfg.protocol
        self.lc = lc
        self.n = n = env_cfg.num_pursuers
        self.n_step = protocol.n_step
        crash = protocol.crash_curriculum
        self.exits = (
            (env_cfg.capture_count, env_cfg.crash_reward)
            if crash is not None and crash.charge_exits
            else None
        )
        self.actor = self.make_actor(lc, n).to(device)
        self.critic = self.make_critic(lc, n).to(device)
        self.actor_target = target_copy(self.actor)
        self.critic_target = target_copy(self.critic)
        self.opt_actor = adam(self.actor.parameters(), lc.lr_actor)
        self.opt_critic = adam(self.critic.parameters(), lc.lr_critic)
        self.policy = self.make_policy()
        fields = transition_fields(n) | self.extra_fields()
        demos = protocol.demonstrations
        self.demo, self.demo_transitions, self.bc_weight = None, 0, 0.0
        if demos is not None and demos.transitions > 0:
            self.demo = SCRIPTED[demos.policy](env_cfg)
            self.demo_transitions, self.bc_weight = demos.transitions, demos.bc_weight
            fields["demo"] = ((), torch.bool)
        self.buffer = ReplayBuffer(lc.buffer_size, cfg.num_envs, fields, device)
        self.noise = OUNoise((cfg.num_envs, n, 2), protocol.noise.theta, 1.0, device=device)
        # (E, 1, 1) 1 for the environments that explore, 0 for the last greedy_envs share
        greedy = round(protocol.greedy_envs * cfg.num_envs)
        explore = torch.arange(cfg.num_envs, device=device) < cfg.num_envs - greedy
        self.explore = explore.float()[:, None, None]

    # --- what a method provides -----------------------------------------------------------------
    @staticmethod
    @abstractmethod
    def make_actor(lc: Any, num_pursuers: int) -> nn.Module:
        """The actor (see the module docstring for its interface)."""

    @staticmethod
    @abstractmethod
    def make_critic(lc: Any, num_pursuers: int) -> nn.Module:
        """The critic (see the module docstring for its interface)."""

    def make_policy(self) -> DeterministicPolicy:
        """The acting policy over :attr:`actor`."""
        return DeterministicPolicy(self.actor)

    def extra_fields(self) -> dict[str, tuple[tuple[int, ...], torch.dtype]]:
        """Replay fields beyond the transition's (CBC-TP Net: its predictions)."""
        return {}

    def extra_record(self, after: dict[str, Tensor]) -> dict[str, Tensor]:
        """Values of :meth:`extra_fields` for one vector step."""
        return {}

    def predictions(self, w: TDWindows) -> tuple[Tensor | None, Tensor | None]:
        """Predicted evader paths (B, k, 2) at s and at the window's last s' (None, None: the
        method predicts none)."""
        return None, None

    def auxiliary_update(self, gen: torch.Generator) -> dict[str, float]:
        """An update of a network beside the actor and the critic (CBC-TP Net: TP Net), run
        before the warm-up ends too; returns its metrics."""
        return {}

    # --- acting ----------------------------------------------------------------------------------
    @torch.no_grad()
    def act(self, obs: Tensor, info: dict[str, Tensor], noise_scale: float, gen):
        """(E, N, 2) actions of the current actor plus OU noise (none in the ``greedy_envs``
        share of the environments), clipped to [-1, 1], or the demonstrator's while it plays;
        no evader actions (the environment's evader plays)."""
        actions = self.policy.act(obs, info)  # also a prediction the record keeps
        if self.demonstrating():  # the demonstrator plays as it would, without noise
            return self.demo(obs, info).clamp(-1.0, 1.0), None
        if noise_scale > 0:
            actions = actions + self.noise.sample(gen, noise_scale) * self.explore
        return actions.clamp(-1.0, 1.0), None

    def record(self, before, actions, evader_actions, reward, terminated, after) -> None:
        extra = self.extra_record(after)
        if self.demo is not None:
            extra["demo"] = torch.full_like(terminated, self.demonstrating())
        self.buffer.add(**transition(before, actions, reward, terminated, after), **extra)

    def demonstrating(self) -> bool:
        """Whether the demonstrator plays the next step (the protocol's ``demonstrations``)."""
        # The buffer's capacity is whole steps of all environments: it may fall a few
        # transitions short of buffer_size, and so of the demonstrations wanted.
        wanted = min(self.demo_transitions, self.buffer.capacity)
        return self.demo is not None and len(self.buffer) < wanted

    def episode_reset(self, done: Tensor) -> None:
        self.noise.reset(done)
        if self.demo is not None:
            self.demo.reset(done)

    # --- learning --------------------------------------------------------------------------------
    def ready(self) -> bool:
        return len(self.buffer) >= max(self.lc.warmup, self.lc.batch_size)

    def update_credit(self) -> float:
        return self.cfg.num_envs / self.lc.update_every

    def update(self, gen: torch.Generator) -> dict[str, float]:
        """One update of the critic and the actor (see the module docstring) after an
        :meth:`auxiliary_update`; returns their metrics."""
        lc = self.lc
        stats = self.auxiliary_update(gen)
        self.updates += 1
        if len(self.buffer) < lc.warmup:
            return stats
        w = sample_windows(self.buffer, lc.batch_size, self.n_step, lc.gamma, gen)
        pred, next_pred = self.predictions(w)
        with torch.no_grad():
            next_action = self.target_actions(w.next_state, w.next_alive, next_pred)
            q_next = self.critic_target(w.next_state, w.next_alive, next_action, next_pred)
            y = td_target(w, q_next, lc.gamma, self.exits)
        q = self.critic(w.state, w.alive, w.action, pred)
        critic_loss = masked_mean((q - y) ** 2, w.alive)
        stats["critic_grad"] = optimise(
            self.opt_critic, critic_loss, self.critic.parameters(), lc.grad_clip
        )
        actor_loss = self.actor_step(w, pred, gen, stats)
        optimise(self.opt_actor, actor_loss, self.actor.parameters(), lc.grad_clip)
        soft_update(self.actor_target, self.actor, lc.tau)
        soft_update(self.critic_target, self.critic, lc.tau)
        stats.update(
            actor_loss=float(actor_loss.detach()),
            critic_loss=float(critic_loss.detach()),
            q_mean=float(masked_mean(q.detach(), w.alive)),
        )
        return stats

    def observe(
        self, state: Tensor, alive: Tensor, pred: Tensor | None
    ) -> tuple[Tensor, Tensor, Tensor | None]:
        """The actor's inputs from global states: obs (B, N, N, 8), mask (B, N, N) and the
        prediction as each pursuer sees it (B, N, 2k) or None."""
        obs, mask = pursuer_obs(state, alive)
        return obs, mask, None

    def target_actions(self, state: Tensor, alive: Tensor, pred: Tensor | None) -> Tensor:
        """The target actor's actions (B, N, 2) at global states (B, A, 8)."""
        return self.actor_target(*self.observe(state, alive, pred))

    def actor_step(
        self, w: TDWindows, pred: Tensor | None, gen: torch.Generator, stats: dict[str, float]
    ) -> Tensor:
        """The actor's loss: every alive pursuer acts with the current actor at once and the
        actor ascends the mean of their Qs (a centralised policy gradient, as BiCNet's and
        FACMAC's)."""
        obs, mask, rel = self.observe(w.state, w.alive, pred)
        pre = self.actor.pre_activation(obs, mask, rel)  # (B, N, 2)
        if self.demonstrating() and self.bc_weight > 0:
            return self.cloning_loss(pre, w, stats)
        new_action = torch.where(w.alive.unsqueeze(-1), torch.tanh(pre), w.action)
        q_pi = self.frozen_critic(w.state, w.alive, new_action, pred)
        return self.actor_objective(q_pi, pre, w.alive, new_action, w, stats)

    def frozen_critic(self, *inputs: Tensor | None) -> Tensor:
        """The critic's Q with its parameters out of the graph (the actor's gradient only)."""
        self.critic.requires_grad_(False)
        q = self.critic(*inputs)
        self.critic.requires_grad_(True)
        return q

    def actor_objective(
        self,
        q_pi: Tensor,
        pre: Tensor,
        acting: Tensor,
        new_action: Tensor,
        w: TDWindows,
        stats: dict[str, float],
    ) -> Tensor:
        """Minus the mean Q of the ``acting`` pursuers (B, N) bool, plus ``action_reg`` times
        their squared pre-tanh actions ``pre`` (B, N, 2), plus behaviour cloning of the
        demonstrations with the protocol's ``bc_weight``: then the Q term is divided by the
        batch's mean |Q| (TD3+BC, Fujimoto & Gu 2021), so that the weight means the same
        whatever the reward's scale. ``new_action`` (B, N, 2) holds the actor's actions where
        ``acting``."""
        reg = masked_mean((pre**2).sum(-1), acting)
        q_term, bc_term = masked_mean(q_pi, acting), 0.0
        if self.demo is not None and self.bc_weight > 0:
            q_term = q_term / masked_mean(q_pi.detach().abs(), acting).clamp(min=1e-6)
            demo = self.buffer.get("demo", w.row, w.env).unsqueeze(-1) & acting
            bc = ((new_action - w.action) ** 2).sum(-1)
            bc_term = self.bc_weight * (bc * demo).sum() / len(w.row)
            stats["bc_share"] = float(demo.sum()) / max(float(acting.sum()), 1.0)
        return -q_term + self.lc.action_reg * reg + bc_term

    def cloning_loss(self, pre: Tensor, w: TDWindows, stats: dict[str, float]) -> Tensor:
        """While the demonstrator still plays the critic is too young to follow: the actor
        learns by behaviour cloning alone, every alive pursuer of every sample."""
        bc = masked_mean(((torch.tanh(pre) - w.action) ** 2).sum(-1), w.alive)
        reg = masked_mean((pre**2).sum(-1), w.alive)
        stats["bc_share"] = 1.0
        return self.bc_weight * bc + self.lc.action_reg * reg

    # --- saving ----------------------------------------------------------------------------------
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
        demo = self.demo.state_dict() if self.demo is not None else None
        return {"noise": self.noise.state_dict(), "demo": demo}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.noise.load_state_dict(state["noise"])
        if self.demo is not None:
            self.demo.load_state_dict(state["demo"])

    @classmethod
    def build_policy(cls, cfg: TrainConfig, env_cfg: EnvConfig, device):
        actor = cls.make_actor(cfg.learner, env_cfg.num_pursuers).to(device)
        return DeterministicPolicy(actor), {"actor": actor}
