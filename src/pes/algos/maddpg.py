"""MADDPG (Lowe et al., 2017): per-agent MLP actors, each on its own pursuer's observation, and
per-agent centralised MLP critics on the global state and every pursuer's action.

It trains on the deterministic actor-critic of :mod:`pes.learn.actor_critic` (acting with OU
noise, the replay storage of global states, TD targets, target networks, checkpoints) with its
own networks and actor update:

1. critic i: y_i = r_i + gamma * (1 - terminated) * Q'_i(s', mu'_1(o'_1), ..., mu'_N(o'_N)),
   squared error averaged over the pursuers alive in s;
2. actor i: ascend Q_i(s, a_1, ..., mu_i(o_i), ..., a_N) with the other pursuers' actions from
   the buffer (MADDPG's per-agent gradient), for every pursuer on the full minibatch, plus a
   penalty on the squared pre-tanh action;
3. soft target updates with rate tau.

The N actors (and the N critics) are one :class:`EnsembleMLP`: N independent MLPs evaluated
with one batched matrix product per layer, not a Python loop over the agents. ``shared=True``
makes it one MLP for all pursuers (the critic then also sees the pursuer's one-hot index).

Damaged pursuers (evaluation with ``crash_mode="disable"``): their observation rows are zero
and flagged 0 in every input (the flags are part of the inputs), their actions are zeroed in
the critics' inputs, and their Qs are left out of the losses.

:class:`pes.algos.ddpg.DDPG` is this learner with decentralised critics.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor, nn

from pes.learn.actor_critic import ActorCritic, ActorCriticConfig
from pes.learn.config import TrainConfig
from pes.learn.nets import EnsembleMLP, RowScaled, observation_input
from pes.learn.presets import QUICK_RUN, TINY_PROTOCOL, TINY_RUN, gpu_preset
from pes.learn.td import TDWindows


@dataclass
class MADDPGConfig(ActorCriticConfig):
    """MADDPG's settings (the paper gives none for its baselines: CBC-TP Net's, §V-A)."""

    mlp_hidden: int = 64
    """Units of each of the two hidden layers of the actors' and the critics' MLPs."""
    shared: bool = False
    """One actor and one critic for all pursuers (the critic then also reads the pursuer's
    one-hot index); False: one each, as MADDPG."""

    POSITIVE: ClassVar[tuple[str, ...]] = (*ActorCriticConfig.POSITIVE, "mlp_hidden")


MLP_QUICK: dict[str, Any] = dict(
    QUICK_RUN,
    mlp_hidden=64,
    lr_actor=5e-4,
    lr_critic=1e-3,
    buffer_size=300_000,
    batch_size=256,
    update_every=16,
    warmup=10_000,
)
"""The quick preset of the MLP learners before their searches: CBC Net's quick learner with
MLPs, twice as many updates (an MLP update is cheap). DDPG's and MADDPG's searches started
from it; their quick presets are it with each search's best on top."""

MADDPG_TUNED: dict[str, Any] = dict(
    lr_actor=1.9e-3, lr_critic=1.31e-3, batch_size=512, mlp_hidden=128
)
"""The best of MADDPG's search (results/tuning/maddpg, trial t07: 3.5 % of the held-out
episodes after 1,000,000 env steps)."""

MADDPG_PRESETS: dict[str, dict[str, Any]] = {
    "paper": dict(episodes=4000, num_envs=1, env=dict(evader_policy="ddpg")),
    "quick": {**MLP_QUICK, **MADDPG_TUNED},
    "tiny": dict(
        TINY_RUN,
        mlp_hidden=32,
        buffer_size=20_000,
        batch_size=64,
        update_every=8,
        warmup=500,
        protocol=TINY_PROTOCOL,
    ),
}
MADDPG_PRESETS["gpu"] = gpu_preset(MADDPG_PRESETS["quick"])
"""MADDPG's presets."""

DDPG_TUNED: dict[str, Any] = dict(
    lr_actor=1.18e-3, lr_critic=7.93e-4, batch_size=128, mlp_hidden=256, gamma=0.98
)
"""The best of DDPG's search over the current space with its networks shared
(results/tuning_current/ddpg, trial t02: 22.0 % of the held-out episodes after 1,000,000 env
steps, the earlier preset t00 18.5 %). Its first search (results/tuning/ddpg, one network per
pursuer) had found t05 there: lr 7.03e-4 / 7.19e-4, batch 128, 256 units, gamma 0.95."""

DDPG_PRESETS: dict[str, dict[str, Any]] = {
    **MADDPG_PRESETS,
    "quick": {**MLP_QUICK, **DDPG_TUNED},
}
DDPG_PRESETS["gpu"] = gpu_preset(DDPG_PRESETS["quick"])
"""DDPG's presets: MADDPG's, with the quick one of DDPG's own search."""


class MLPActors(RowScaled):
    """Pursuer i's actor: its Table I observation (N rows of 8, scaled as CBC-TP's, plus a
    real-row flag each, 9N numbers) -> MLP (two hidden layers of ``mlp_hidden``) -> tanh ->
    desired acceleration (2). One MLP per pursuer (``shared=False``) or one for all."""

    def __init__(self, lc: MADDPGConfig, num_pursuers: int) -> None:
        super().__init__(0, lc.obstacle_scale, lc.target_scale)
        members = 1 if lc.shared else num_pursuers
        h = lc.mlp_hidden
        self.body = EnsembleMLP(members, [9 * num_pursuers, h, h, 2], small_out=True)

    def pre_activation(self, obs: Tensor, mask: Tensor, pred: Tensor | None = None) -> Tensor:
        """obs (B, N, N, 8), mask (B, N, N) -> (B, N, 2) before the tanh (``pred`` unused)."""
        return self.body(observation_input(obs, mask, self.scale)).transpose(0, 1)

    def forward(self, obs: Tensor, mask: Tensor, pred: Tensor | None = None) -> Tensor:
        """obs (B, N, N, 8), mask (B, N, N) -> actions (B, N, 2) in [-1, 1]."""
        return torch.tanh(self.pre_activation(obs, mask))


class CentralCritics(RowScaled):
    """MADDPG's centralised critics: Q_i from the global state (every pursuer's row and the
    evader's, scaled as CBC-TP's, (N + 1) x 8), the alive flags (N) and every pursuer's action
    (2N, zero for dead pursuers) -> MLP (two hidden layers of ``mlp_hidden``) -> Q_i. One MLP per
    pursuer, or one shared that also reads the one-hot index i.

    The global state holds everything in the pursuers' observations (each is a function of it,
    :func:`pes.learn.features.pursuer_obs`), so it stands for their concatenation."""

    def __init__(self, lc: MADDPGConfig, num_pursuers: int) -> None:
        super().__init__(0, lc.obstacle_scale, lc.target_scale)
        self.n = num_pursuers
        members = 1 if lc.shared else num_pursuers
        self.index = members == 1 and num_pursuers > 1
        size = 8 * (num_pursuers + 1) + num_pursuers + 2 * num_pursuers
        size += num_pursuers if self.index else 0
        h = lc.mlp_hidden
        self.body = EnsembleMLP(members, [size, h, h, 1])

    def context(self, state: Tensor, alive: Tensor) -> Tensor:
        """What critic i sees besides the actions: (N, B, C)."""
        b = state.shape[0]
        ctx = torch.cat([(state * self.scale).flatten(1), alive.to(state.dtype)], dim=-1)
        ctx = ctx.unsqueeze(0).expand(self.n, b, -1)
        if self.index:
            eye = torch.eye(self.n, dtype=state.dtype, device=state.device)
            ctx = torch.cat([ctx, eye.unsqueeze(1).expand(-1, b, -1)], dim=-1)
        return ctx

    def each(self, state: Tensor, alive: Tensor, actions: Tensor) -> Tensor:
        """Critic i on its own joint action: state (B, A, 8), alive (B, N), actions (N, B, N, 2)
        (row i: the joint action critic i judges) -> Q (B, N)."""
        acts = (actions * alive.unsqueeze(-1).to(actions.dtype)).flatten(-2)
        x = torch.cat([self.context(state, alive), acts], dim=-1)
        return self.body(x).squeeze(-1).transpose(0, 1)

    def forward(
        self, state: Tensor, alive: Tensor, actions: Tensor, pred: Tensor | None = None
    ) -> Tensor:
        """state (B, A, 8), alive (B, N), actions (B, N, 2) -> Q (B, N)."""
        return self.each(state, alive, actions.unsqueeze(0).expand(self.n, *actions.shape))


class MADDPG(ActorCritic):
    """The MADDPG learner (``--algo maddpg``)."""

    name = "maddpg"
    Config = MADDPGConfig
    PRESETS = MADDPG_PRESETS
    TUNE_SPACE: ClassVar[dict[str, tuple]] = {
        **ActorCritic.TUNE_SPACE,
        "mlp_hidden": ("choice", [64, 128, 256]),
    }

    @staticmethod
    def make_actor(lc: MADDPGConfig, num_pursuers: int) -> nn.Module:
        return MLPActors(lc, num_pursuers)

    @staticmethod
    def make_critic(lc: MADDPGConfig, num_pursuers: int) -> nn.Module:
        return CentralCritics(lc, num_pursuers)

    @staticmethod
    def fixed_swarm(cfg: TrainConfig) -> str | None:
        return "has MLPs whose inputs are sized"

    def actor_step(
        self, w: TDWindows, pred: Tensor | None, gen: torch.Generator, stats: dict[str, float]
    ) -> Tensor:
        """Actor i ascends Q_i with only its own action replaced by its actor's, for every
        pursuer on the full minibatch."""
        obs, mask, _ = self.observe(w.state, w.alive, None)
        pre = self.actor.pre_activation(obs, mask)  # (B, N, 2)
        if self.demonstrating() and self.bc_weight > 0:
            return self.cloning_loss(pre, w, stats)
        own = torch.eye(self.n, dtype=torch.bool, device=w.state.device)[:, None, :, None]
        joint = torch.where(own, torch.tanh(pre).unsqueeze(0), w.action.unsqueeze(0))
        self.critic.requires_grad_(False)
        q_pi = self.critic.each(w.state, w.alive, joint)
        self.critic.requires_grad_(True)
        new_action = torch.where(w.alive.unsqueeze(-1), torch.tanh(pre), w.action)
        return self.actor_objective(q_pi, pre, w.alive, new_action, w, stats)
