"""MADDPG (Lowe et al., 2017): per-agent MLP actors, each on its own pursuer's observation, and
per-agent centralised MLP critics on the global state and every pursuer's action.

It trains on CBC-TP's machinery (:class:`pes.algos.cbc_tp.CBCTP`: acting with OU noise, the
replay storage of global states, target networks, checkpoints) with other networks and its own
update:

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

import math

import torch
from torch import Tensor, nn

from pes.algos.cbc_tp import CBCTP
from pes.algos.common import masked_mean, optimise
from pes.algos.config import TrainConfig
from pes.algos.features import pursuer_obs
from pes.algos.nets import RowScaled
from pes.errors import ConfigError
from pes.sim.config import EnvConfig


class EnsembleLinear(nn.Module):
    """``members`` independent linear layers applied at once: (K, B, in) -> (K, B, out),
    each initialised as :class:`torch.nn.Linear`."""

    def __init__(self, members: int, fan_in: int, fan_out: int) -> None:
        super().__init__()
        bound = 1.0 / math.sqrt(fan_in)
        self.weight = nn.Parameter(torch.empty(members, fan_in, fan_out).uniform_(-bound, bound))
        self.bias = nn.Parameter(torch.empty(members, 1, fan_out).uniform_(-bound, bound))

    def forward(self, x: Tensor) -> Tensor:
        return torch.bmm(x, self.weight) + self.bias  # 2x faster than baddbmm's broadcast bias


class EnsembleMLP(nn.Module):
    """``members`` MLPs of the same ``sizes`` (ReLU between layers), one per agent or one shared
    by all (``members == 1``). Input (N, B, in) -> (N, B, out); a single member is applied to
    every agent's slice. The last layer starts within +-3e-3 when ``small_out`` (DDPG's init)."""

    def __init__(self, members: int, sizes: list[int], small_out: bool = False) -> None:
        super().__init__()
        self.layers = nn.ModuleList(
            EnsembleLinear(members, sizes[i], sizes[i + 1]) for i in range(len(sizes) - 1)
        )
        if small_out:
            nn.init.uniform_(self.layers[-1].weight, -3e-3, 3e-3)
            nn.init.uniform_(self.layers[-1].bias, -3e-3, 3e-3)

    @property
    def members(self) -> int:
        return self.layers[0].weight.shape[0]

    def forward(self, x: Tensor) -> Tensor:
        k, b = x.shape[:2]
        if self.members == 1:
            x = x.reshape(1, k * b, -1)
        for i, layer in enumerate(self.layers):
            x = layer(x)
            if i < len(self.layers) - 1:
                x = torch.relu(x)
        return x.reshape(k, b, -1)


def observation_input(obs: Tensor, mask: Tensor, scale: Tensor) -> Tensor:
    """Each pursuer's flat MLP input: obs (B, N, N, 8) scaled by ``scale`` (8,) and its row
    flags mask (B, N, N) -> (N, B, 9N), agent-major for :class:`EnsembleMLP`."""
    rows = torch.cat([obs * scale, mask.unsqueeze(-1).to(obs.dtype)], dim=-1)
    return rows.flatten(-2).transpose(0, 1)


class MLPActors(RowScaled):
    """Pursuer i's actor: its Table I observation (N rows of 8, scaled as CBC-TP's, plus a
    real-row flag each, 9N numbers) -> MLP (two hidden layers of ``mlp_hidden``) -> tanh ->
    desired acceleration (2). One MLP per pursuer (``shared=False``) or one for all."""

    def __init__(self, cfg: TrainConfig, num_pursuers: int) -> None:
        super().__init__(0, cfg.obstacle_scale, cfg.target_scale)
        members = 1 if cfg.shared else num_pursuers
        h = cfg.mlp_hidden
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
    :func:`pes.algos.features.pursuer_obs`), so it stands for their concatenation."""

    def __init__(self, cfg: TrainConfig, num_pursuers: int) -> None:
        super().__init__(0, cfg.obstacle_scale, cfg.target_scale)
        self.n = num_pursuers
        members = 1 if cfg.shared else num_pursuers
        self.index = members == 1 and num_pursuers > 1
        size = 8 * (num_pursuers + 1) + num_pursuers + 2 * num_pursuers
        size += num_pursuers if self.index else 0
        h = cfg.mlp_hidden
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


class MADDPG(CBCTP):
    """The MADDPG learner (``algo: maddpg``)."""

    name = "maddpg"

    def __init__(self, cfg: TrainConfig, env_cfg: EnvConfig, device: torch.device) -> None:
        if cfg.use_tp:
            raise ConfigError(f"{cfg.algo} has no TP Net: set use_tp=false")
        super().__init__(cfg, env_cfg, device)

    @staticmethod
    def make_actor(cfg: TrainConfig, num_pursuers: int) -> nn.Module:
        return MLPActors(cfg, num_pursuers)

    @staticmethod
    def make_critic(cfg: TrainConfig, num_pursuers: int) -> nn.Module:
        return CentralCritics(cfg, num_pursuers)

    @staticmethod
    def fixed_swarm(cfg: TrainConfig) -> str | None:
        return "has MLPs whose inputs are sized"

    def update(self, gen: torch.Generator) -> dict[str, float]:
        """One critic and one actor step for every pursuer on one minibatch (see the module's
        docstring); returns the losses and the mean Q."""
        cfg, n = self.cfg, self.n
        self.updates += 1
        w = self.sample_windows(gen)
        state, alive, action = w.state, w.alive, w.action
        with torch.no_grad():
            next_obs, next_mask = pursuer_obs(w.next_state, w.next_alive)
            next_action = self.actor_target(next_obs, next_mask)
            q_next = self.critic_target(w.next_state, w.next_alive, next_action)
            keep = (~w.terminated).unsqueeze(-1).float() * w.next_alive.float()
            y = w.ret + cfg.gamma * w.before_last * keep * q_next
        q = self.critic(state, alive, action)
        critic_loss = masked_mean((q - y) ** 2, alive)
        stats = {
            "critic_grad": optimise(
                self.opt_critic, critic_loss, self.critic.parameters(), cfg.grad_clip
            )
        }
        if self.critic_warming():
            return self.finish_update(None, critic_loss, q, alive, stats)

        # Actor i ascends Q_i with only its own action replaced by its actor's.
        obs, mask = pursuer_obs(state, alive)
        pre = self.actor.pre_activation(obs, mask)  # (B, N, 2)
        own = torch.eye(n, dtype=torch.bool, device=state.device)[:, None, :, None]
        joint = torch.where(own, torch.tanh(pre).unsqueeze(0), action.unsqueeze(0))
        self.critic.requires_grad_(False)
        q_pi = self.critic.each(state, alive, joint)
        self.critic.requires_grad_(True)
        reg = masked_mean((pre**2).sum(-1), alive)
        actor_loss = -masked_mean(q_pi, alive) + cfg.action_reg * reg
        return self.finish_update(actor_loss, critic_loss, q, alive, stats)
