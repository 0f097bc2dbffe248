"""BiCNet (Peng et al., 2017, "Multiagent Bidirectionally-Coordinated Nets"): one bidirectional
RNN runs across the pursuers, in index order, in both the actor and the critic; each agent's
cell outputs its own action (actor) or its own Q (critic), and the RNN's hidden states are the
agents' communication channel.

It trains on the deterministic actor-critic of :mod:`pes.learn.actor_critic` with its
centralised actor gradient: BiCNet's actor gradient sums over every agent's Q the gradients
through every agent's action, all of which come from the one actor (eq. 8 of Peng et al.). The
critic is CBC Net's (:class:`pes.algos.cbc_tp.CBCCritic` without a prediction), which is BiCNet's: a
bidirectional LSTM across the pursuers, cell j holding pursuer j's global-state row, the
evader's row, j's action and an alive flag. What differs from CBC Net is the actor: BiCNet's
crosses the team once for all agents (cell j: pursuer j's own observation row) instead of
crossing each pursuer's observation with the pursuer itself at both ends.

Damaged pursuers keep their place in the sequence with a zero row and a 0 flag, their actions
are ignored (the environment stops them; the critic zeroes them) and their Qs are left out of
the losses. The networks serve any number of pursuers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import Tensor, nn

from pes.algos.cbc_tp import CBCCritic
from pes.learn.actor_critic import ActorCritic, ActorCriticConfig
from pes.learn.nets import RowScaled, mlp
from pes.learn.presets import QUICK_RUN, TINY_PROTOCOL, TINY_RUN, gpu_preset


@dataclass
class BiCNetConfig(ActorCriticConfig):
    """BiCNet's settings (the paper gives none for its baselines: CBC-TP Net's, §V-A)."""

    hidden: int = 256
    """Units of the actor's and the critic's bidirectional LSTM (each direction)."""
    mlp_hidden: int = 64
    """Units of the MLP after each LSTM."""

    POSITIVE: ClassVar[tuple[str, ...]] = (*ActorCriticConfig.POSITIVE, "hidden", "mlp_hidden")


BICNET_TUNED: dict[str, Any] = dict(
    lr_actor=4.4e-4, lr_critic=1.38e-3, batch_size=128, update_every=16, gamma=0.95, hidden=64
)
"""The best of BiCNet's search over the update ratio, batch and discount as well as the
learning rates and width (results/tuning_current/bicnet, trial t03: 46.0 % of the held-out
episodes after 1,000,000 env steps in 0.37 CPU hours, within one standard error of the top
trial t05's 47.0 % in 2.90; the search began at its earlier search's best, results/tuning/bicnet
t01: lr_actor 2.06e-4, lr_critic 1.28e-3, batch 256, hidden 128, one update per 32 env steps,
29.0 % there)."""

BICNET_PRESETS: dict[str, dict[str, Any]] = {
    "paper": dict(episodes=4000, num_envs=1, env=dict(evader_policy="ddpg")),
    # CBC Net's quick learner (its LSTMs cost about as much per update)
    "quick": dict(
        QUICK_RUN,
        hidden=64,
        mlp_hidden=64,
        lr_actor=5e-4,
        lr_critic=1e-3,
        buffer_size=300_000,
        batch_size=256,
        update_every=32,
        warmup=10_000,
    )
    | BICNET_TUNED,
    "tiny": dict(
        TINY_RUN,
        hidden=32,
        mlp_hidden=32,
        buffer_size=20_000,
        batch_size=64,
        update_every=8,
        warmup=500,
        protocol=TINY_PROTOCOL,
    ),
}
BICNET_PRESETS["gpu"] = gpu_preset(BICNET_PRESETS["quick"])


class BiCNetActor(RowScaled):
    """BiCNet's actor: a bidirectional LSTM (``hidden`` per direction) across the pursuers, cell
    j holding pursuer j's own observation row (Table I self row, 8, scaled as CBC-TP's) and its
    alive flag; each cell's output -> MLP (``mlp_hidden``, ReLU) -> tanh -> pursuer j's desired
    acceleration. The last layer starts within +-3e-3, as CBC-TP's."""

    def __init__(self, lc: BiCNetConfig) -> None:
        super().__init__(0, lc.obstacle_scale, lc.target_scale)
        self.lstm = nn.LSTM(9, lc.hidden, batch_first=True, bidirectional=True)
        self.head = mlp([2 * lc.hidden, lc.mlp_hidden, 2])
        nn.init.uniform_(self.head[-1].weight, -3e-3, 3e-3)
        nn.init.uniform_(self.head[-1].bias, -3e-3, 3e-3)

    def pre_activation(self, obs: Tensor, mask: Tensor, pred: Tensor | None = None) -> Tensor:
        """obs (B, N, N, 8), mask (B, N, N) -> (B, N, 2) before the tanh (only each pursuer's
        own row, ``obs[:, j, 0]``, is read; ``pred`` is unused)."""
        own, alive = obs[:, :, 0], mask[:, :, 0]
        cells = torch.cat([own * self.scale, alive.unsqueeze(-1).to(obs.dtype)], dim=-1)
        out, _ = self.lstm(cells)
        return self.head(out)

    def forward(self, obs: Tensor, mask: Tensor, pred: Tensor | None = None) -> Tensor:
        """obs (B, N, N, 8), mask (B, N, N) -> actions (B, N, 2) in [-1, 1]."""
        return torch.tanh(self.pre_activation(obs, mask))


class BiCNetCritic(nn.Module):
    """BiCNet's critic: CBC Net's (:class:`pes.algos.cbc_tp.CBCCritic`), one for all pursuers."""

    def __init__(self, lc: BiCNetConfig) -> None:
        super().__init__()
        self.nets = nn.ModuleList(
            [CBCCritic(lc.hidden, lc.mlp_hidden, 0, lc.obstacle_scale, lc.target_scale)]
        )

    def forward(self, state: Tensor, alive: Tensor, actions: Tensor, pred: Tensor | None = None):
        """state (B, A, 8), alive (B, N), actions (B, N, 2) -> Q (B, N)."""
        return self.nets[0](state, alive, actions, None)


class BiCNet(ActorCritic):
    """The BiCNet learner (``--algo bicnet``): the base class's centralised actor gradient."""

    name = "bicnet"
    Config = BiCNetConfig
    PRESETS = BICNET_PRESETS
    TUNE_SPACE: ClassVar[dict[str, tuple]] = {
        **ActorCritic.TUNE_SPACE,
        "hidden": ("choice", [32, 64, 128]),
    }

    @staticmethod
    def make_actor(lc: BiCNetConfig, num_pursuers: int) -> nn.Module:
        return BiCNetActor(lc)

    @staticmethod
    def make_critic(lc: BiCNetConfig, num_pursuers: int) -> nn.Module:
        return BiCNetCritic(lc)
